"""Compare two cloth engines on one scene: PyBullet's deformable world (the simulator view,
:mod:`kubric.simulator.deformables`) and Blender's cloth modifier (bpy), for docs/deformables.md.

Scene: a 1 m × 1 m sheet of ``--resolution``² vertices, 0.8 m above a floor, falls for
``--seconds`` s (12 frames/s) onto a ball of radius 0.25 m resting on the floor (dynamic in
PyBullet; a collision object in Blender, whose cloth cannot push rigid bodies). Each engine runs
twice, each run in a fresh process. Measured per engine:

* stable: every vertex finite and no edge stretched over 3× its rest length;
* stretch: the largest edge length / rest length over all frames;
* depth: the deepest any vertex goes inside the ball (analytic sphere at its pose of that
  frame) or below the floor's top (z = 0), in mm, over all frames (≤ 0: none);
* cost: CPU seconds of the simulation per simulated second (the process's start excluded);
* deterministic: the two processes' vertex arrays are bit-identical;
* ball moved: how far the cloth pushed the ball (m; two-way coupling).

Run: ``.venv/bin/python benchmarks/bench_cloth_engines.py [--resolution 16] [--seconds 2]``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import pathlib
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import smoke_mode  # noqa: E402

RADIUS, HEIGHT, FPS = 0.25, 0.8, 12
BALL = (0.1, 0.0, RADIUS)


def run_pybullet(n: int, seconds: float) -> dict:
    import kubric as kb
    from kubric.simulator.pybullet import PyBullet
    frames = int(round(seconds * FPS))
    scene = kb.Scene(frame_start=0, frame_end=frames, frame_rate=FPS, step_rate=240)
    scene += kb.Cube(name="floor", scale=(3, 3, 0.1), position=(0, 0, -0.1), static=True)
    ball = kb.Sphere(name="ball", scale=RADIUS, position=BALL, mass=1.0)
    scene += ball
    cloth = kb.Deformable.cloth(size=(1, 1), resolution=(n, n), position=(0, 0, HEIGHT))
    scene += cloth
    sim = PyBullet(scene)
    t0 = time.process_time()
    sim.run(0, frames)
    wall = time.process_time() - t0
    verts = np.stack([cloth.deformed_vertices(f) for f in range(frames + 1)])
    balls = np.stack([ball.get_value_at("position", f) for f in range(frames + 1)])
    return dict(verts=verts, balls=balls, faces=cloth.faces, wall=wall)


def run_blender(n: int, seconds: float) -> dict:
    import bpy

    from kubric.core.deformables import cloth_grid
    frames = int(round(seconds * FPS))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = FPS
    scene.frame_start, scene.frame_end = 0, frames
    v, f, _ = cloth_grid((1, 1), (n, n))
    mesh = bpy.data.meshes.new("cloth")
    mesh.from_pydata((v + [0, 0, HEIGHT]).tolist(), [], f.tolist())
    cloth = bpy.data.objects.new("cloth", mesh)
    scene.collection.objects.link(cloth)
    mod = cloth.modifiers.new("cloth", "CLOTH")
    mod.collision_settings.distance_min = 0.005
    mod.point_cache.frame_start, mod.point_cache.frame_end = 0, frames
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=RADIUS,
                                         location=BALL)
    bpy.context.active_object.modifiers.new("collision", "COLLISION")
    bpy.ops.mesh.primitive_plane_add(size=6, location=(0, 0, 0))
    bpy.context.active_object.modifiers.new("collision", "COLLISION")
    out = []
    t0 = time.process_time()
    for frame in range(frames + 1):
        scene.frame_set(frame)
        evaluated = cloth.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        co = np.zeros(len(evaluated.vertices) * 3)
        evaluated.vertices.foreach_get("co", co)
        out.append(co.reshape(-1, 3))
    wall = time.process_time() - t0
    verts = np.stack(out)  # object frame = world (identity transform)
    return dict(verts=verts, balls=np.tile(BALL, (frames + 1, 1)), faces=f, wall=wall)


def measures(run: dict, seconds: float) -> dict:
    verts, faces = run["verts"], run["faces"]
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    rest = np.linalg.norm(verts[0][edges[:, 0]] - verts[0][edges[:, 1]], axis=1)
    length = np.linalg.norm(verts[:, edges[:, 0]] - verts[:, edges[:, 1]], axis=2)
    stretch = float((length / rest).max())
    inside = RADIUS - np.linalg.norm(verts - run["balls"][:, None], axis=2)
    depth = float(max(inside.max(), (-verts[..., 2]).max()))
    return dict(stable=bool(np.isfinite(verts).all() and stretch < 3), stretch=round(stretch, 2),
                depth_mm=round(1000 * depth, 2), cost=round(run["wall"] / seconds, 2),
                ball_moved=round(float(np.linalg.norm(run["balls"][-1] - run["balls"][0])), 3),
                digest=hashlib.sha256(np.ascontiguousarray(verts).tobytes()).hexdigest())


def child(engine: str, n: int, seconds: float) -> None:
    run = (run_pybullet if engine == "pybullet" else run_blender)(n, seconds)
    print("RESULT " + json.dumps(measures(run, seconds)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=smoke_mode.size(16, 4))
    parser.add_argument("--seconds", type=float, default=smoke_mode.size(2.0, 0.25))
    parser.add_argument("--engines", default="pybullet,blender")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        child(args.child, args.resolution, args.seconds)
        return 0
    print(f"{args.resolution}² cloth, {args.seconds} s at {FPS} frames/s, 2 processes each")
    print("| engine | stable | stretch | depth (mm) | CPU-s / simulated s | deterministic | "
          "ball moved (m) |")
    print("|---|---|---|---|---|---|---|")
    for engine in args.engines.split(","):
        runs = []
        for _ in range(2):
            proc = subprocess.run([sys.executable, __file__, "--child", engine, "--resolution",
                                   str(args.resolution), "--seconds", str(args.seconds)],
                                  capture_output=True, text=True, check=True)
            line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")][-1]
            runs.append(json.loads(line[len("RESULT "):]))
        a, b = runs
        print(f"| {engine} | {'yes' if a['stable'] and b['stable'] else 'no'} | {a['stretch']} | "
              f"{a['depth_mm']} | {min(a['cost'], b['cost'])} | "
              f"{'yes' if a['digest'] == b['digest'] else 'no'} | {a['ball_moved']} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
