"""Deformable cloth (kubric.core.deformables): the model, the PyBullet soft body, the raycast
render and the tracks, checked on real output against independent derivations."""

import hashlib
import os
import subprocess
import sys

import numpy as np
import pytest
import trimesh

import kubric as kb
from kubric.core.deformables import cloth_grid
from kubric.errors import InputError

FRAMES = 7
BALL_RADIUS = 0.25

# a cloth falls onto a ball resting on the floor: the scene the module fixture simulates, renders
# and tracks, and the determinism test runs in two fresh processes
SCENE_CODE = """
import kubric as kb
from kubric.simulator.pybullet import PyBullet

def cloth_scene(with_cloth=True, simulator_first=False):
    scene = kb.Scene(resolution=(32, 32), frame_start=0, frame_end=6, frame_rate=12,
                     step_rate=240)
    sim = PyBullet(scene) if simulator_first else None
    scene += kb.Cube(name="floor", scale=(3, 3, 0.1), position=(0, 0, -0.1), static=True)
    ball = kb.Sphere(name="ball", scale=0.25, position=(0.1, 0, 0.25), mass=1.0)
    scene += ball
    cloth = kb.Deformable.cloth(size=(1, 1), resolution=(12, 12), position=(0, 0, 0.8),
                                name="cloth")
    if with_cloth:
        scene += cloth
    scene += kb.DirectionalLight(position=(1, -1, 3), look_at=(0, 0, 0), intensity=1.5)
    scene.camera = kb.PerspectiveCamera(position=(0, -2.5, 2.0), look_at=(0, 0, 0.3))
    sim = sim or PyBullet(scene)
    sim.run(0, 6)
    sim.close()
    return scene, ball, cloth


def soft_scene():
    scene = kb.Scene(resolution=(32, 32), frame_start=0, frame_end=6, frame_rate=12,
                     step_rate=240)
    scene += kb.Cube(name="floor", scale=(3, 3, 0.1), position=(0, 0, -0.1), static=True)
    cube = kb.Cube(name="cube", scale=0.15, position=(0.05, 0, 0.15), mass=1.0)
    scene += cube
    toy = kb.Deformable.soft_box(position=(0, 0, 0.7), euler=(0.3, 0.2, 0), name="toy",
                                 mass=0.5)
    scene += toy
    scene += kb.DirectionalLight(position=(1, -1, 3), look_at=(0, 0, 0), intensity=1.5)
    scene.camera = kb.PerspectiveCamera(position=(0, -2.0, 1.2), look_at=(0, 0, 0.3))
    sim = PyBullet(scene)
    sim.run(0, 6)
    sim.close()
    return scene, cube, toy
"""


def _digest(cloth) -> str:
    return hashlib.sha256(np.stack([cloth.deformed_vertices(f) for f in range(FRAMES)])
                          .tobytes()).hexdigest()


namespace: dict = {}
exec(SCENE_CODE, namespace)
cloth_scene, soft_scene = namespace["cloth_scene"], namespace["soft_scene"]
MESH_RADIUS = 0.3


def mesh_scene():
    """A soft ball tetrahedralised from a closed mesh (an icosphere) falls onto a cube."""
    from kubric.simulator.pybullet import PyBullet
    scene = kb.Scene(resolution=(32, 32), frame_start=0, frame_end=6, frame_rate=12,
                     step_rate=240)
    scene += kb.Cube(name="floor", scale=(3, 3, 0.1), position=(0, 0, -0.1), static=True)
    cube = kb.Cube(name="cube", scale=0.15, position=(0.05, 0, 0.15), mass=1.0)
    scene += cube
    ball = trimesh.creation.icosphere(2, radius=MESH_RADIUS)
    toy = kb.Deformable.soft_mesh(ball.vertices, ball.faces, position=(0, 0, 0.7), mass=0.5,
                                  name="mesh_toy")
    scene += toy
    scene += kb.DirectionalLight(position=(1, -1, 3), look_at=(0, 0, 0), intensity=1.5)
    scene.camera = kb.PerspectiveCamera(position=(0, -2.0, 1.2), look_at=(0, 0, 0.3))
    PyBullet(scene).run(0, 6)
    return scene, cube, toy


