"""Renderers: views of the scene model that make images (the protocol: :mod:`.base`).

``kubric.renderer.create(name, scene, scratch_dir, **settings)`` builds a registered backend
(``blender``: Cycles on ``bpy==5.0.1``; ``raycast``: embree, exact layers without bpy). The
backend classes ``Blender`` and ``Raycast`` are loaded on first access, so ``import kubric.renderer``
imports neither bpy nor embree; ``kubric.renderer.capabilities(name)`` says what a backend can do
(photoreal RGB, layers, exposure effects, state saving) without importing it either.
"""

import importlib

from kubric.renderer.base import (
    ALL_LAYERS,
    ANNOTATION_LAYERS,
    BACKENDS,
    EFFECTS,
    Capabilities,
    CapabilityError,
    Renderer,
    capabilities,
    create,
)

__all__ = ["ALL_LAYERS", "ANNOTATION_LAYERS", "BACKENDS", "EFFECTS", "Capabilities",
           "CapabilityError", "Renderer", "capabilities", "create"]
#: backend class name → its module, for ``kubric.renderer.Blender`` etc. (derived from BACKENDS)
_LAZY = {row.path.split(":")[1]: row.path.split(":")[0] for row in BACKENDS.values()}


def __getattr__(name):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'kubric.renderer' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
