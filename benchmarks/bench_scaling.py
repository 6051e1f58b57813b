"""Scaling of `kubric generate`: the process pool vs Dask's LocalCluster, 1 and 2 workers (not a test).

Measured in one run, each configuration into a fresh output directory:

* **Speed-up**: N tiny MOVi-A scenes (32², 3 frames, 2 samples, no denoising, one render thread
  per scene for both runners) with 1 and 2 workers; speed-up = time(1 worker) / time(2 workers).
* **Per-scene overhead**: M scenes of the test recipe (no rendering: a worker process that starts,
  writes two small images and exits) with 1 worker; the time per scene is what a runner adds
  around a scene (process start, imports, bookkeeping), and Dask's is compared with the pool's.

* **Scheduler cost per task**: K no-op tasks with the ``scene=1`` resource annotation through a
  LocalCluster of 2 workers; time per task is the scheduler + worker round trip that each scene
  costs on a cluster (the input for the 1000-worker sizing in the README).

The LocalCluster's start-up (once per run) is printed separately and not counted in its times.
The issue's targets (speed-up with 2 workers ≥ 1.8×, Dask's per-scene overhead within 5 % of the
pool's) are printed next to the measured values, as met or not met.

Run: ``python benchmarks/bench_scaling.py [--scenes N] [--overhead-scenes M] [--tasks K]``; the
full size is N = 12 (then M = 20, K = 4000; N = 6 before 2026-11-22). ``--scenes`` scales M and K with it,
so ``--scenes 2`` is a smoke run of about a minute and a half.
"""

from __future__ import annotations

import argparse
import math
import os
import pathlib
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import smoke_mode  # noqa: E402

FAKE = f"{ROOT / 'tests' / 'fake_recipes.py'}:Fake"
TINY = ["resolution=32", "frame_end=3", "samples=2", "denoise=false", "max_num_objects=5"]
SPEEDUP_TARGET = 1.8     # the issue's: 2 workers at least 1.8x faster than 1
OVERHEAD_TARGET = 0.05   # the issue's: Dask's per-scene overhead within 5 % of the pool's


def run(kind: str, recipe: str, options: list[str], scenes: int, workers: int, root: pathlib.Path):
    """(seconds of the run, seconds to start the cluster) for one configuration."""
    from kubric.pipeline.dask_runner import ClusterOptions, DaskRunner, open_cluster
    from kubric.pipeline.runner import LocalRunner
    out = root / f"{kind}-{workers}-{recipe.rsplit(':', 1)[-1]}-{'-'.join(options)}"
    common = dict(assignments=options, retries=0, progress=False)
    if kind == "pool":
        runner, client, cluster, startup = LocalRunner(recipe, out, range(scenes),
                                                       workers=workers, **common), None, None, 0.0
    else:
        start = time.perf_counter()
        client, cluster = open_cluster(ClusterOptions(spec="local", workers=workers,
                                                      dashboard_address=":0"))
        startup = time.perf_counter() - start
        runner = DaskRunner(recipe, out, range(scenes), client, **common)
    try:
        start = time.perf_counter()
        summary = runner.run()
        seconds = time.perf_counter() - start
    finally:
        if client is not None:
            client.close()
            cluster.close()
    if not summary.ok or len(summary.done) != scenes:
        raise SystemExit(f"{kind} with {workers} workers failed: {summary.format(out)}")
    return seconds, startup


def _noop(k):
    return k