@pytest.fixture(scope="module", params=["cloth", "soft", "mesh"])
def rendered(request):
    """(scene, the rigid object, the deformable, raycast layers, tracks) of the cloth scene and
    of the soft-box scene (a squishy box falls onto a cube) and of the soft-mesh scene."""
    pytest.importorskip("embreex")
    from kubric.annotations.tracks import scene_tracks
    from kubric.renderer.raycast import Raycast
    make = {"cloth": cloth_scene, "soft": soft_scene, "mesh": mesh_scene}[request.param]
    scene, rigid, deformable = make()
    layers = Raycast(scene).render()
    tracks = scene_tracks(scene, layers, [rigid, deformable], np.random.RandomState(0),
                          num_tracks=64, stride=2)
    return scene, rigid, deformable, layers, tracks


# ---------------------------------------------------------------------------------- model
def test_cloth_grid_layout_and_uv():
    v, f, uv = cloth_grid((2.0, 1.0), (3, 2))
    assert v.shape == (6, 3) and f.shape == (4, 3) and uv.shape == (4, 3, 2)
    assert np.allclose(v[[0, 2, 3, 5]], [[-1, -.5, 0], [1, -.5, 0], [-1, .5, 0], [1, .5, 0]])
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    assert np.all(normals[:, 2] > 0)  # counter-clockwise from +z
    # uv is the vertex position normalised over the sheet
    assert np.allclose(uv, (v[f][..., :2] - [-1, -0.5]) / [2.0, 1.0])


@pytest.mark.parametrize("kwargs,message", [
    (dict(size=(0, 1)), "size must be two positive numbers"),
    (dict(resolution=(1, 4)), "resolution must be two integers ≥ 2"),
    (dict(resolution=(2.5, 4)), "resolution must be two integers ≥ 2"),
])
def test_cloth_grid_bad_input_is_one_line(kwargs, message):
    with pytest.raises(InputError, match=message):
        cloth_grid(**kwargs)


@pytest.mark.parametrize("kwargs,message", [
    (dict(faces=[[0, 1, 3]]), r"faces holds 3; allowed: \[0, 2\]"),
    (dict(faces=[[0, 1, 1]]), "face 0 repeats a vertex"),
    (dict(kind="jelly"), r"kind 'jelly' is not one of \['cloth', 'soft'\]"),
    (dict(static=True), "static must be False"),
])
def test_deformable_bad_input_is_one_line(kwargs, message):
    args = dict(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]]) | kwargs
    with pytest.raises(InputError, match=message):
        kb.Deformable(**args)


def test_simulated_vertices_shape_checked_and_interpolated_linearly():
    cloth = kb.Deformable.cloth(resolution=(2, 2), position=(0, 0, 1), scale=2)
    assert np.allclose(cloth.deformed_vertices()[:, 2], 1) and np.allclose(
        np.ptp(cloth.deformed_vertices()[:, 0]), 2)  # the rest mesh placed by the pose
    with pytest.raises(InputError, match=r"simulated_vertices must have shape \(4, 3\)"):
        cloth.simulated_vertices = np.zeros((3, 3))
    a, b = np.zeros((4, 3)), np.arange(12.0).reshape(4, 3)
    cloth.record(0, a)
    cloth.record(2, b)
    assert np.allclose(cloth.deformed_vertices(0.5), 0.25 * b)
    assert np.allclose(cloth.deformed_vertices(7), b)  # held after the last key
    assert np.allclose(cloth.surface_points([0], [[1, 0, 0]], 2), b[cloth.faces[0, 0]])


