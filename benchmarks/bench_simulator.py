"""PyBullet view throughput: scene set-up, placement, stepping and keyframe write-back.

Prints, for scenes of N random cubes/spheres on a floor (MOVi-like: 48 frames at 24 fps), the time
of each phase and the physics steps per second, at step_rate 240 and 960.
"""

import time

import numpy as np
import smoke_mode

import kubric as kb
from kubric.simulator import PyBullet
from kubric.simulator import pybullet as kb_pybullet

REGION = ((-4, -4, 0), (4, 4, 3))


def measure(n_objects: int, step_rate: int, seed: int = 0) -> dict:
    rng = np.random.RandomState(seed)
    t0 = time.perf_counter()
    scene = kb.Scene(frame_start=0, frame_end=48)
    scene.set_rates(24, step_rate)
    scene.add(kb.Cube(scale=(6, 6, 0.5), position=(0, 0, -0.5), static=True))
    sim = PyBullet(scene)
    t1 = time.perf_counter()
    for i in range(n_objects):
        obj = (kb.Cube if i % 2 else kb.Sphere)(scale=float(rng.uniform(0.15, 0.35)))
        scene.add(obj)
        kb.move_until_no_overlap(obj, sim, spawn_region=REGION, max_trials=500, rng=rng)
        obj.velocity = rng.uniform(-3, 3, size=3)
    t2 = time.perf_counter()
    write = {"t": 0.0}
    original = kb_pybullet.PyBullet._write_keyframes

    def timed(self, *args):
        start = time.perf_counter()
        original(self, *args)
        write["t"] += time.perf_counter() - start

    kb_pybullet.PyBullet._write_keyframes = timed
    try:
        _, collisions = sim.run(0, 48)
    finally:
        kb_pybullet.PyBullet._write_keyframes = original
    t3 = time.perf_counter()
    sim.close()
    steps = 48 * scene.steps_per_frame
    physics = t3 - t2 - write["t"]
    return {"setup": t1 - t0, "placement": t2 - t1, "physics": physics,
            "write_back": write["t"], "steps_per_s": steps / physics, "events": len(collisions)}


def main():
    print(f"{'objects':>7} {'step_rate':>9} {'setup_s':>8} {'place_s':>8} {'physics_s':>9} "
          f"{'write_s':>8} {'steps/s':>8} {'events':>6}")
    for n in smoke_mode.size((10, 30, 100), (2,)):
        for rate in smoke_mode.size((240, 960), (240,)):
            r = measure(n, rate)
            print(f"{n:>7} {rate:>9} {r['setup']:>8.3f} {r['placement']:>8.3f} "
                  f"{r['physics']:>9.3f} {r['write_back']:>8.3f} {r['steps_per_s']:>8.0f} "
                  f"{r['events']:>6}")


if __name__ == "__main__":
    main()
