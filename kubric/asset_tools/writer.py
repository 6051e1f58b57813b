"""Write one asset (archive + manifest entry) and whole manifests, deterministically.

An object archive holds ``data.json`` (the manifest entry), the visual mesh
(``visual_geometry.obj`` — z up, for KuBasic — or ``visual_geometry.glb`` — glTF's y-up convention
with embedded textures, so Blender's glTF importer brings it in z up), optionally a material for
the OBJ (``visual_geometry.mtl`` whose ``map_Kd`` is ``texture.png``: Blender's OBJ importer turns
it into a material with a node named ``"Image Texture"``, as the dome needs), ``collision_geometry.obj``
(convex hulls, one ``o`` object each) and ``object.urdf`` (one link; the mesh is centred on its
centre of mass, so the inertial origin is 0).

Numbers in JSON are rounded to 9 significant digits and keys are sorted: building the same
source twice gives byte-identical manifests and archives.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kubric.asset_tools import physics
from kubric.assets.archive import write_archive
from kubric.assets.glb import write_visual_glb
from kubric.errors import InputError
from kubric.io.paths import pid_alive

OBJ_IMPORT_KWARGS = {"forward_axis": "Y", "up_axis": "Z"}  # z-up OBJ into Blender unchanged

#: a staging folder of one process beside the archives it writes: ``.stage_{pid}_<random>``
STAGE_PREFIX = ".stage_"
_STAGE_RE = re.compile(r"^\.stage_(\d+)_")


def remove_stale_stages(parent) -> list[Path]:
    """Remove the staging folders under ``parent`` of processes that no longer run (left by a
    ``kill -9`` inside a published source); returns them."""
    removed = []
    try:
        entries = list(Path(parent).iterdir())
    except OSError:
        return removed
    for entry in entries:
        m = _STAGE_RE.match(entry.name)
        if m and entry.is_dir() and not entry.is_symlink() and not pid_alive(int(m.group(1))):
            shutil.rmtree(entry, ignore_errors=True)
            removed.append(entry)
    return removed


@contextlib.contextmanager
def staging(parent: Path):
    """A fresh staging folder beside the archive being written (same file system), removed
    when the block ends; a dead process's staging folders there are removed first."""
    remove_stale_stages(parent)
    with tempfile.TemporaryDirectory(prefix=f"{STAGE_PREFIX}{os.getpid()}_", dir=parent) as tmp:
        yield Path(tmp)

