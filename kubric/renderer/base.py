"""The renderer protocol: what a rendering backend does, the layers it may produce, and the one place
where a recipe builds its renderer (docs/renderers.md).

A backend is a class registered in :data:`BACKENDS` (name → ``"module:Class"``; imported on first
use, so naming a backend never imports bpy or embree). It is constructed as
``Backend(scene, scratch_dir=None, **settings)`` and implements :class:`Renderer`:

* ``render(frames=None, return_layers=ALL_LAYERS)`` → ``{layer: (T, H, W, C) numpy array}`` for the
  requested frames (default: the scene's ``frame_start .. frame_end``) in the layer conventions of
  docs/conventions.md: ``rgba`` uint8 (C = 4); ``depth`` (distance to the camera centre) and ``z``
  (distance along the view axis) float32 metres, 10000 where the pixel-centre ray hits nothing;
  ``segmentation`` uint32 (0 = nothing, else the object's ``segmentation_id`` or its position in
  ``scene.assets`` + 1); ``forward_flow`` / ``backward_flow`` float32 (Δrow, Δcol) in pixels;
  ``normal`` float32 world-space unit normals; ``object_coordinates`` and ``uv`` float32 in
  [0, 1]. Every annotation layer is the value at the surface seen through the pixel centre, 0 on
  background (depth / z: 10000).
* ``settings()`` → the JSON-able dict recorded as ``metadata["renderer"]``: ``engine`` (the
  backend's name for itself) and the settings that decide its pixels.
* ``layers``: the subset of :data:`ALL_LAYERS` the backend can produce; ``scene``: the scene.

Adding a backend = one new module with the class + one row in :data:`BACKENDS`.
"""

from __future__ import annotations

import abc
import importlib

import numpy as np

#: the exact annotation layers (one value per pixel centre; docs/conventions.md)
ANNOTATION_LAYERS = ("depth", "z", "segmentation", "forward_flow", "backward_flow", "normal",
                     "object_coordinates", "uv")
#: every layer a backend may be asked for
ALL_LAYERS = ("rgba",) + ANNOTATION_LAYERS

#: name → "module:Class" of every backend (the recipes' ``renderer`` option values)
BACKENDS = {
    "blender": "kubric.renderer.blender:Blender",
    "raycast": "kubric.renderer.raycast:Raycast",
}


class Renderer(abc.ABC):
    """The protocol every rendering backend implements (see module doc)."""

    #: the layers this backend can produce (a subset of ALL_LAYERS)
    layers: tuple[str, ...] = ALL_LAYERS
    #: the scene it renders (a :class:`kubric.core.scene.Scene`), set by the constructor
    scene = None

    @abc.abstractmethod
    def render(self, frames=None, return_layers=ALL_LAYERS) -> dict[str, np.ndarray]:
        """Render ``frames`` → ``{layer: (T, H, W, C) array}`` for every layer of
        ``return_layers``."""

    @abc.abstractmethod
    def settings(self) -> dict:
        """``metadata["renderer"]``: ``engine`` and the settings that decide the pixels."""

    def check_request(self, frames, return_layers) -> tuple[list[int], tuple[str, ...]]:
        """The validated (frames, layers) of a render call: frames default to the scene's range,
        must be integers ≥ 0 and not empty; every layer must be one of :attr:`layers`."""
        who = f"{type(self).__name__}.render"
        frames = list(self.scene.frames if frames is None else frames)
        if not frames:
            raise ValueError(f"{who}: frames is empty")
        for f in frames:
            if isinstance(f, bool) or not isinstance(f, (int, np.integer)):
                raise TypeError(f"{who}: frames must be integers, got {f!r}")
        frames = [int(f) for f in frames]
        if min(frames) < 0:
            raise ValueError(f"{who}: renders frames ≥ 0 only, got {min(frames)}")
        if isinstance(return_layers, str):
            raise TypeError(f"{who}: return_layers must be a sequence of layer names, got the "
                            f"string {return_layers!r}")
        wanted = tuple(return_layers)
        unknown = sorted(set(wanted) - set(self.layers))
        if unknown:
            raise ValueError(f"{who}: unknown layers {unknown}; allowed: {list(self.layers)}")
        return frames, wanted


def backend(name: str) -> type:
    """The backend class registered as ``name`` (imports its module)."""
    if name not in BACKENDS:
        raise ValueError(f"unknown renderer {name!r}; allowed: {sorted(BACKENDS)}")
    module, cls = BACKENDS[name].split(":")
    return getattr(importlib.import_module(module), cls)


def create(name: str, scene, scratch_dir=None, **settings) -> Renderer:
    """Build the renderer ``name`` of :data:`BACKENDS` for ``scene`` with its keyword
    ``settings`` (each backend documents and checks its own)."""
    return backend(name)(scene, scratch_dir, **settings)

