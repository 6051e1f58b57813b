"""One scene to an object store (or any fsspec URL): render into local scratch, upload after.

Object stores have no atomic rename, so :func:`run_scene_remote` renders the scene with the
ordinary atomic :func:`~kubric.pipeline.worker.run_scene` into a local scratch directory
(``$KUBRIC_SCRATCH_DIR``, else the system temporary directory), then uploads it file by file with
``_SUCCESS`` last, replacing whatever an earlier, interrupted upload left. A scene directory
without ``_SUCCESS`` is therefore never data: resume redoes it, readers skip it.
"""

from __future__ import annotations

import os
import tempfile
import time

from kubric.io import storage
from kubric.io.scene_dir import SUCCESS_FILE as SUCCESS
from kubric.io.scene_dir import scene_name
from kubric.pipeline.worker import SceneResult, run_scene


def run_scene_remote(recipe, seed: int, out_url: str, scratch: str | None = None,
                     echo=print) -> SceneResult:
    """Generate scene ``seed`` under ``out_url`` (see module doc). ``echo`` receives one line per
    uploaded file."""
    start = time.time()
    final = storage.join(out_url, scene_name(seed))
    marker = storage.join(final, SUCCESS)
    if storage.isfile(marker):
        return SceneResult(seed, final, "skipped", 0.0)
    scratch = scratch or os.environ.get("KUBRIC_SCRATCH_DIR") or None
    with tempfile.TemporaryDirectory(prefix="kubric-scratch-", dir=scratch) as tmp:
        local = run_scene(recipe, seed, tmp)
        if storage.isfile(marker):  # another worker finished the same seed meanwhile
            return SceneResult(seed, final, "skipped", time.time() - start)
        echo(f"uploading {local.path} to {final}")
        storage.upload_dir(local.path, final, last=SUCCESS,
                           on_file=lambda rel, k, n: echo(f"uploaded {k}/{n} {rel}"))
    return SceneResult(seed, final, "done", time.time() - start)


__all__ = ["run_scene_remote"]