def scheduler_cost(tasks: int) -> float:
    """Seconds per no-op task with the scene resource, LocalCluster of 2 one-slot workers."""
    from kubric.pipeline.dask_runner import RESOURCE, ClusterOptions, open_cluster
    client, cluster = open_cluster(ClusterOptions(spec="local", workers=2, dashboard_address=":0"))
    try:
        client.gather(client.map(_noop, range(50), resources={RESOURCE: 1}))  # warm up
        start = time.perf_counter()
        futures = client.map(_noop, range(1000, 1000 + tasks), resources={RESOURCE: 1})
        assert client.gather(futures) == list(range(1000, 1000 + tasks))
        return (time.perf_counter() - start) / tasks
    finally:
        client.close()
        cluster.close()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=smoke_mode.size(12, 2),
                        help="MOVi-A scenes per configuration (default 12: with 6, three rounds "
                        "of ~1-s scenes, a run's fixed ~0.3 s of first-task set-up was a tenth "
                        "of the 2-worker time)")
    parser.add_argument("--overhead-scenes", type=int, default=smoke_mode.size(None, 2),
                        help="test-recipe scenes for the per-scene overhead, even (default: "
                        "10 for 6 scenes, scaled with --scenes)")
    parser.add_argument("--tasks", type=int, default=smoke_mode.size(None, 10),
                        help="no-op tasks for the scheduler "
                        "cost (default: 2000 for 6 scenes, scaled with --scenes, at least 100)")
    args = parser.parse_args(argv)
    if args.scenes < 2:
        parser.error(f"--scenes must be ≥ 2 (two workers need two scenes), got {args.scenes}")
    if args.overhead_scenes is None:
        args.overhead_scenes = 2 * math.ceil(5 * args.scenes / 6)  # 6 → 10, 2 → 4
    if args.tasks is None:
        args.tasks = max(100, 2000 * args.scenes // 6)
    if args.overhead_scenes < 2 or args.overhead_scenes % 2:
        parser.error(f"--overhead-scenes must be even and ≥ 2, got {args.overhead_scenes}")
    if args.tasks < 1:
        parser.error(f"--tasks must be ≥ 1, got {args.tasks}")
    print(f"sizes: {args.scenes} MOVi-A scenes per configuration, {args.overhead_scenes} "
          f"overhead scenes, {args.tasks} scheduler tasks")
    os.environ["KUBRIC_RENDER_THREADS"] = "1"  # the pool's workers render as the Dask tasks do
    from kubric.pipeline.recipe import get_recipe
    get_recipe("movi_a").from_assignments(TINY).prepare()  # assets built before timing
    print(f"machine: {os.cpu_count()} cores (shared with other work: numbers are noisy)")
    with tempfile.TemporaryDirectory(prefix="bench-scaling-") as tmp:
        root = pathlib.Path(tmp)
        times = {}
        for workers in (1, 2):  # interleaved, so that drifting load hits both runners alike
            for kind in ("pool", "dask"):
                seconds, startup = run(kind, "movi_a", TINY, args.scenes, workers, root)
                times[kind, workers] = seconds
                extra = f"  (LocalCluster start {startup:.2f} s, not counted)" if startup else ""
                print(f"{kind:>4}, {workers} worker(s): {args.scenes} MOVi-A scenes in "
                      f"{seconds:6.1f} s = {seconds / args.scenes:5.2f} s/scene{extra}", flush=True)
        for kind in ("pool", "dask"):
            speedup = times[kind, 1] / times[kind, 2]
            print(f"speed-up 1 → 2 workers, {kind}: {speedup:.2f}x (target ≥ {SPEEDUP_TARGET}x: "
                  f"{'met' if speedup >= SPEEDUP_TARGET else 'NOT met'})")
        print(f"dask / pool time, 2 workers: {times['dask', 2] / times['pool', 2]:.3f}")
        totals = {"pool": 0.0, "dask": 0.0}
        for rounds in range(2):  # alternating halves, so that drifting load hits both alike
            for kind in ("pool", "dask"):
                seconds, _ = run(kind, FAKE, [f"frames={rounds + 1}"], args.overhead_scenes // 2,
                                 1, root)
                totals[kind] += seconds
        per_scene = {kind: total / (args.overhead_scenes // 2 * 2) for kind, total in totals.items()}
        for kind in ("pool", "dask"):
            print(f"{kind:>4}: per-scene overhead (no rendering, 1 worker) "
                  f"{per_scene[kind] * 1000:7.1f} ms", flush=True)
        diff = per_scene["dask"] - per_scene["pool"]
        ratio = per_scene["dask"] / per_scene["pool"]
        print(f"Dask per-scene overhead vs pool: {ratio:.3f}x ({diff * 1000:+.1f} ms per scene; "
              f"target within {OVERHEAD_TARGET:.0%}: "
              f"{'met' if ratio <= 1 + OVERHEAD_TARGET else 'NOT met'})")
        per_task = scheduler_cost(args.tasks)
        print(f"scheduler + worker round trip: {per_task * 1000:.2f} ms per task "
              f"({args.tasks} no-op tasks with the scene resource, 2 workers)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
