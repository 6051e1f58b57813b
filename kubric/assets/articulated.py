"""Multi-link (articulated) URDFs: every link simulated and rendered.

:func:`link_visuals` reads a URDF's ``<link><visual>`` elements (``origin`` xyz / rpy; geometry
``mesh`` (file + ``scale``), ``box``, ``sphere``, ``cylinder`` or ``capsule``, axis z) and
:func:`export_link_meshes` writes one GLB per link that has visuals, in that link's URDF frame
(metres, z up; written by :func:`kubric.assets.glb.write_visual_glb`: glTF files are y up, so
Blender's importer brings them in z up).

:func:`add_articulated` adds such a URDF to a scene: the base link is a
:class:`~kubric.core.objects.FileBasedObject` whose ``simulation_filename`` is the URDF (PyBullet
loads it with its joints, motors off, so it moves passively), and every other link with a visual
is an unsimulated ``FileBasedObject`` that the PyBullet view poses from the link's frame each
frame (see :meth:`kubric.simulator.PyBullet.attach_links`). Each link is a scene asset of its
own, so it has its own segmentation index.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from kubric.assets.glb import write_visual_glb
from kubric.core.imports import uninterrupted_import
from kubric.core.objects import FileBasedObject
from kubric.errors import InputError


def _floats(text, n, default):
    if text is None:
        return np.asarray(default, dtype=np.float64)
    vals = [float(v) for v in text.split()]
    if len(vals) == 1 and n == 3:
        vals = vals * 3
    if len(vals) != n:
        raise InputError(f"expected {n} numbers, got {text!r}")
    return np.asarray(vals, dtype=np.float64)


def _origin_matrix(elem) -> np.ndarray:
    trimesh = uninterrupted_import("trimesh")

    origin = elem.find("origin") if elem is not None else None
    xyz = _floats(origin.get("xyz") if origin is not None else None, 3, (0, 0, 0))
    rpy = _floats(origin.get("rpy") if origin is not None else None, 3, (0, 0, 0))
    mat = trimesh.transformations.euler_matrix(*rpy, axes="sxyz")
    mat[:3, 3] = xyz
    return mat


def _geometry_mesh(geom, urdf_dir: Path, where: str):
    trimesh = uninterrupted_import("trimesh")

    if geom is None or len(geom) == 0:
        raise InputError(f"{where}: <visual> without <geometry>")
    shape = geom[0]
    tag = shape.tag
    if tag == "box":
        return trimesh.creation.box(_floats(shape.get("size"), 3, (1, 1, 1)))
    if tag == "sphere":
        return trimesh.creation.icosphere(subdivisions=2, radius=float(shape.get("radius")))
    if tag == "cylinder":
        return trimesh.creation.cylinder(radius=float(shape.get("radius")),
                                         height=float(shape.get("length")), sections=24)
    if tag == "capsule":
        return trimesh.creation.capsule(radius=float(shape.get("radius")),
                                        height=float(shape.get("length")), count=[16, 16])
    if tag == "mesh":
        name = shape.get("filename", "")
        path = (urdf_dir / name.replace("package://", "")).resolve()
        if not path.is_file():
            raise FileNotFoundError(f"{where}: mesh {name!r} not found at {str(path)!r}")
        mesh = trimesh.load(str(path), force="mesh", process=True)
        if len(mesh.faces) == 0 or not np.all(np.isfinite(mesh.vertices)):
            raise InputError(f"{where}: mesh {name!r} is empty or has non-finite vertices")
        mesh.apply_scale(_floats(shape.get("scale"), 3, (1, 1, 1)))
        return mesh
    raise InputError(f"{where}: unsupported visual geometry <{tag}> (allowed: mesh, box, "
                     "sphere, cylinder, capsule)")


def link_visuals(urdf: str | os.PathLike) -> dict[str, object]:
    """``{link name: trimesh of all its visuals in the link frame}`` (links without visuals are
    left out); the first link of the file is the root."""
    trimesh = uninterrupted_import("trimesh")

    urdf = Path(urdf)
    try:
        root = ET.parse(urdf).getroot()
    except (ET.ParseError, OSError) as err:
        raise InputError(f"URDF {str(urdf)!r} is not readable XML: {err}") from None
    out = {}
    for link in root.findall("link"):
        name = link.get("name")
        parts = []
        for k, visual in enumerate(link.findall("visual")):
            where = f"{urdf.name}: link {name!r} visual {k}"
            mesh = _geometry_mesh(visual.find("geometry"), urdf.parent, where)
            mesh.apply_transform(_origin_matrix(visual))
            parts.append(trimesh.Trimesh(mesh.vertices, mesh.faces, process=False))
        if parts:
            out[name] = trimesh.util.concatenate(parts)
    return out


def export_link_meshes(urdf: str | os.PathLike, out_dir: str | os.PathLike) -> dict[str, Path]:
    """Write ``<out_dir>/<link>.glb`` for every link with visuals; returns ``{link: path}``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    for name, mesh in link_visuals(urdf).items():
        safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in name)
        path = out / f"{safe}.glb"
        write_visual_glb(mesh, path)
        paths[name] = path
    return paths


def root_link(urdf: str | os.PathLike) -> str:
    """Name of the URDF's root link (the one that is no joint's child)."""
    root = ET.parse(Path(urdf)).getroot()
    children = {j.find("child").get("link") for j in root.findall("joint")
                if j.find("child") is not None}
    roots = [lk.get("name") for lk in root.findall("link") if lk.get("name") not in children]
    if len(roots) != 1:
        raise InputError(f"URDF {str(urdf)!r} must have exactly one root link, found {roots}")
    return roots[0]


def add_articulated(scene, simulator, urdf: str | os.PathLike, mesh_dir: str | os.PathLike,
                    name: str = "articulated", **base_kwargs):
    """Add a multi-link URDF to ``scene`` (see the module docstring); returns
    ``(base, {link name: link object})``. ``base_kwargs`` (position, quaternion, scale, mass,
    ...) go to the base object; the link objects share its scale."""
    urdf = Path(urdf).resolve()
    meshes = export_link_meshes(urdf, mesh_dir)
    bounds = {link: mesh.bounds for link, mesh in link_visuals(urdf).items()}  # link frames
    base_link = root_link(urdf)
    if base_link in meshes:
        base_kwargs = {"render_filename": str(meshes[base_link]),
                       "bounds": bounds[base_link], **base_kwargs}
    base = FileBasedObject(name=name, simulation_filename=str(urdf), **base_kwargs)
    scene.add(base)
    links = {}
    for link, path in meshes.items():
        if link == base_link:
            continue
        obj = FileBasedObject(name=f"{name}_{link}", render_filename=str(path),
                              bounds=bounds[link], scale=base.scale,
                              metadata={"articulated_link": link, "articulated_base": name})
        scene.add(obj)
        links[link] = obj
    simulator.attach_links(base, links)
    return base, links
