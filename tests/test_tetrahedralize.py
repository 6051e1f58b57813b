"""Soft solids from closed meshes (kubric.core.tetrahedralize, Deformable.soft_mesh): the
tetrahedra fill the mesh (checked against trimesh's volume and area) and the simulated surface
is the input mesh; its tracks are checked in test_deformables.py (the "mesh" scene)."""

import numpy as np
import pytest
import trimesh

import kubric as kb
from kubric.core import tet_meshes
from kubric.core.tetrahedralize import tetrahedralize
from kubric.errors import InputError


def _area(vertices, faces):
    tri = np.asarray(vertices)[np.asarray(faces)]
    return np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum() / 2


@pytest.mark.parametrize("mesh", [trimesh.creation.icosphere(2, radius=0.4),
                                  trimesh.creation.cylinder(radius=0.3, height=0.5, sections=12),
                                  trimesh.creation.box((0.5, 0.3, 0.2))],
                         ids=["sphere", "cylinder", "box"])
def test_tetrahedra_fill_the_mesh_and_their_boundary_is_its_surface(mesh):
    assert mesh.is_watertight
    nodes, tets = tetrahedralize(mesh.vertices, mesh.faces, cells=4)
    v = len(mesh.vertices)
    assert np.array_equal(nodes[:v], mesh.vertices)  # the surface vertices first, unchanged
    vol = tet_meshes.signed_volumes(nodes, tets) / 6
    assert np.all(vol > 0)
    assert abs(vol.sum() - mesh.volume) < 1e-3 * mesh.volume
    assert np.array_equal(np.unique(tets), np.arange(len(nodes)))  # every node in a tetrahedron
    # the boundary: only surface vertices, closed, the surface's area (so no crack or void)
    boundary = tet_meshes.surface(nodes, tets)
    assert boundary.max() < v
    assert abs(_area(nodes, boundary) - mesh.area) < 1e-3 * mesh.area
    # interior nodes are inside, at least half a lattice spacing from the surface
    inner = nodes[v:]
    if len(inner):
        assert mesh.contains(inner).all()
        from scipy.spatial import cKDTree
        samples = trimesh.sample.sample_surface(mesh, 20000, seed=0)[0]
        assert cKDTree(samples).query(inner)[0].min() > 0.45 * max(mesh.extents) / 4


@pytest.mark.parametrize("edit,message", [
    (lambda f: f[1:], "has no opposite face"),
    (lambda f: f[:, ::-1], "encloses volume -"),
    (lambda f: np.concatenate([f, f[:1]]), "used twice in the same direction"),
])
def test_bad_meshes_are_one_line(edit, message):
    mesh = trimesh.creation.box()
    with pytest.raises(InputError, match=message):
        tetrahedralize(mesh.vertices, edit(np.asarray(mesh.faces)))


def test_soft_mesh_renders_the_input_faces():
    mesh = trimesh.creation.icosphere(1, radius=0.3)
    toy = kb.Deformable.soft_mesh(mesh.vertices, mesh.faces, position=(0, 0, 1), name="toy")
    assert toy.kind == "soft" and np.array_equal(toy.faces, mesh.faces)
    assert np.array_equal(toy.rendered_vertices, np.arange(len(mesh.vertices)))
    assert np.allclose(toy.aabb(), [[-0.3, -0.3, 0.7], [0.3, 0.3, 1.3]], atol=0.02)
