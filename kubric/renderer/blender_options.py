"""The Blender renderer's options: each checked in one line naming the bad value and the allowed
set; the live ones (:func:`live_option`) are applied to the Blender scene as soon as they are set.

What each option means: :mod:`kubric.renderer.blender`'s module doc. Environment variables read
here: KUBRIC_USE_GPU (the default device) and KUBRIC_RENDER_THREADS (:func:`render_threads`).
"""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

import numpy as np


@contextlib.contextmanager
def silenced(active: bool):
    """Redirect the process's stdout/stderr file descriptors to /dev/null while active."""
    if not active:
        yield
        return
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)


def as_bool(name, value):
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"Blender option {name} must be True or False, got {value!r}")
    return bool(value)


def as_int(name, value, low):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ValueError(f"Blender option {name} must be an integer ≥ {low}, got {value!r}")
    return int(value)


def as_threshold(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) \
            or not 0 < value <= 1:
        raise ValueError(f"Blender option {name} must be a number in (0, 1], got {value!r}")
    return float(value)


def shutter(value):
    """``motion_blur`` → the shutter length in frames (True: 0.5, False: 0)."""
    if isinstance(value, (bool, np.bool_)):
        return 0.5 if value else 0.0
    if isinstance(value, (int, float, np.number)) and 0 <= float(value) <= 10:
        return float(value)
    raise ValueError(f"Blender option motion_blur must be a bool or a shutter length in frames in "
                     f"[0, 10], got {value!r}")


def render_device(value):
    """``device`` → "CPU" or "GPU" (None: "GPU" when KUBRIC_USE_GPU is 1/true/yes)."""
    if value is None:
        value = "GPU" if os.environ.get("KUBRIC_USE_GPU", "").lower() in ("1", "true", "yes") \
            else "CPU"
    if value not in ("CPU", "GPU"):
        raise ValueError(f"Blender option device must be 'CPU' or 'GPU', got {value!r}")
    return value


def choice(allowed):
    def convert(name, value):
        if not isinstance(value, str) or value.upper() not in allowed:
            raise ValueError(f"Blender option {name} must be one of {list(allowed)}, "
                             f"got {value!r}")
        return value.upper()
    return convert


def live_option(name, convert, apply):
    """A renderer option: validated by ``convert(name, value)``, applied to the Blender scene at
    once by ``apply(bpy_scene, value)`` (upstream scripts set these after construction)."""
    def fget(self):
        return self._options[name]

    def fset(self, value):
        self._options[name] = convert(name, value)
        if getattr(self, "bpy_scene", None) is not None:
            apply(self.bpy_scene, self._options[name])
    return property(fget, fset, doc=f"Renderer option {name} (applied to Blender when set).")


def set_cycles(attr):
    return lambda bscene, value: setattr(bscene.cycles, attr, value)


def render_threads() -> int | None:
    """The render thread count from KUBRIC_RENDER_THREADS (None = Blender's automatic count)."""
    value = os.environ.get("KUBRIC_RENDER_THREADS", "").strip()
    if not value:
        return None
    if not value.isdigit() or int(value) < 1:
        raise ValueError(f"KUBRIC_RENDER_THREADS must be an integer ≥ 1, got {value!r}")
    return int(value)


def custom_scene_path(path) -> str | None:
    """``custom_scene`` (upstream's option): None or an existing ``.blend`` file, as a str."""
    if path is None:
        return None
    if not isinstance(path, (str, os.PathLike)) or Path(path).suffix.lower() != ".blend":
        raise ValueError(f"Blender option custom_scene must be the path of a .blend file, got "
                         f"{path!r}")
    if not Path(path).is_file():
        raise FileNotFoundError(f"Blender option custom_scene: {str(path)!r} does not exist")
    return str(Path(path).resolve())
