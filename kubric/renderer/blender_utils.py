"""Blender helpers under upstream Kubric's module path ``kubric.renderer.blender_utils``.

* :func:`mm3hash` — the Cryptomatte id of an object name (MurmurHash3, x86 32-bit variant, seed 0,
  with Cryptomatte's rule that the id read as a float32 is never a denormal, inf or NaN). Pure
  Python: no Blender needed.
* :func:`name_and_link` / :func:`prepare_blender_object` — give a new Blender object its asset's
  uid as name, quaternion rotation mode, and link it into a scene collection. The renderer's own
  builders use :func:`name_and_link`; the decorator is upstream's spelling for custom builders
  ``fn(view, asset) -> bpy object``.

``bpy`` is imported only when an object is actually prepared, so importing this module (or
calling :func:`mm3hash`) does not load Blender.
"""

from __future__ import annotations

import functools

_MASK32 = 0xFFFFFFFF


def _rotl32(x: int, r: int) -> int:
    return ((x << r) | (x >> (32 - r))) & _MASK32


def _mix_block(k: int) -> int:
    k = (k * 0xCC9E2D51) & _MASK32
    k = _rotl32(k, 15)
    return (k * 0x1B873593) & _MASK32


def murmurhash3_32(data: bytes, seed: int = 0) -> int:
    """MurmurHash3 (x86, 32-bit) of ``data`` as an unsigned 32-bit integer."""
    h = seed & _MASK32
    n_full = len(data) // 4
    for i in range(n_full):
        h ^= _mix_block(int.from_bytes(data[4 * i:4 * i + 4], "little"))
        h = _rotl32(h, 13)
        h = (h * 5 + 0xE6546B64) & _MASK32
    tail = data[4 * n_full:]
    if tail:
        h ^= _mix_block(int.from_bytes(tail, "little"))
    h ^= len(data)
    h ^= h >> 16
    h = (h * 0x85EBCA6B) & _MASK32
    h ^= h >> 13
    h = (h * 0xC2B2AE35) & _MASK32
    return h ^ (h >> 16)


def mm3hash(name: str) -> int:
    """The Cryptomatte id of ``name``: its MurmurHash3 with the float32 exponent kept away from
    0 and 255 (bit 23 flipped in those cases), as an unsigned 32-bit integer."""
    if not isinstance(name, str):
        raise TypeError(f"mm3hash: name must be a string, got {name!r}")
    h = murmurhash3_32(name.encode("utf-8"))
    exponent = (h >> 23) & 0xFF
    if exponent in (0, 255):
        h ^= 1 << 23
    return h


def name_and_link(obj, asset, collection=None):
    """Name ``obj`` after ``asset.uid`` (an older object of that name is renamed instead), set
    quaternion rotation and link it into ``collection`` (default: the current Blender scene's)
    unless it is already there; returns ``obj``."""
    if collection is None:
        import bpy
        collection = bpy.context.scene.collection
    if obj.name != asset.uid:  # take the uid even from another datablock that holds it
        obj.rename(asset.uid, mode="ALWAYS")
    obj.rotation_mode = "QUATERNION"
    if obj.name not in collection.objects:
        collection.objects.link(obj)
    return obj


def prepare_blender_object(func):
    """Decorator for ``func(view, asset) -> bpy object``: the object returned is named after the
    asset's uid, rotates by quaternion and is linked into the current Blender scene."""
    @functools.wraps(func)
    def wrapper(view, asset, *args, **kwargs):
        obj = func(view, asset, *args, **kwargs)
        if obj is None:
            raise ValueError(f"{func.__name__} returned no Blender object for {asset.uid!r}")
        return name_and_link(obj, asset)
    return wrapper


__all__ = ["mm3hash", "murmurhash3_32", "name_and_link", "prepare_blender_object"]
