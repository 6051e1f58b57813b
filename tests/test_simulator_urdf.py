"""FileBasedObject in the PyBullet view: URDF loading, scale, mass, centre of mass, bad inputs."""

import numpy as np
import pybullet as pb
import pytest

import kubric as kb
from kubric.simulator import PyBullet

BOX_URDF = """<?xml version="1.0"?>
<robot name="box">
  <link name="base">
    <inertial>
      <origin xyz="{com} 0 0" rpy="0 0 0"/>
      <mass value="2.0"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/>
    </inertial>
    <collision><geometry>{geometry}</geometry></collision>
  </link>
</robot>
"""

# a unit cube mesh (half extent 0.5), as an OBJ with 8 vertices and 12 triangles
CUBE_OBJ = "\n".join(
    [f"v {x} {y} {z}" for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
    + ["f 1 2 4", "f 1 4 3", "f 5 7 8", "f 5 8 6", "f 1 5 6", "f 1 6 2",
       "f 3 4 8", "f 3 8 7", "f 1 3 7", "f 1 7 5", "f 2 6 8", "f 2 8 4"]) + "\n"


@pytest.fixture
def box_urdf(tmp_path):
    path = tmp_path / "box.urdf"
    path.write_text(BOX_URDF.format(com=0, geometry='<box size="1 1 1"/>'))
    return path


@pytest.fixture
def mesh_urdf(tmp_path):
    (tmp_path / "cube.obj").write_text(CUBE_OBJ)
    path = tmp_path / "mesh.urdf"
    path.write_text(BOX_URDF.format(com=0, geometry='<mesh filename="cube.obj"/>'))
    return path


def _floor_scene():
    scene = kb.Scene(frame_start=0, frame_end=36)
    floor = kb.Cube(scale=(3, 3, 0.5), position=(0, 0, -0.5), static=True)
    scene.add(floor)
    return scene


@pytest.mark.parametrize("fixture", ["box_urdf", "mesh_urdf"])
def test_urdf_object_is_scaled_weighted_and_lands_on_the_floor(fixture, request):
    path = request.getfixturevalue(fixture)
    scene = _floor_scene()
    obj = kb.FileBasedObject(simulation_filename=str(path), scale=0.5, mass=1.5,
                             position=(0, 0, 1.0), bounds=((-0.5,) * 3, (0.5,) * 3))
    scene.add(obj)
    sim = PyBullet(scene)
    body = obj.linked_objects[sim].uid
    lo, hi = pb.getAABB(body, physicsClientId=sim.client)
    assert np.subtract(hi, lo) == pytest.approx((0.5, 0.5, 0.5), abs=0.02)
    assert pb.getDynamicsInfo(body, -1, physicsClientId=sim.client)[0] == pytest.approx(1.5)
    obj.mass = 3.0  # live change
    assert pb.getDynamicsInfo(body, -1, physicsClientId=sim.client)[0] == pytest.approx(3.0)
    animation, collisions = sim.run(0, 36)
    assert animation[obj]["position"][-1][2] == pytest.approx(0.25, abs=0.01)
    assert any(obj in c["instances"] for c in collisions)


def test_static_urdf_object_stays_put(box_urdf):
    scene = kb.Scene(frame_start=0, frame_end=6)
    obj = kb.FileBasedObject(simulation_filename=str(box_urdf), static=True, position=(0, 0, 5))
    scene.add(obj)
    animation, _ = PyBullet(scene).run(0, 6)
    assert animation[obj]["position"][-1] == (0.0, 0.0, 5.0)


def test_model_position_is_the_object_origin_not_the_centre_of_mass(tmp_path):
    path = tmp_path / "offset.urdf"
    path.write_text(BOX_URDF.format(com=0.5, geometry='<box size="1 1 1"/>'))
    scene = kb.Scene(frame_start=0, frame_end=24, gravity=(0, 0, 0))
    # spin at π rad/s about z around the centre of mass, which sits at origin + (0.5, 0, 0)
    omega = np.array([0.0, 0.0, np.pi])
    obj = kb.FileBasedObject(simulation_filename=str(path), position=(1, 2, 3),
                             angular_velocity=omega, velocity=np.cross(omega, (-0.5, 0, 0)))
    scene.add(obj)
    sim = PyBullet(scene)
    com, _ = pb.getBasePositionAndOrientation(obj.linked_objects[sim].uid,
                                              physicsClientId=sim.client)
    assert com == pytest.approx((1.5, 2.0, 3.0))
    animation, _ = sim.run(0, 24)
    pos = np.array(animation[obj]["position"])
    np.testing.assert_allclose(pos[0], (1, 2, 3), atol=1e-6)
    np.testing.assert_allclose(pos[-1], (2, 2, 3), atol=1e-4)  # half a turn around the COM
    np.testing.assert_allclose(pos[12], (1.5, 1.5, 3), atol=1e-4)  # quarter turn
    np.testing.assert_allclose(animation[obj]["velocity"][0], obj.keyframes["velocity"][0],
                               atol=1e-6)


def test_object_without_simulation_file_is_not_simulated_until_it_gets_one(box_urdf):
    scene = kb.Scene(frame_start=0, frame_end=3)
    obj = kb.FileBasedObject(render_filename="mesh.obj")
    scene.add(obj)
    sim = PyBullet(scene)
    animation, _ = sim.run()
    assert obj not in animation
    obj.simulation_filename = str(box_urdf)
    animation, _ = sim.run()
    assert len(animation[obj]["position"]) == 4


def test_non_uniform_scale_on_urdf_is_a_clear_error(box_urdf):
    scene = kb.Scene()
    sim = PyBullet(scene)
    with pytest.raises(ValueError, match=r"FileBasedObject.*uniform.*\[1\.0, 2\.0, 1\.0\]"):
        scene.add(kb.FileBasedObject(simulation_filename=str(box_urdf), scale=(1, 2, 1)))
    live = kb.FileBasedObject(name="live", simulation_filename=str(box_urdf))
    scene.add(live)
    with pytest.raises(ValueError, match=r"live.*uniform.*\[2\.0, 2\.0, 3\.0\]"):
        live.scale = (2, 2, 3)
    assert sim.check_overlap(live) is False  # the old body is still there and usable


def test_missing_or_non_urdf_file_is_a_clear_error(tmp_path, box_urdf):
    scene = kb.Scene()
    PyBullet(scene)
    missing = tmp_path / "nope.urdf"
    with pytest.raises(FileNotFoundError, match=r"ghost.*nope\.urdf.*does not exist"):
        scene.add(kb.FileBasedObject(name="ghost", simulation_filename=str(missing)))
    with pytest.raises(ValueError, match=r"meshy.*'\.obj'.*urdf"):
        scene.add(kb.FileBasedObject(name="meshy", simulation_filename=str(tmp_path / "a.obj")))
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot>not really</robot>")
    with pytest.raises(ValueError, match=r"broken.*could not load.*broken\.urdf"):
        scene.add(kb.FileBasedObject(name="broken", simulation_filename=str(broken)))
