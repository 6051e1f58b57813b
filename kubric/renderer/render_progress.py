"""A progress bar over the frames of a Blender render, so that a long render from the Python API
says what it is doing (a 24-frame MOVi-A scene path-traces for about a minute on 2 cores).

The bar goes to the process's real stderr (a duplicate of descriptor 2, taken before Blender's
console output is silenced) and appears only once a render has run for ``KUBRIC_RENDER_PROGRESS_DELAY``
seconds (default 3): short renders print nothing. ``KUBRIC_RENDER_PROGRESS=0`` turns it off;
``kubric worker`` does, since its output is a scene's log.
"""

from __future__ import annotations

import contextlib
import os

#: the environment variables read at each render
ENV, DELAY_ENV = "KUBRIC_RENDER_PROGRESS", "KUBRIC_RENDER_PROGRESS_DELAY"


@contextlib.contextmanager
def frame_bar(what: str, total: int):
    """While active, each frame Blender finishes (``render_post``) advances a bar of ``total``
    frames labelled ``what``."""
    if total < 1 or os.environ.get(ENV, "1") == "0":
        yield
        return
    import bpy
    from tqdm import tqdm
    stream = os.fdopen(os.dup(2), "w")
    bar = tqdm(total=total, desc=what, unit="frame", file=stream, dynamic_ncols=True,
               delay=float(os.environ.get(DELAY_ENV, "3")))

    def advance(*_args):
        bar.update(1)

    bpy.app.handlers.render_post.append(advance)
    try:
        yield
    finally:
        bpy.app.handlers.render_post.remove(advance)
        bar.close()
        stream.close()


__all__ = ["frame_bar"]
