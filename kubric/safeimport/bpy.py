"""``from kubric.safeimport.bpy import bpy`` (upstream Kubric's spelling) gives the ``bpy`` module.

Blender comes from the ``bpy`` wheel on PyPI (``bpy==5.0.1``, a dependency of this package). When
it cannot be imported the error says so, instead of a bare ``No module named 'bpy'``.
"""

try:
    import bpy
except ImportError as err:  # pragma: no cover - bpy is a declared dependency
    raise ImportError(f"kubric.safeimport.bpy: cannot import Blender's Python module 'bpy' ({err}); "
                      "install it with `pip install bpy==5.0.1` (Python 3.11 only)") from err

__all__ = ["bpy"]
