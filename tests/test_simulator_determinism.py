"""Bit-identical trajectories: repeated in one process, across processes, several clients at once.

Run as a script (``python test_simulator_determinism.py SEED``) it prints the trajectory digest of
the 10-object scene, which the cross-process test compares.
"""

import hashlib
import subprocess
import sys

import numpy as np

import kubric as kb
from kubric.simulator import PyBullet

REGION = ((-1.5, -1.5, 0.0), (1.5, 1.5, 2.0))


def build_scene(seed: int, gravity=(0.0, 0.0, -10.0)):
    """A floor and 10 random cubes/spheres placed without overlap, with random velocities."""
    rng = np.random.RandomState(seed)
    scene = kb.Scene(frame_start=0, frame_end=24, gravity=gravity)
    floor = kb.Cube(name="floor", scale=(4, 4, 0.5), position=(0, 0, -0.5), static=True)
    scene.add(floor)
    sim = PyBullet(scene)
    for i in range(10):
        size = float(rng.uniform(0.15, 0.3))
        obj = (kb.Cube if i % 2 else kb.Sphere)(scale=size, mass=float(rng.uniform(0.5, 2)),
                                                friction=float(rng.uniform(0.2, 0.8)),
                                                restitution=float(rng.uniform(0.2, 0.8)))
        scene.add(obj)
        kb.move_until_no_overlap(obj, sim, spawn_region=REGION, max_trials=200, rng=rng)
        obj.velocity = rng.uniform(-2, 2, size=3)
    return scene, sim


def trajectory(seed: int, gravity=(0.0, 0.0, -10.0)):
    """(float64 array (objects, frames, 13), collisions) of the simulated scene."""
    scene, sim = build_scene(seed, gravity)
    animation, collisions = sim.run(0, 24)
    sim.close()
    return _as_array(animation), collisions


def _as_array(animation):
    return np.array([[np.concatenate([p, q, v, w]) for p, q, v, w in zip(
        track["position"], track["quaternion"], track["velocity"], track["angular_velocity"],
        strict=True)] for track in animation.values()], dtype=np.float64)


def digest(seed: int) -> str:
    traj, collisions = trajectory(seed)
    h = hashlib.sha256(traj.tobytes())
    for c in collisions:
        h.update(repr((c["instances"][0].uid, c["instances"][1].uid, c["frame"], c["force"],
                       c["position"], c["contact_normal"])).encode())
    return h.hexdigest()


def test_ten_objects_collide_and_move():
    traj, collisions = trajectory(5)
    assert traj.shape == (11, 25, 13)
    assert np.all(np.isfinite(traj))
    moved = np.linalg.norm(traj[1:, -1, :3] - traj[1:, 0, :3], axis=1)
    assert np.all(moved > 0.05)
    assert np.all(traj[1:, -1, 2] > 0.0)  # nothing fell through the floor
    assert len(collisions) > 10


def test_repeated_ten_times_in_one_process_is_bit_identical():
    reference, ref_collisions = trajectory(5)
    for _ in range(9):
        traj, collisions = trajectory(5)
        assert traj.tobytes() == reference.tobytes()
        assert [(c["frame"], c["force"]) for c in collisions] == \
            [(c["frame"], c["force"]) for c in ref_collisions]
    assert trajectory(6)[0].tobytes() != reference.tobytes()


def test_two_processes_with_the_same_seed_are_bit_identical():
    runs = [subprocess.run([sys.executable, __file__, "5"], capture_output=True, text=True,
                           check=True, timeout=120) for _ in range(2)]
    digests = [r.stdout.strip().splitlines()[-1] for r in runs]
    assert digests[0] == digests[1] == digest(5)


def test_simultaneous_simulators_do_not_interfere():
    alone, _ = trajectory(5)
    scene_a, sim_a = build_scene(5)
    scene_b, sim_b = build_scene(5)
    scene_c, sim_c = build_scene(9, gravity=(0.0, 10.0, 0.0))  # different world, alive meanwhile
    anim_c, _ = sim_c.run(0, 24)
    anim_a, _ = sim_a.run(0, 12)  # interleaved runs
    anim_b, _ = sim_b.run(0, 24)
    anim_a2, _ = sim_a.run(12, 24)
    a = _as_array(anim_a)
    a2 = _as_array(anim_a2)
    np.testing.assert_array_equal(_as_array(anim_b), alone)
    # the split run restarts from the float32 model state at frame 12 (the model is the truth)
    np.testing.assert_allclose(a2[:, 0, :3], alone[:, 12, :3], atol=1e-6)
    np.testing.assert_array_equal(a, alone[:, :13])
    np.testing.assert_allclose(a2[:, -1, :3], alone[:, -1, :3], atol=1e-3)
    assert _as_array(anim_c)[1:, -1, 1].mean() > 1.0  # its own gravity (+y) applied
    for sim in (sim_a, sim_b, sim_c):
        sim.close()


if __name__ == "__main__":
    print(digest(int(sys.argv[1])))
