"""Cloth sheets and soft toys for MOVi-C–F (options ``cloths=N``, ``soft_objects=N``;
docs/deformables.md).

Cloth: a :meth:`kubric.Deformable.cloth` square of edge U(``CLOTH_SIZE``) m at
``CLOTH_RESOLUTION``² vertices, mass ``CLOTH_MASS`` kg (spring stiffness and margin: the
Deformable defaults, measured stable at MOVi's 240 steps/s). Soft toy: a
:meth:`kubric.Deformable.soft_box` cube of edge U(``SOFT_SIZE``) m, ``SOFT_RESOLUTION``³ cells,
mass ``SOFT_MASS`` kg (NeoHookean defaults). Each is turned by a random yaw, its centre at x, y
U(``DROP_REGION``) m and U(``DROP_CLEARANCE``) m above the highest point of the foreground objects
at the start, so it falls onto the objects (two-way: it pushes them too), and textured with a
checkerboard of two random hues (``SQUARES``² squares over its UVs, a PNG in the scene's scratch
folder) so that its motion is visible. Instance metadata: ``scale`` (the edge, m),
``is_dynamic`` True, ``cloth`` or ``soft`` True.

Soft toys from KuBasic (``soft_shapes`` other than ``("box",)``): each toy's shape is drawn from
``soft_shapes`` (after its other draws): "box" as above, or a KuBasic shape whose visual mesh is
closed and measured stable (:data:`SOFT_SHAPES`), its vertices merged by position, centred and
scaled so that its longest side is the drawn size, tetrahedralised by
:meth:`kubric.Deformable.soft_mesh` (``cells=4``), box-mapped UVs; metadata ``shape`` its name.
"""

from __future__ import annotations

import colorsys
import pathlib

import numpy as np

import kubric as kb
from kubric.core.deformables import checker_image

CLOTH_SIZE = (1.5, 3.0)
CLOTH_RESOLUTION = 16
CLOTH_MASS = 0.2
SOFT_SIZE = (0.4, 0.8)
SOFT_RESOLUTION = 3
SOFT_MASS = 0.5
DROP_REGION = (-1.0, 1.0)
DROP_CLEARANCE = (0.3, 1.0)
SQUARES = 8
#: soft toy shapes: the procedural box and the KuBasic shapes whose visual mesh is closed and
#: whose soft body was measured stable (docs/deformables.md)
SOFT_SHAPES = ("box", "cube", "cone", "cylinder", "sphere")


def soft_shape_list(value) -> tuple[str, ...]:
    """Option converter: ``"box,sphere"`` or a sequence of names → a tuple of shape names."""
    items = value.split(",") if isinstance(value, str) else list(value)
    names = tuple(str(v).strip() for v in items if str(v).strip())
    if not names or any(n not in SOFT_SHAPES for n in names):
        raise ValueError(f"expected names of {', '.join(SOFT_SHAPES)} separated by commas")
    return names


soft_shape_list.allowed = f"shape names separated by commas, from {', '.join(SOFT_SHAPES)}"


def closed_mesh(path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3), faces (F, 3)) of an OBJ with its vertices merged by position (to 1e-7
    m: an OBJ splits them at texture seams), centred on its box, longest side 1."""
    import trimesh
    mesh = trimesh.load(str(path), process=False, force="mesh")
    v, f = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
    merged, inverse = np.unique(np.round(v, 7), axis=0, return_inverse=True)
    lo, hi = merged.min(axis=0), merged.max(axis=0)
    return (merged - (lo + hi) / 2) / float((hi - lo).max()), inverse.reshape(-1)[f]


def _hue_pair(rng) -> np.ndarray:
    """Two sRGB colours of opposite-ish random hues, one light and one dark."""
    hue = float(rng.uniform(0, 1))
    light = colorsys.hsv_to_rgb(hue, 0.25, 0.95)
    dark = colorsys.hsv_to_rgb((hue + 0.5) % 1.0, 0.8, 0.45)
    return np.array([light, dark])


def _top(scene) -> float:
    tops = [float(a.aabbox[1, 2]) for a in scene.foreground_assets
            if isinstance(a, kb.PhysicalObject)]
    return max(tops, default=0.0)


def _drop(scene, rng, kind: str, k: int, folder: pathlib.Path, top: float,
          soft_shapes=("box",), kubasic=None):
    """One deformable of ``kind`` (module doc) added to ``scene``."""
    from PIL import Image
    size = float(rng.uniform(*(CLOTH_SIZE if kind == "cloth" else SOFT_SIZE)))
    x, y = rng.uniform(*DROP_REGION, size=2)
    position = (float(x), float(y), top + float(rng.uniform(*DROP_CLEARANCE)))
    yaw = float(rng.uniform(0, 2 * np.pi))
    name = f"{kind}_{k}"
    path = pathlib.Path(folder) / f"{name}.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(checker_image((SQUARES, SQUARES), 8, _hue_pair(rng))).save(path)
    material = kb.PrincipledBSDFMaterial(color=kb.Texture(filename=str(path), mapping="uv"),
                                         roughness=0.9, name=f"{name}_material")
    common = dict(position=position, euler=(0.0, 0.0, yaw), friction=0.5, material=material,
                  name=name)
    if kind == "cloth":
        obj = kb.Deformable.cloth(size=(size, size), resolution=(CLOTH_RESOLUTION,) * 2,
                                  mass=CLOTH_MASS, **common)
    else:
        shape = "box" if soft_shapes == ("box",) else soft_shapes[rng.randint(len(soft_shapes))]
        if shape == "box":
            obj = kb.Deformable.soft_box(size=(size,) * 3, resolution=(SOFT_RESOLUTION,) * 3,
                                         mass=SOFT_MASS, **common)
        else:
            from kubric.core.tet_meshes import box_uv
            v, f = closed_mesh(kubasic.fetch(shape) / "visual_geometry.obj")
            obj = kb.Deformable.soft_mesh(v * size, f, uv=box_uv(v, f), cells=4, mass=SOFT_MASS,
                                          **common)
    obj.metadata = {"scale": size, "is_dynamic": True, kind: True}
    if kind == "soft" and soft_shapes != ("box",):
        obj.metadata["shape"] = shape
    scene += obj
    return obj


def add_deformables(scene, rng, cloths: int, soft_objects: int, folder: pathlib.Path,
                    soft_shapes=("box",), kubasic=None) -> list:
    """``cloths`` sheets then ``soft_objects`` toys (module doc) added to ``scene``, all above
    the objects present now; their textures go to ``folder``; ``kubasic``: the KuBasic source
    (needed when ``soft_shapes`` names a KuBasic shape)."""
    top = _top(scene)
    return [_drop(scene, rng, kind, k, folder, top, tuple(soft_shapes), kubasic)
            for kind, count in (("cloth", cloths), ("soft", soft_objects))
            for k in range(count)]
