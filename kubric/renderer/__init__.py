"""Renderers: views of the scene model that make images.

``kubric.renderer.Blender`` (Cycles on ``bpy==5.0.1``) is loaded on first access, so
``import kubric.renderer`` does not import bpy.
"""

import importlib

_LAZY = {"Blender": "kubric.renderer.blender"}


def __getattr__(name):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'kubric.renderer' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