def clean_number(x):
    """Round floats to 9 significant digits (and -0 → 0) for stable JSON."""
    if isinstance(x, dict):
        return {k: clean_number(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [clean_number(v) for v in x]
    if isinstance(x, np.ndarray):
        return clean_number(x.tolist())
    if isinstance(x, (float, np.floating)):
        v = float(f"{float(x):.9g}")
        return 0.0 if v == 0 else v
    if isinstance(x, np.integer):
        return int(x)
    return x


def dumps(obj) -> str:
    return json.dumps(clean_number(obj), indent=2, sort_keys=True) + "\n"


def with_checksum(folder: Path, asset_id: str, entry: dict) -> dict:
    """``entry`` with the ``sha256`` of its archive (``path``, default ``ID.tar.gz``, in
    ``folder``) when the archive is there and the entry has none: a copy of the source served at
    a URL is then checked after download (a transfer cut short is never cached)."""
    archive = folder / entry.get("path", f"{asset_id}.tar.gz")
    if "sha256" in entry or "data_dir" in entry or not archive.is_file():
        return entry
    digest = hashlib.sha256()
    with open(archive, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return {**entry, "sha256": digest.hexdigest()}


def write_manifest(path: str | os.PathLike, name: str, version: str, entries: dict,
                   description: str = "") -> Path:
    """Write ``manifest.json`` atomically (entries sorted by id); ``description`` (optional)
    states what the source is, e.g. its units."""
    path = Path(path)
    head = {"name": name, "version": version}
    if description:
        head["description"] = description
    entries = {k: with_checksum(path.parent, k, entries[k]) for k in sorted(entries)}
    text = dumps({**head, "assets": entries})
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
    return path


@dataclass
class Collision:
    """Collision geometry of an object.

    kind: ``"box"`` (params: size (3,)), ``"sphere"`` (radius), ``"cylinder"`` (radius, length;
    axis z), ``"hulls"`` (the convex hulls in ``hulls``) or ``"concave"`` (the visual mesh as a
    static triangle mesh; only for static objects such as the dome).
    """

    kind: str
    params: tuple = ()
    hulls: list = field(default_factory=list)
    method: str = ""


def _geometry_xml(col: Collision) -> str:
    if col.kind == "box":
        return '<box size="{} {} {}"/>'.format(*(physics.fmt(v) for v in col.params))
    if col.kind == "sphere":
        return f'<sphere radius="{physics.fmt(col.params[0])}"/>'
    if col.kind == "cylinder":
        r, h = (physics.fmt(v) for v in col.params)
        return f'<cylinder radius="{r}" length="{h}"/>'
    if col.kind in ("hulls", "concave"):
        return '<mesh filename="collision_geometry.obj" scale="1 1 1"/>'
    raise InputError(f"Collision.kind must be box, sphere, cylinder, hulls or concave, "
                     f"got {col.kind!r}")


def urdf_text(name: str, mass: float, inertia: np.ndarray, col: Collision,
              visual_file: str, friction: float = 0.5) -> str:
    """A one-link URDF: inertial at the origin (mesh centred on its centre of mass)."""
    f = physics.fmt
    i = np.asarray(inertia, dtype=np.float64)
    concave = ' concave="yes"' if col.kind == "concave" else ""
    return "\n".join([
        '<?xml version="1.0"?>',
        f'<robot name="{name}">',
        f'  <link name="base"{concave}>',
        "    <contact>",
        f'      <lateral_friction value="{f(friction)}"/>',
        "    </contact>",
        "    <inertial>",
        '      <origin xyz="0 0 0" rpy="0 0 0"/>',
        f'      <mass value="{f(mass)}"/>',
        f'      <inertia ixx="{f(i[0, 0])}" ixy="{f(i[0, 1])}" ixz="{f(i[0, 2])}" '
        f'iyy="{f(i[1, 1])}" iyz="{f(i[1, 2])}" izz="{f(i[2, 2])}"/>',
        "    </inertial>",
        "    <visual>",
        '      <origin xyz="0 0 0" rpy="0 0 0"/>',
        f'      <geometry><mesh filename="{visual_file}" scale="1 1 1"/></geometry>',
        "    </visual>",
        f"    <collision{concave}>",
        '      <origin xyz="0 0 0" rpy="0 0 0"/>',
        f"      <geometry>{_geometry_xml(col)}</geometry>",
        "    </collision>",
        "  </link>",
        "</robot>",
        "",
    ])


MTL_NAME = "visual_geometry.mtl"
TEXTURE_NAME = "texture.png"


def mtl_text(material_name: str) -> str:
    """A matte material whose diffuse colour is the image ``texture.png`` (white × texture)."""
    return "\n".join([f"newmtl {material_name}", "Ka 0 0 0", "Kd 1 1 1", "Ks 0 0 0", "Ns 0",
                      "d 1", "illum 1", f"map_Kd {TEXTURE_NAME}", ""])


def _write_visual_obj(mesh, path: Path, material: str | None = None) -> None:
    """z-up OBJ with UVs when the mesh has them; ``material``: use that material of
    ``visual_geometry.mtl`` (written by the caller) for every face."""
    f = physics.fmt
    lines = [f"mtllib {MTL_NAME}"] if material else []
    lines += ["v " + " ".join(f(x) for x in v) for v in mesh.vertices]
    uv = getattr(mesh.visual, "uv", None)
    if uv is not None and len(uv) == len(mesh.vertices):
        lines += ["vt " + " ".join(f(x) for x in t) for t in uv]
        lines += [f"usemtl {material}"] if material else []
        lines += ["f " + " ".join(f"{i + 1}/{i + 1}" for i in face) for face in mesh.faces]
    else:
        if material:
            raise InputError("a textured OBJ needs UVs: the mesh has none (or not one per vertex)")
        lines += ["f " + " ".join(str(i + 1) for i in face) for face in mesh.faces]
    path.write_text("\n".join(lines) + "\n")


def package_object(asset_id: str, visual, out_dir: str | os.PathLike, *, collision: Collision,
                   license: str, metadata: dict | None = None, physics_parts=None,
                   visual_format: str = "obj", static: bool = False,
                   extra_kwargs: dict | None = None, texture_png: bytes | None = None,
                   visual_parts=None) -> dict:
    """Centre, measure and write one FileBasedObject asset; return its manifest entry.

    Args:
      visual: trimesh mesh (z up, metres) as it should look.
      collision: see :class:`Collision`; hull coordinates are in the same frame as ``visual``.
      physics_parts: closed meshes whose mass properties define the object (default: the
        collision hulls, or ``visual`` itself for primitive collision shapes).
      static: static objects get mass 0 and ``static: true``.
      texture_png: PNG bytes; with an OBJ visual (which must have UVs) the archive gets
        ``texture.png`` and ``visual_geometry.mtl`` (material ``<asset_id>``, ``map_Kd`` = the PNG).
      visual_parts: trimeshes in ``visual``'s frame, each with its own material, written as the
        primitives of the GLB visual instead of ``visual`` (which still gives bounds and sizes).
    """
    out_dir = Path(out_dir)
    metadata = dict(metadata or {})
    if static:
        props = {"volume": 0.0, "center_mass": np.zeros(3), "inertia": np.zeros((3, 3))}
    else:
        if physics_parts is None:
            physics_parts = collision.hulls if collision.kind == "hulls" else [visual]
        props = physics.mass_properties(physics_parts)
    com = props["center_mass"]
    inertia = np.asarray(props["inertia"], dtype=np.float64)
    inertia = np.where(np.abs(inertia) < 1e-12 * max(np.trace(inertia), 1e-30), 0.0, inertia)
    props["inertia"] = inertia
    visual = visual.copy()
    visual.apply_translation(-com)
    if visual_parts is not None:
        if visual_format != "glb":
            raise InputError(f"{asset_id}: visual_parts need visual_format 'glb', got "
                             f"{visual_format!r}")
        visual_parts = [p.copy() for p in visual_parts]
        for part in visual_parts:
            part.apply_translation(-com)
    hulls = []
    for h in collision.hulls:
        h = h.copy()
        h.apply_translation(-com)
        hulls.append(h)
    bounds = np.stack([visual.vertices.min(axis=0), visual.vertices.max(axis=0)])
    mass = props["volume"]
    vis_name = f"visual_geometry.{visual_format}"
    urdf_visual = vis_name if visual_format == "obj" else "collision_geometry.obj"
    metadata.update({
        "nr_faces": int(len(visual.faces)), "nr_vertices": int(len(visual.vertices)),
        "volume": props["volume"], "surface_area": float(visual.area),
        "inertia": props["inertia"], "collision": collision.kind,
        "collision_method": collision.method or collision.kind,
    })
    kwargs = {"bounds": bounds, "mass": mass,
              "render_filename": "{asset_dir}/" + vis_name,
              "simulation_filename": "{asset_dir}/object.urdf"}
    if visual_format == "obj":
        kwargs["render_import_kwargs"] = dict(OBJ_IMPORT_KWARGS)
    if static:
        kwargs["static"] = True
    kwargs.update(extra_kwargs or {})
    entry = clean_number({"id": asset_id, "asset_type": "FileBasedObject", "license": license,
                          "kwargs": kwargs, "metadata": metadata})
    archive = out_dir / f"{asset_id}.tar.gz"
    archive.parent.mkdir(parents=True, exist_ok=True)
    with staging(archive.parent) as stage:
        if visual_format == "obj":
            material = None
            if texture_png is not None:
                material = "".join(c if c.isalnum() else "_" for c in asset_id)
                (stage / MTL_NAME).write_text(mtl_text(material))
                (stage / TEXTURE_NAME).write_bytes(bytes(texture_png))
            _write_visual_obj(visual, stage / vis_name, material)
        elif texture_png is not None:
            raise InputError(f"{asset_id}: texture_png is only supported with visual_format "
                             f"'obj', got {visual_format!r}")
        elif visual_format == "glb":
            write_visual_glb(visual if visual_parts is None else visual_parts, stage / vis_name)
        else:
            raise InputError(f"visual_format must be 'obj' or 'glb', got {visual_format!r}")
        if collision.kind == "concave":
            _write_visual_obj(visual, stage / "collision_geometry.obj")
        else:
            write_hulls_or_hull(hulls, visual, stage / "collision_geometry.obj")
        name = "".join(c if c.isalnum() else "_" for c in asset_id)
        (stage / "object.urdf").write_text(urdf_text(name, mass, props["inertia"], collision,
                                                     urdf_visual))
        (stage / "data.json").write_text(dumps(entry))
        write_archive(stage, archive)
    return entry


def write_hulls_or_hull(hulls, visual, path: Path) -> None:
    """Write ``hulls``, or the visual mesh's convex hull when there are none (convex primitives)."""
    physics.write_hulls_obj(hulls if hulls else [visual.convex_hull], path)


def package_texture(asset_id: str, image_path: str | os.PathLike, out_dir: str | os.PathLike, *,
                    license: str, metadata: dict | None = None,
                    extra_kwargs: dict | None = None) -> dict:
    """Write a Texture asset (an image, e.g. an HDRI) and return its manifest entry."""
    image_path = Path(image_path)
    out_dir = Path(out_dir)
    fname = "texture" + image_path.suffix.lower()
    kwargs = {"filename": "{asset_dir}/" + fname, "mapping": "environment"}
    kwargs.update(extra_kwargs or {})
    entry = clean_number({"id": asset_id, "asset_type": "Texture", "license": license,
                          "kwargs": kwargs, "metadata": dict(metadata or {})})
    archive = out_dir / f"{asset_id}.tar.gz"
    archive.parent.mkdir(parents=True, exist_ok=True)
    with staging(archive.parent) as stage:
        shutil.copyfile(image_path, stage / fname)
        (stage / "data.json").write_text(dumps(entry))
        write_archive(stage, archive)
    return entry
