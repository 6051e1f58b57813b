"""Deformables in PyBullet: a :class:`~kubric.core.deformables.Deformable` becomes a soft body,
two-way coupled with the rigid bodies (it pushes them, they push it): a cloth a mass-spring body
(``pybullet.loadSoftBody`` of an OBJ of its current world vertices), a soft solid a NeoHookean
body (of a VTK file of its vertices and tetrahedra).

PyBullet simulates soft bodies only in its *deformable world*
(``resetSimulation(RESET_USE_DEFORMABLE_WORLD)``, a different dynamics world with its own solver),
which replaces the engine's world: :class:`kubric.simulator.pybullet.PyBullet` opens it when the
first deformable joins (at construction or later) and rebuilds every body from the model.
Facts measured for the choice (docs/deformables.md): the soft body keeps the file's vertex order;
its nodes are read each frame with ``getMeshData(..., MESH_DATA_SIMULATION_MESH)``; the same scene
gives bit-identical nodes in two processes; a spring cloth is stable at 240 steps/s up to about
24 × 24 vertices per square metre with ``collision_margin`` 0.02 m (finer sheets need more steps).
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from dataclasses import dataclass

import numpy as np
import pybullet as pb

from kubric.errors import InputError

#: float32 round trip of an OBJ's vertex through the engine (m): the check that the engine kept
#: the order of the vertices it was given
_ORDER_TOLERANCE = 1e-5


@dataclass
class SoftBody:
    """The engine side of one deformable (``uid`` None: not built)."""

    uid: int | None = None


def write_obj(path: str, vertices: np.ndarray, faces: np.ndarray) -> None:
    """A plain OBJ (``v`` / ``f`` lines, 1-based) of world vertices (V, 3) and faces (F, 3)."""
    with open(path, "w", encoding="ascii") as f:
        f.writelines(f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in vertices)
        f.writelines(f"f {a} {b} {c}\n" for a, b, c in np.asarray(faces, np.int64) + 1)


def write_vtk(path: str, vertices: np.ndarray, tetrahedra: np.ndarray) -> None:
    """A legacy ASCII VTK unstructured grid of world vertices (V, 3) and tetrahedra (T, 4)."""
    with open(path, "w", encoding="ascii") as f:
        f.write("# vtk DataFile Version 2.0\nkubric soft body\nASCII\n"
                f"DATASET UNSTRUCTURED_GRID\nPOINTS {len(vertices)} double\n")
        f.writelines(f"{x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in vertices)
        f.write(f"CELLS {len(tetrahedra)} {5 * len(tetrahedra)}\n")
        f.writelines(f"4 {a} {b} {c} {d}\n" for a, b, c, d in np.asarray(tetrahedra, np.int64))
        f.write(f"CELL_TYPES {len(tetrahedra)}\n" + "10\n" * len(tetrahedra))


@contextlib.contextmanager
def _quiet_stdout():
    """PyBullet's VTK reader prints node / link / face / tetra counts on the C stdout: send the
    process's file descriptor 1 to /dev/null meanwhile (a worker's stdout stays its own)."""
    sys.stdout.flush()
    keep, sink = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    os.dup2(sink, 1)
    try:
        yield
    finally:
        os.dup2(keep, 1)
        os.close(keep)
        os.close(sink)


def _load(deformable, path: str, client: int) -> int:
    common = dict(basePosition=(0.0, 0.0, 0.0), scale=1.0, mass=float(deformable.mass),
                  useSelfCollision=0, frictionCoeff=float(deformable.friction), useFaceContact=1,
                  collisionMargin=float(deformable.collision_margin), physicsClientId=client)
    if deformable.kind == "soft":
        mu, lam, damping = (float(x) for x in deformable.neo_hookean)
        with _quiet_stdout():
            return pb.loadSoftBody(path, useNeoHookean=1, NeoHookeanMu=mu, NeoHookeanLambda=lam,
                                   NeoHookeanDamping=damping, **common)
    return pb.loadSoftBody(path, useNeoHookean=0, useBendingSprings=1, useMassSpring=1,
                           springElasticStiffness=float(deformable.stiffness),
                           springDampingStiffness=float(deformable.damping),
                           springDampingAllDirections=1, **common)


def build(deformable, client: int) -> SoftBody:
    """A soft body of ``deformable`` at its current vertices (module doc)."""
    verts = deformable.deformed_vertices()
    soft = deformable.kind == "soft"
    fd, path = tempfile.mkstemp(suffix=".vtk" if soft else ".obj", prefix="kubric_soft_")
    os.close(fd)
    try:
        if soft:
            write_vtk(path, verts, deformable.tetrahedra)
        else:
            write_obj(path, verts, deformable.faces)
        uid = _load(deformable, path, client)
    finally:
        os.unlink(path)
    if uid < 0:
        raise RuntimeError(f"{deformable.uid}: PyBullet could not build its soft body")
    nodes = read(uid, client)
    if nodes.shape != verts.shape or np.abs(nodes - verts).max() > _ORDER_TOLERANCE:
        pb.removeBody(uid, physicsClientId=client)
        raise RuntimeError(f"{deformable.uid}: PyBullet's soft body does not keep the mesh's "
                           f"{len(verts)} vertices in order (got {len(nodes)} nodes)")
    return SoftBody(uid)


def read(uid: int, client: int) -> np.ndarray:
    """(V, 3) float64 world positions of a soft body's nodes."""
    _, nodes = pb.getMeshData(uid, -1, flags=pb.MESH_DATA_SIMULATION_MESH,
                              physicsClientId=client)
    return np.asarray(nodes, np.float64).reshape(-1, 3)


#: an edge stretched beyond this multiple of its rest length means the simulation diverged (a
#: hard impact stretches a sheet up to about 3× for a frame, then it recovers; a blow-up
#: reaches hundreds)
MAX_STRETCH = 10.0


def check_stable(deformable, frames, meshes) -> None:
    """One line when the simulated ``meshes`` (per frame (V, 3)) of ``deformable`` blew up (a
    non-finite vertex or an edge over :data:`MAX_STRETCH` × its rest length): a mass-spring
    sheet needs a time step below about its spacing × sqrt(node mass / stiffness)."""
    f = np.asarray(deformable.faces, np.int64)
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    rest = np.linalg.norm(deformable.vertices[edges[:, 0]] - deformable.vertices[edges[:, 1]],
                          axis=1) * float(np.max(deformable.scale))
    for frame, verts in zip(frames, meshes, strict=True):
        stretch = np.linalg.norm(verts[edges[:, 0]] - verts[edges[:, 1]], axis=1) / rest
        if not np.isfinite(verts).all() or stretch.max() > MAX_STRETCH:
            raise InputError(f"{deformable.uid}: the cloth simulation blew up at frame {frame} "
                             f"(an edge stretched {np.nan_to_num(stretch.max(), nan=np.inf):.3g}× "
                             f"its rest length; allowed ≤ {MAX_STRETCH:g}×): raise the scene's "
                             "step_rate, or lower the cloth's resolution or stiffness, or raise "
                             "its mass")


def remove(body: SoftBody, client: int) -> None:
    if body.uid is not None:
        pb.removeBody(body.uid, physicsClientId=client)
        body.uid = None
