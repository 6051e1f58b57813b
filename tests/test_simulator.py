"""PyBullet view: free fall, time steps, bounces, collisions, property mapping, keyframes."""

import subprocess
import sys

import numpy as np
import pybullet as pb
import pytest

import kubric as kb
from kubric.core.views import View
from kubric.simulator import PyBullet


def test_simulator_package_is_lazy_and_reachable_from_kb():
    code = ("import sys, kubric as kb, kubric.simulator as s; "
            "assert 'pybullet' not in sys.modules; "
            "from kubric.simulator.pybullet import PyBullet; "
            "assert kb.simulator.PyBullet is s.PyBullet is PyBullet; print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


def _free_fall(step_rate):
    scene = kb.Scene(frame_start=0, frame_end=24, gravity=(0, -10, 0))
    scene.set_rates(24, step_rate)
    cube = kb.Cube(position=(0, 0, 0))
    scene.add(cube)
    sim = PyBullet(scene)
    animation, _ = sim.run(0, 24)
    sim.close()
    return cube, animation[cube]


@pytest.mark.parametrize("step_rate", [240, 480, 960])
def test_free_fall_follows_gravity_and_step_rate(step_rate):
    cube, track = _free_fall(step_rate)
    assert len(track["position"]) == 25
    y = track["position"][-1][1]
    assert abs(y + 5.0) < 0.1
    # Semi-implicit Euler after n steps of dt: y = -g dt² n (n + 1) / 2 = -5 (1 + 1/n) for t = 1 s,
    # so the exact value proves that 1/step_rate really is the time step.
    assert y == pytest.approx(-5.0 * (1 + 1 / step_rate), abs=1e-9)
    assert track["velocity"][-1][1] == pytest.approx(-10.0, abs=1e-9)
    assert track["position"][0] == (0.0, 0.0, 0.0) and track["velocity"][0] == (0.0, 0.0, 0.0)
    # Written back to the model: current value = last frame, one keyframe per frame.
    assert cube.position[1] == pytest.approx(y, abs=1e-6)
    assert sorted(cube.keyframes["position"]) == list(range(25))
    assert cube.get_value_at("position", 12)[1] == pytest.approx(track["position"][12][1], 1e-6)
    assert sorted(cube.keyframes["angular_velocity"]) == list(range(25))


def test_gravity_and_step_rate_follow_the_scene_after_creation():
    scene = kb.Scene(frame_start=0, frame_end=24)
    cube = kb.Cube()
    scene.add(cube)
    sim = PyBullet(scene)
    scene.gravity = (3.0, 0.0, 0.0)
    scene.set_rates(24, 480)
    animation, _ = sim.run(0, 24)
    x, _, z = animation[cube]["position"][-1]
    assert x == pytest.approx(1.5 * (1 + 1 / 480), abs=1e-9) and z == 0.0


def test_velocity_angular_velocity_and_pose_follow_the_model():
    scene = kb.Scene(frame_start=1, frame_end=25, gravity=(0, 0, 0))
    cube = kb.Cube(position=(1, 2, 3), velocity=(1.0, 0.0, 0.0))
    scene.add(cube)
    sim = PyBullet(scene)
    cube.angular_velocity = (0.0, 0.0, np.pi)  # after creation
    animation, _ = sim.run(1, 25)  # 24 frames = 1 s
    pos = np.array(animation[cube]["position"])
    np.testing.assert_allclose(pos[-1], (2.0, 2.0, 3.0), atol=1e-6)
    q = kb.Quaternion(animation[cube]["quaternion"][-1])  # WXYZ: half a turn about z
    axis, angle = q.axis_angle
    assert angle == pytest.approx(np.pi, abs=1e-4) and abs(axis[2]) == pytest.approx(1, abs=1e-6)
    np.testing.assert_allclose(animation[cube]["quaternion"][0], (1, 0, 0, 0), atol=1e-7)
    # quaternion half way: rotation by π/2 about z, WXYZ (cos π/4, 0, 0, sin π/4)
    np.testing.assert_allclose(np.abs(animation[cube]["quaternion"][12]),
                               (np.sqrt(0.5), 0, 0, np.sqrt(0.5)), atol=1e-4)
    assert sorted(cube.keyframes["quaternion"]) == list(range(1, 26))


def test_dynamics_properties_reach_the_engine_before_and_after_creation():
    scene = kb.Scene()
    cube = kb.Cube(mass=2.5, friction=0.3, restitution=0.7, scale=(1, 2, 3))
    scene.add(cube)
    sim = PyBullet(scene)
    body = cube.linked_objects[sim].uid

    def info():
        # (PyBullet does not report restitution of maximal-coordinate bodies: the bounce tests
        # prove it, set before and after creation.)
        info = pb.getDynamicsInfo(body, -1, physicsClientId=sim.client)
        return info[0], info[2], info[1]  # mass, inertia, lateral friction

    mass, inertia, friction = info()
    assert (mass, friction) == pytest.approx((2.5, 0.3))
    # box inertia m (b² + c²) / 3 for half extents (1, 2, 3)
    assert inertia == pytest.approx((2.5 * 13 / 3, 2.5 * 10 / 3, 2.5 * 5 / 3))
    cube.mass, cube.friction, cube.restitution = 4.0, 0.9, 0.1
    body = cube.linked_objects[sim].uid
    mass, _, friction = info()
    assert (mass, friction) == pytest.approx((4.0, 0.9))
    cube.scale = 0.5  # rebuilds the box: new half extents
    body = cube.linked_objects[sim].uid
    aabb_min, aabb_max = pb.getAABB(body, physicsClientId=sim.client)
    assert np.subtract(aabb_max, aabb_min) == pytest.approx((1.0, 1.0, 1.0), abs=0.05)
    assert info()[0] == pytest.approx(4.0)


def test_static_and_massless_objects_are_fixed_and_can_be_released():
    scene = kb.Scene(frame_start=0, frame_end=24)
    floor = kb.Cube(scale=(4, 4, 0.5), position=(0, 0, -0.5), static=True)
    held = kb.Cube(scale=0.25, position=(0, 0, 2.0), static=True)
    massless = kb.Sphere(scale=0.25, position=(2, 0, 2.0), mass=0.0)
    scene.add([floor, held, massless])
    sim = PyBullet(scene)
    animation, _ = sim.run(0, 12)
    for obj in (floor, held, massless):
        assert animation[obj]["position"][-1] == animation[obj]["position"][0]
    held.static = False  # now falls, and must still collide with the static floor
    massless.mass = 1.0
    animation, _ = sim.run(0, 48)
    assert animation[held]["position"][-1][2] == pytest.approx(0.25, abs=0.01)
    assert animation[massless]["position"][-1][2] == pytest.approx(0.25, abs=0.01)
    assert animation[floor]["position"][-1] == animation[floor]["position"][0]


def _drop_ball(restitution, frames=48, set_after_creation=False):
    scene = kb.Scene(frame_start=0, frame_end=frames)
    floor = kb.Cube(name="floor", scale=(5, 5, 0.5), position=(0, 0, -0.5), static=True,
                    restitution=1.0)  # Bullet multiplies the two restitutions
    ball = kb.Sphere(name="ball", scale=0.2, position=(0, 0, 1.2),
                     restitution=0.0 if set_after_creation else restitution)
    scene.add([floor, ball])
    sim = PyBullet(scene)
    ball.restitution = restitution
    animation, collisions = sim.run(0, frames)
    sim.close()
    return floor, ball, np.array(animation[ball]["position"])[:, 2], collisions


def test_ball_without_restitution_stays_on_the_floor():
    floor, ball, z, collisions = _drop_ball(0.0)
    landed = int(np.argmax(z <= 0.2 + 1e-3))
    assert 10 <= landed <= 12
    assert np.all(z[landed:] <= 0.2 + 1e-4)  # no bounce
    assert np.all(z[landed:] > 0.2 - 3e-3)  # no sinking (split impulse pushes it out)
    np.testing.assert_allclose(z[-10:], 0.2, atol=1e-5)  # rests on the floor


def test_bouncy_ball_bounces_back_and_collision_is_reported():
    floor, ball, z, collisions = _drop_ball(0.9, set_after_creation=True)
    drop_height = 1.0  # ball bottom starts 1 m above the floor
    landed = int(np.argmin(z[:15]))
    assert z[landed + 1] > z[landed]  # going up again
    rebound = z[landed:35].max() - 0.2
    assert rebound > 0.7 * drop_height
    assert rebound < drop_height  # no energy gain
    # impact after t = sqrt(2 h / g) = 0.447 s, i.e. frame 10.73
    hits = [c for c in collisions if set(c["instances"]) == {ball, floor}]
    first = min(hits, key=lambda c: c["frame"])
    assert first["frame"] == pytest.approx(np.sqrt(2 * drop_height / 10) * 24, abs=0.5)
    assert isinstance(first["frame"], float) and first["force"] > 0
    assert first["position"][2] == pytest.approx(0.0, abs=0.02)
    assert abs(first["contact_normal"][2]) == pytest.approx(1.0, abs=1e-3)
    assert set(first) == {"instances", "frame", "force", "position", "contact_normal"}
    # a second impact after the rebound, with a gap of flight in between
    frames = sorted(c["frame"] for c in hits)
    assert frames[-1] - frames[0] > 10


def test_contacts_are_merged_per_frame_and_raw_contacts_are_available():
    def run(**kwargs):
        scene = kb.Scene(frame_start=0, frame_end=24)
        floor = kb.Cube(scale=(3, 3, 0.5), position=(0, 0, -0.5), static=True)
        box = kb.Cube(scale=0.2, position=(0, 0, 0.2001))  # resting: 4 contact points per step
        scene.add([floor, box])
        sim = PyBullet(scene)
        _, collisions = sim.run(0, 24, **kwargs)
        return collisions

    merged, raw = run(), run(merge_contacts=False)
    assert len(raw) > 10 * len(merged)  # 10 steps per frame, several points each
    frames = [c["frame"] for c in merged]
    assert len(frames) == len({int(np.ceil(f)) for f in frames})  # one event per frame
    assert len(merged) >= 23
    by_uid = [{**c, "instances": tuple(a.uid for a in c["instances"])} for c in raw]
    for event in merged:  # the two runs' scenes hold different assets with the same uids
        assert {**event, "instances": tuple(a.uid for a in event["instances"])} in by_uid
        same = [c for c in raw if np.ceil(c["frame"]) == np.ceil(event["frame"])]
        assert event["force"] == max(c["force"] for c in same)
    total = sum(c["force"] for c in raw if 12 < c["frame"] <= 13) / 10  # per step
    assert total == pytest.approx(10.0, rel=0.05)  # weight m g of the 1 kg box
    assert run(min_contact_force=1e9) == []


class _Recorder(View):
    def __init__(self, scene):
        self.keys = []
        self.deleted = []
        super().__init__(scene)

    def on_keyframe(self, asset, name, frame):
        self.keys.append((asset.uid, name, frame))

    def on_keyframe_delete(self, asset, name, frame):
        self.deleted.append((asset.uid, name, frame))


def test_repeated_runs_replace_the_animation_and_notify_other_views():
    scene = kb.Scene(frame_start=0, frame_end=10)
    floor = kb.Cube(scale=(3, 3, 0.5), position=(0, 0, -0.5), static=True)
    ball = kb.Sphere(scale=0.2, position=(0, 0, 1.0), restitution=0.0)
    scene.add([floor, ball])
    recorder = _Recorder(scene)
    sim = PyBullet(scene)
    sim.run(0, 30)  # settle
    assert ("Sphere", "position", 30) in recorder.keys
    settled = np.array(ball.position)
    ball.velocity = (1.0, 0.0, 0.0)  # reset, then the real run
    animation, _ = sim.run(0, 10)
    assert sorted(ball.keyframes["position"]) == list(range(11))  # frames 11..30 are gone
    np.testing.assert_allclose(animation[ball]["position"][0], settled, atol=1e-6)
    np.testing.assert_allclose(ball.keyframes["velocity"][0], (1.0, 0.0, 0.0), atol=1e-6)
    assert ball.position[0] > 0.2  # slid along x during the second run
    assert recorder.keys.count(("Sphere", "position", 10)) == 2
    # other views are told to drop the stale keys, once per property and frame
    stale = [d for d in recorder.deleted if d[:2] == ("Sphere", "position")]
    assert sorted(d[2] for d in stale) == list(range(11, 31))


def test_run_rejects_bad_frame_range():
    scene = kb.Scene()
    sim = PyBullet(scene)
    with pytest.raises(ValueError, match=r"frame_end \(3\).*frame_start \(5\)"):
        sim.run(5, 3)
    with pytest.raises(TypeError, match="frame_start"):
        sim.run(0.5, 3)


def test_run_frame_end_defaults_to_scene_and_cameras_are_ignored():
    scene = kb.Scene(frame_start=1, frame_end=6)
    cube = kb.Cube()
    scene.add([cube, kb.PerspectiveCamera(), kb.PointLight()])
    sim = PyBullet(scene)
    animation, collisions = sim.run()
    assert list(animation) == [cube]
    assert len(animation[cube]["position"]) == 7 and collisions == []
    assert sorted(cube.keyframes["position"]) == list(range(7))


def test_negative_mass_on_live_object_is_rejected_and_engine_unchanged():
    scene = kb.Scene()
    cube = kb.Cube(mass=2.0)
    scene.add(cube)
    sim = PyBullet(scene)
    body = cube.linked_objects[sim].uid
    with pytest.raises(ValueError, match=r"Cube.*mass.*-1"):
        cube.mass = -1.0
    assert cube.mass == 2.0
    assert pb.getDynamicsInfo(body, -1, physicsClientId=sim.client)[0] == 2.0


def test_non_uniform_sphere_and_zero_scale_are_clear_errors():
    scene = kb.Scene()
    PyBullet(scene)
    with pytest.raises(ValueError, match=r"Sphere.*uniform.*\[1\.0, 2\.0, 1\.0\]"):
        scene.add(kb.Sphere(scale=(1, 2, 1)))
    with pytest.raises(ValueError, match=r"Cube.*positive.*0\.0"):
        scene.add(kb.Cube(scale=(1, 0, 1)))


def test_save_state_writes_a_loadable_bullet_file(tmp_path):
    scene = kb.Scene()
    scene.add([kb.Cube(position=(0, 0, 3)), kb.Sphere(position=(3, 0, 3))])
    sim = PyBullet(scene)
    path = sim.save_state(tmp_path / "out" / "scene.bullet")
    data = path.read_bytes()
    assert data.startswith(b"BULLET") and len(data) > 1000
    other = pb.connect(pb.DIRECT)
    try:
        loaded = pb.loadBullet(str(path), physicsClientId=other)
        assert len(loaded) == 2
        positions = sorted(pb.getBasePositionAndOrientation(b, physicsClientId=other)[0]
                           for b in loaded)
        assert positions == [(0.0, 0.0, 3.0), (3.0, 0.0, 3.0)]
    finally:
        pb.disconnect(physicsClientId=other)
    with pytest.raises(ValueError, match="bullet"):
        sim.save_state(tmp_path / "scene.txt")


def test_removed_asset_leaves_the_engine():
    scene = kb.Scene()
    a, b = kb.Cube(), kb.Sphere(position=(0.5, 0, 0))
    scene.add([a, b])
    sim = PyBullet(scene)
    assert sim.check_overlap(a)
    scene.remove(b)
    assert not sim.check_overlap(a)
    assert pb.getNumBodies(physicsClientId=sim.client) == 1


def test_contact_event_records_follow_the_contract():
    from kubric.simulator import contacts

    a, b = kb.Cube(), kb.Sphere()
    # pybullet.getContactPoints tuples: flag, bodyA, bodyB, linkA, linkB, posOnA, posOnB,
    # normalOnB, distance, normalForce, ...
    points = [(0, 1, 2, -1, -1, (0, 0, 1), (0, 0, 0.9), (0, 0, 1), -0.1, 5.0),
              (0, 1, 2, -1, -1, (1, 0, 1), (1, 0, 0.9), (0, 0, 1), -0.1, 7.0),
              (0, 1, 7, -1, -1, (0, 0, 1), (0, 0, 0.9), (0, 0, 1), -0.1, 1e-9)]
    events = contacts.raw_events(points, {1: a, 2: b}, frame=3.5, step=5, min_force=1e-6)
    assert len(events) == 2  # the tiny force is dropped
    assert events[0]["instances"] == (b, a) and events[0]["position"] == (0.0, 0.0, 0.9)
    later = contacts.raw_events([(0, 2, 1, -1, -1, (0, 0, 0), (0, 0, 0), (0, 0, -1), 0, 9.0),
                                 (0, 1, 3, -1, -1, (0, 0, 0), (0, 0, 0), (0, 0, -1), 0, 2.0)],
                                {1: a, 2: b}, frame=3.6, step=6)
    merged = contacts.finalize(contacts.merge_events(events + later, steps_per_frame=10))
    assert [e["force"] for e in merged] == [9.0, 2.0]  # (a, b) pair merged, order kept
    assert merged[0]["instances"] == (a, b) and merged[1]["instances"] == (None, a)
    assert all(set(e) == {"instances", "frame", "force", "position", "contact_normal"}
               for e in merged)
    next_frame = contacts.raw_events(points[:1], {1: a, 2: b}, frame=4.1, step=11)
    assert len(contacts.merge_events(events + next_frame, steps_per_frame=10)) == 2