# ---------------------------------------------------------------------------------- simulation
def test_same_seed_same_vertices_in_two_processes():
    code = SCENE_CODE + (
        "\nimport hashlib, numpy as np\nfor make in (cloth_scene, soft_scene):\n"
        "    c = make()[2]\n"
        "    print(hashlib.sha256(np.stack([c.deformed_vertices(f) for f in range(7)])"
        ".tobytes()).hexdigest())\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           env=env, check=True).stdout.split()[-2:] for _ in range(2)]
    here = [_digest(cloth_scene()[2]), _digest(soft_scene()[2])]
    assert runs[0] == runs[1] == here


def test_a_cloth_added_to_a_running_simulator_reopens_it_as_a_deformable_world():
    # MOVi makes its simulator before the objects: the first deformable rebuilds every body
    # from the model, so the result is the one of a simulator made after the objects
    _, ball_a, cloth_a = cloth_scene(simulator_first=True)
    _, ball_b, cloth_b = cloth_scene()
    assert _digest(cloth_a) == _digest(cloth_b)
    assert np.array_equal(ball_a.get_values_over_time("position"),
                          ball_b.get_values_over_time("position"))


def test_cloth_falls_drapes_and_pushes_the_ball():
    _, ball_alone, _ = cloth_scene(with_cloth=False)
    scene, ball, cloth = cloth_scene()
    rest = cloth.deformed_vertices(0)
    assert np.allclose(rest[:, 2], 0.8, atol=1e-6)  # frame 0: the rest state
    assert cloth.deformed_vertices(6)[:, 2].min() < 0.3  # it fell
    # two-way: alone the ball rests still; under the cloth it is pushed
    assert np.allclose(ball_alone.get_value_at("position", 6), (0.1, 0, 0.25), atol=1e-4)
    assert np.linalg.norm(np.subtract(ball.get_value_at("position", 6), (0.1, 0, 0.25))) > 1e-3


def test_no_soft_box_vertex_deeper_in_the_cube_or_floor_than_the_margin():
    _, cube, toy = soft_scene()
    margin = toy.collision_margin
    assert toy.deformed_vertices(6)[:, 2].min() < 0.32  # it fell onto the cube (top: z 0.3)
    for f in range(FRAMES):
        v = toy.deformed_vertices(f)
        with cube.at_frame(f):
            m, half = cube.matrix_world, np.asarray(cube.scale)
        local = (v - m[:3, 3]) @ m[:3, :3]                       # the cube's unscaled frame
        # box signed distance: inside it is −(the distance to the nearest face)
        inside = np.all(np.abs(local) < half, axis=1)
        depth = np.where(inside, (half - np.abs(local)).min(axis=1), 0.0)
        assert depth.max() < margin, f
        assert v[:, 2].min() > -margin, f


def test_soft_box_mesh_is_a_closed_positive_tetrahedral_solid():
    from kubric.core import tet_meshes
    v, t, f, uv = tet_meshes.box((0.4, 0.2, 0.3), (2, 1, 3))
    assert len(v) == 3 * 2 * 4 and len(t) == 6 * 2 * 1 * 3
    vol = tet_meshes.signed_volumes(v, t)
    assert np.all(vol > 0) and np.isclose(vol.sum() / 6, 0.4 * 0.2 * 0.3)
    # the surface is closed (every edge in two faces) and faces outwards (divergence theorem)
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    assert np.all(np.unique(edges, axis=0, return_counts=True)[1] == 2)
    tri = v[f]
    enclosed = np.einsum("ij,ij->i", np.cross(tri[:, 1], tri[:, 2]), tri[:, 0]).sum() / 6
    assert np.isclose(enclosed, 0.4 * 0.2 * 0.3)
    assert uv.shape == (len(f), 3, 2) and uv.min() >= 0 and uv.max() <= 1


@pytest.mark.parametrize("kwargs,message", [
    (dict(kind="soft"), r"a soft solid needs tetrahedra \(T, 4\)"),
    (dict(kind="soft", tetrahedra=[[0, 2, 1, 3]]), "tetrahedron 0 is not positive"),
    (dict(tetrahedra=[[0, 1, 2, 3]]), "a cloth has no tetrahedra"),
])
def test_soft_solid_bad_input_is_one_line(kwargs, message):
    args = dict(vertices=np.eye(4, 3)[[3, 0, 1, 2]], faces=[[0, 2, 1]]) | kwargs
    with pytest.raises(InputError, match=message):
        kb.Deformable(**args)


def test_no_cloth_vertex_deeper_in_a_collider_than_the_margin():
    scene, ball, cloth = cloth_scene()
    margin = cloth.collision_margin
    for f in range(FRAMES):
        v = cloth.deformed_vertices(f)
        centre = np.asarray(ball.get_value_at("position", f))
        # sphere: signed distance |v − c| − r; floor: its top face is z = 0
        assert np.linalg.norm(v - centre, axis=1).min() - BALL_RADIUS > -margin, f
        assert v[:, 2].min() > -margin, f


# ---------------------------------------------------------------------------------- render + tracks
def test_tracks_on_the_deformable_match_forward_flow(rendered):
    _, _, _, layers, tracks = rendered
    q = tracks["query_points"]
    errors = []
    for i in np.flatnonzero(tracks["instance_id"] == 2):
        t, r, c = int(q[i, 0]), int(q[i, 1]), int(q[i, 2])
        if t + 1 < FRAMES:
            step = tracks["target_points"][i, t + 1] - tracks["target_points"][i, t]  # (x, y)
            errors.append(np.abs(step[::-1] - layers["forward_flow"][t, r, c]).max())
    assert len(errors) >= 20
    assert np.median(errors) < 1e-3
    moving = np.abs(layers["forward_flow"][:-1][layers["segmentation"][:-1, ..., 0] == 3])
    assert moving.max() > 0.5  # the cloth really moves on screen


def test_visible_deformable_track_points_keep_their_instance(rendered):
    _, _, _, layers, tracks = rendered
    seg = layers["segmentation"][..., 0]
    for i in np.flatnonzero(tracks["instance_id"] == 2):
        for t in np.flatnonzero(~tracks["occluded"][i]):
            x, y = tracks["target_points"][i, t]
            assert seg[t, int(y), int(x)] == 3  # the cloth's label (third asset)


def test_deformable_track_is_a_fixed_barycentric_point_of_the_simulated_mesh(rendered):
    _, _, cloth, _, tracks = rendered
    sel = np.flatnonzero(tracks["instance_id"] == 2)
    world = tracks["points_world"][sel].astype(np.float64)
    q_t = tracks["query_points"][sel, 0].astype(int)
    # the material point: the triangle of the query frame's simulated mesh that contains the
    # tracked point (inside it and on its plane), and the point's barycentrics there (trimesh)
    tri, bary = np.zeros(len(sel), int), np.zeros((len(sel), 3))
    for n in range(len(sel)):
        tris = cloth.deformed_vertices(int(q_t[n]))[cloth.faces]
        p = world[n, q_t[n]]
        b = trimesh.triangles.points_to_barycentric(tris, np.broadcast_to(p, (len(tris), 3)))
        off = np.abs(np.einsum("fk,fkj->fj", b, tris) - p).max(axis=1)
        inside = np.flatnonzero((b.min(axis=1) > -1e-4) & (off < 1e-5))
        assert len(inside), n
        tri[n], bary[n] = inside[0], b[inside[0]]
    for f in range(FRAMES):
        verts = cloth.deformed_vertices(f)[cloth.faces[tri]]
        assert np.abs(np.einsum("nk,nkj->nj", bary, verts) - world[:, f]).max() < 1e-4, f


def test_object_coordinates_are_rest_state_points(rendered):
    _, _, deformable, layers, _ = rendered
    on = layers["segmentation"][..., 0] == 3
    objc, uv = layers["object_coordinates"][on], layers["uv"][on]
    if deformable.name == "mesh_toy":
        # the rest icosphere's surface (its flat triangles sag at most 2 % inside the sphere)
        assert on.sum() > 100
        lo, hi = deformable.rest_bounds
        radius = np.linalg.norm(objc * (hi - lo) + lo, axis=1)
        assert radius.max() < MESH_RADIUS + 1e-5 and radius.min() > 0.98 * MESH_RADIUS
        return
    if deformable.kind == "soft":
        # the rest box's surface: one coordinate of every point is 0 or 1, however squashed
        assert on.sum() > 300
        assert np.minimum(objc, 1 - objc).min(axis=1).max() < 1e-5
        assert np.ptp(objc, axis=0).min() > 0.5
        return
    # rest sheet: object x, y over its bounds = the grid's (u, v), wherever the cloth has moved
    assert on.sum() > 300
    assert np.abs(objc[:, :2] - uv[:, :2]).max() < 1e-5
    assert np.all(objc[:, 2] == 0)


def test_a_blown_up_cloth_simulation_is_one_line():
    # a real blow-up (a 24² sheet at stiffness 200 on a ball) takes a minute of exploding
    # contacts: the check runs on the meshes such a run records
    from kubric.simulator.deformables import check_stable
    cloth = kb.Deformable.cloth(resolution=(3, 3), name="cloth")
    rest = cloth.deformed_vertices()
    check_stable(cloth, [0, 1], [rest, rest * 9.9])  # within 10× of the rest length: fine
    for bad, what in ((rest * 10.5, r"10\.5×"), (np.where(rest == rest[0], np.nan, rest), "inf×")):
        with pytest.raises(InputError, match=r"cloth: the cloth simulation blew up at frame 1 "
                                             rf"\(an edge stretched {what} its rest length; "
                                             r"allowed ≤ 10×\): raise the scene's step_rate"):
            check_stable(cloth, [0, 1], [rest, bad])


def test_cloth_lands_on_a_walking_person():
    # people are kinematic colliders (kubric.simulator.characters): the cloth stops on the head
    from kubric.assets.procedural_character import tube_person, walk_clip
    from kubric.simulator.pybullet import PyBullet
    scene = kb.Scene(frame_start=0, frame_end=6, frame_rate=12, step_rate=240)
    scene += kb.Cube(name="floor", scale=(3, 3, 0.1), position=(0, 0, -0.1), static=True)
    person = tube_person()
    scene += person
    person.play(walk_clip(seconds=1.0))
    top = float(person.aabb(0)[1, 2])
    cloth = kb.Deformable.cloth(size=(1, 1), resolution=(8, 8), position=(0, 0, top + 0.3))
    scene += cloth
    PyBullet(scene).run(0, 6)
    # in free fall it would be 0.5 · 9.81 · 0.5² = 1.23 m lower by frame 6
    assert cloth.deformed_vertices(6)[:, 2].max() > top - 0.2
    assert cloth.deformed_vertices(6)[:, 2].min() < top - 0.05  # it drapes


def test_instance_metadata_follows_the_simulated_mesh():
    # the cloth falls freely for the first frames (it starts 0.55 m above the ball's top):
    # its centroid's velocity is then −g·t (a parabola: the central difference is exact)
    from kubric.annotations.metadata import get_instance_info
    scene, ball, cloth = cloth_scene()
    info = get_instance_info(scene, [cloth], frames=list(range(FRAMES)))[0]
    for f in range(FRAMES):
        assert np.allclose(info["positions"][f], cloth.deformed_vertices(f).mean(axis=0),
                           atol=1e-6)
    assert np.ptp(info["positions"][:, 2]) > 0.3  # no longer the constant rest placement
    for f in (1, 2):
        assert abs(info["velocities"][f, 2] + 9.81 * f / 12) < 0.05 * 9.81 * f / 12, f
    assert np.allclose(info["velocities"][:3, :2], 0, atol=1e-3)
