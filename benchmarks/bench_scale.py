"""How kubric's scale-out costs grow with the number of scenes N (10², 10³, 10⁴) — not a test.

Every measurement runs in a fresh child process (``--child SPEC``) that reports its wall time,
its own CPU time and its peak resident memory (``VmHWM``: the client alone, not its scene
subprocesses or the Dask workers). Sections:

* **generate** — N scenes through the process pool, through Dask with workers offering the
  ``scene`` resource, and through Dask with plain workers (no flags: slots from their threads),
  a real ``dask scheduler`` and ``--slots`` ``dask worker`` processes on this machine, the pool
  with as many workers. Two workloads: ``bench`` = ``python -m kubric worker bench`` (the no-render
  recipe: a real worker process, ~0.2 CPU-s of interpreter start and imports per scene), and
  ``stdlib`` = a worker of the same contract in ``python -S`` (copies a ``bench`` scene into a
  work directory, writes ``_SUCCESS``, renames; ~15 ms), which leaves the runners' own cost
  visible and makes 10⁴ scenes affordable on a small machine (at N ≥ 10⁴ only ``--big-arms``).
  Reported: slot-seconds per scene (wall × slots / N; the *per-scene overhead* with the stdlib
  worker), CPU ms per scene of the client, of the scheduler process and of the Dask worker
  processes (their own CPU, not their scene subprocesses'), client peak memory.
* **resume** — a half-finished run of N scenes (N/2 complete, some stale work directories or
  prefixes without ``_SUCCESS``), locally and on S3 (moto's server on 127.0.0.1; each scene
  prefix holds its ``metadata.json`` and ``_SUCCESS``, what the scan touches): the time from
  ``Runner.run()`` to the first submission (listing, ``_SUCCESS`` checks, the to-do list).
* **pack** — N ``bench`` scenes packed locally (``kubric.datasets.pack``) and to ``s3://``
  (:mod:`kubric.datasets.store_commit`), one encoding process: scenes per second, peak memory.
* **load** — the train split of the N = ``--load-size`` (1000) dataset read in full (open +
  decode every example) from the local directory (twice, before and after: the baseline) and
  from its ``s3://`` URL with a cold and then a warm cache (:mod:`kubric.datasets.dataset_cache`).

Run: ``python benchmarks/bench_scale.py [--sizes 100,1000,10000] [--bench-sizes 100,1000]
[--slots 4]``; ``make bench`` runs the defaults below (about 25 min on an idle 2-core machine).
The goals of issue #25 are printed as met / not met: per-scene overhead at the largest N within
1.2× of the smallest, client and pack memory within 1.5× from 10³ to 10⁴, resume of 10⁴ listed
scenes under 10 s locally.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import resource
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
import smoke_mode  # noqa: E402

#: a worker of the kubric contract in the standard library only (python -S): copy the template
#: scene into OUT/.scene_X.incomplete-PID, write _SUCCESS, rename to OUT/scene_X.
STDLIB_WORKER = r"""
import os, shutil, sys, json
template, out, seed = sys.argv[1], sys.argv[2], int(sys.argv[3])
name = f"scene_{seed:08d}"
final = os.path.join(out, name)
if os.path.isfile(os.path.join(final, "_SUCCESS")):
    sys.exit(0)
work = os.path.join(out, f".{name}.incomplete-{os.getpid()}")
shutil.copytree(template, work)
with open(os.path.join(work, "_SUCCESS"), "w") as fh:
    fh.write(json.dumps({"recipe": "bench", "seed": seed}) + "\n")
os.rename(work, final)
"""


# ------------------------------------------------------------------------------ children
def _usage() -> dict:
    """CPU seconds and peak resident memory of this process. The peak is ``VmHWM`` (reset by
    exec), not ``ru_maxrss``, which Linux carries over from the parent across ``execve``."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    status = pathlib.Path("/proc/self/status").read_text().splitlines()
    hwm = next(int(ln.split()[1]) for ln in status if ln.startswith("VmHWM:"))
    return {"cpu": me.ru_utime + me.ru_stime, "maxrss_mb": hwm / 1024}


def _template(root: pathlib.Path) -> pathlib.Path:
    """One bench scene without its _SUCCESS (the stdlib worker's template)."""
    from kubric.pipeline.worker import run_scene
    from kubric.recipes.bench import Bench
    scene = run_scene(Bench(), 0, root / "template-src").path
    template = root / "template"
    if not template.exists():
        shutil.copytree(scene, template, ignore=shutil.ignore_patterns("_SUCCESS"))
    return template


def child_generate(spec: dict) -> dict:
    from kubric.pipeline.runner import LocalRunner
    out, n, worker = spec["out"], spec["n"], spec["worker"]
    command = None
    if worker == "stdlib":
        template = str(_template(pathlib.Path(spec["scratch"])))
        command = lambda self, seed: [sys.executable, "-S", "-c", STDLIB_WORKER, template,  # noqa: E731
                                      str(self.out_root), str(seed)]
    common = dict(retries=0, progress=False)
    client = None
    if spec["arm"] == "pool":
        cls = type("Pool", (LocalRunner,), {"command": command} if command else {})
        runner = cls("bench", out, range(n), workers=spec["slots"], **common)
    else:
        from distributed import Client

        from kubric.pipeline.dask_runner import DaskRunner
        client = Client(spec["address"], timeout=60)
        cls = type("Dask", (DaskRunner,), {"command": command} if command else {})
        runner = cls("bench", out, range(n), client, **common)
    before = _usage()
    start = time.perf_counter()
    summary = runner.run()
    wall = time.perf_counter() - start
    if client is not None:
        client.close()
    if not summary.ok or len(summary.done) != n:
        raise SystemExit(f"generate failed: {summary.format(out)}")
    after = _usage()
    return {"wall": wall, "cpu": after["cpu"] - before["cpu"], "maxrss_mb": after["maxrss_mb"]}


def child_resume(spec: dict) -> dict:
    from kubric.pipeline.runner import LocalRunner
    seen = {}

    class Probe(LocalRunner):
        def _execute(self, todo, summary, bar):
            seen["at"] = time.perf_counter()
            seen["todo"] = len(todo)

    runner = Probe("bench", spec["out"], range(spec["n"]), workers=1, progress=False)
    start = time.perf_counter()
    summary = runner.run()
    return {"scan": seen["at"] - start, "todo": seen["todo"], "skipped": len(summary.skipped),
            **_usage()}


def child_pack(spec: dict) -> dict:
    from kubric.datasets import packer, store_commit
    start = time.perf_counter()
    kwargs = dict(splits="train=0.9,validation=0.1", progress=False, workers=1)
    if spec["out"].startswith("s3://"):  # a URL: the store commit (the sharded packer refuses one)
        result = store_commit.pack_into(spec["scenes"], spec["out"], **kwargs)
    else:
        result = packer.pack(spec["scenes"], spec["out"], **kwargs)
    return {"wall": time.perf_counter() - start, "packed": sum(result.counts.values()),
            **_usage()}


def child_load(spec: dict) -> dict:
    """Open a split (a directory or a URL: fetched into the local cache unless already there)
    and decode every example."""
    from kubric.datasets import load
    start = time.perf_counter()
    source = load(spec["dataset"], "train")
    opened = time.perf_counter() - start
    for i in range(len(source)):
        source[i]
    return {"open": opened, "wall": time.perf_counter() - start, "examples": len(source),
            **_usage()}


def child(spec: dict) -> None:
    result = {"generate": child_generate, "resume": child_resume, "pack": child_pack,
              "load": child_load}[
        spec["what"]](spec)
    print("RESULT " + json.dumps(result), flush=True)


def measure(spec: dict, timeout: float = 3600) -> dict:
    proc = subprocess.run([sys.executable, __file__, "--child", json.dumps(spec)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode or not lines:
        raise SystemExit(f"child {spec['what']} failed:\n{proc.stdout[-2000:]}\n"
                         f"{proc.stderr[-3000:]}")
    return json.loads(lines[-1][7:])


# ------------------------------------------------------------------------------ set-up
def bench_scenes(root: pathlib.Path, n: int) -> pathlib.Path:
    """``n`` real bench scenes (seeds 0..n-1), made in this process (the recipe's generate and
    the worker's atomic writer; no subprocess per scene)."""
    from kubric.pipeline.worker import run_scene
    from kubric.recipes.bench import Bench
    scenes = root / f"scenes-{n}"
    recipe = Bench()
    for seed in range(n):
        run_scene(recipe, seed, scenes)
    return scenes


def half_finished(scenes: pathlib.Path, root: pathlib.Path, n: int) -> pathlib.Path:
    """A run of ``n`` seeds with the even seeds complete, plus 10 stale work directories and 10
    final directories without _SUCCESS (a cut upload's look)."""
    out = root / f"half-{n}"
    out.mkdir()
    for seed in range(0, n, 2):
        shutil.copytree(scenes / f"scene_{seed:08d}", out / f"scene_{seed:08d}",
                        copy_function=os.link)
    for seed in range(1, min(n - 2, 41), 4):  # seed + 2 < n: a scene of the run
        (out / f".scene_{seed:08d}.incomplete-999999999").mkdir()
        shutil.copytree(scenes / f"scene_{seed + 2:08d}", out / f"scene_{seed + 2:08d}")
        (out / f"scene_{seed + 2:08d}" / "_SUCCESS").unlink()
    return out


def upload_markers(fs, half: pathlib.Path, prefix: str) -> None:
    """The half-finished run on S3 as the resume scan sees it: every scene prefix with its
    ``metadata.json`` and, where complete, ``_SUCCESS`` (the scan lists scene prefixes and asks
    for each ``_SUCCESS``; the other files of a scene cost it nothing, only upload time)."""
    local = half.parent / f"{half.name}-markers"
    for scene in half.glob("scene_*"):
        (local / scene.name).mkdir(parents=True)
        for name in ("metadata.json", "_SUCCESS"):
            if (scene / name).exists():
                os.link(scene / name, local / scene.name / name)
    fs.put(str(local) + "/", prefix, recursive=True)
    shutil.rmtree(local)


def start_cluster(procs, root: pathlib.Path, slots: int, plain: bool) -> tuple[str, list]:
    """(address, [scheduler pid, worker pids]) of a real scheduler and ``slots`` one-thread
    workers (offering ``scene=1`` unless ``plain``)."""
    from dask_helpers import start_dask
    root.mkdir(parents=True, exist_ok=True)
    first = len(procs)
    # in this session: under the kernel's autogroup scheduling, workers in sessions of their own
    # got twice the CPU share of the pool's scenes on the loaded shared machine
    address = start_dask(procs, root, n_workers=slots, plain=plain, nthreads=1,
                         own_session=False)
    return address, [p.pid for p in procs[first:]]


def tree_cpu(pids: list[int]) -> float:
    """CPU seconds (user + system) of the processes ``pids`` and their live descendants, each
    counting only itself (a finished scene subprocess is not in it)."""
    parent, own = {}, {}
    for entry in pathlib.Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parent[int(entry.name)] = int(fields[1])
        own[int(entry.name)] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    total, todo = 0.0, list(pids)
    seen = set()
    while todo:
        pid = todo.pop()
        if pid in seen or pid not in own:
            continue
        seen.add(pid)
        total += own[pid]
        todo += [c for c, p in parent.items() if p == pid]
    return total


# ------------------------------------------------------------------------------ report
def table(rows: list[list], header: list[str]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(out)


def verdict(ok: bool) -> str:
    return "met" if ok else "NOT met"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default=smoke_mode.size("100,1000,10000", "10"),
                        help="N for the stdlib-worker runs, resume and pack")
    parser.add_argument("--bench-sizes", default=smoke_mode.size("100,1000", "2"),
                        help="N for the runs with the real `kubric worker bench` process")
    parser.add_argument("--slots", type=int, default=smoke_mode.size(4, 2),
                        help="pool workers = Dask workers")
    parser.add_argument("--arms", default="pool,dask-resource,dask-plain")
    parser.add_argument("--big-arms", default="pool,dask-plain",
                        help="the arms also run at N ≥ 10000 (time: ~N × 30 ms of CPU each)")
    parser.add_argument("--sections", default="generate,resume,pack,load")
    parser.add_argument("--load-size", type=int, default=smoke_mode.size(1000, 10),
                        help="N of the dataset read from disk and from s3:// (load section)")
    parser.add_argument("--json", default=None, help="also write every result to this file")
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        child(json.loads(args.child))
        return 0
    sizes = [int(s) for s in args.sizes.split(",") if s]
    bench_sizes = [int(s) for s in args.bench_sizes.split(",") if s]
    arms = args.arms.split(",")
    sections = args.sections.split(",")
    from dask_helpers import processes, s3_env, start_s3
    print(f"bench_scale: sizes {sizes}, real-worker sizes {bench_sizes}, {args.slots} slots, "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores", flush=True)
    results: dict = {}
    with tempfile.TemporaryDirectory(prefix="kubric-bench-scale-") as tmp, processes() as procs:
        root = pathlib.Path(tmp)
        endpoint = start_s3(procs, root)
        os.environ.update(s3_env(endpoint))
        os.environ["KUBRIC_CACHE_DIR"] = str(root / "cache")
        import fsspec.config
        fsspec.config.conf["s3"] = {"endpoint_url": endpoint}
        import s3fs
        fs = s3fs.S3FileSystem()
        fs.mkdir("bench")
        addresses = {}
        if "generate" in sections:
            if "dask-resource" in arms:
                addresses["dask-resource"] = start_cluster(procs, root / "dr", args.slots, False)
            if "dask-plain" in arms:
                addresses["dask-plain"] = start_cluster(procs, root / "dp", args.slots, True)
            big_arms = args.big_arms.split(",")
            for workload, ns in (("stdlib", sizes), ("bench", bench_sizes)):
                for n in ns:
                    for arm in arms:
                        if n >= 10000 and arm not in big_arms:
                            continue
                        out = root / f"gen-{workload}-{arm}-{n}"
                        address, pids = addresses.get(arm, (None, []))
                        spec = {"what": "generate", "arm": arm.split("-")[0], "n": n,
                                "worker": workload, "out": str(out), "slots": args.slots,
                                "address": address, "scratch": str(root)}
                        before = tree_cpu(pids[:1]), tree_cpu(pids[1:])
                        r = measure(spec)
                        r["slot_s"] = r["wall"] * args.slots / n
                        r["scheduler_ms"] = 1000 * (tree_cpu(pids[:1]) - before[0]) / n
                        r["workers_ms"] = 1000 * (tree_cpu(pids[1:]) - before[1]) / n
                        results[("generate", workload, arm, n)] = r
                        print(f"  generate {workload:6} {arm:13} N={n:>6}: {r['wall']:7.1f} s, "
                              f"{1000 * r['slot_s']:6.1f} slot-ms/scene, client "
                              f"{1000 * r['cpu'] / n:5.2f} CPU-ms/scene, "
                              f"{r['maxrss_mb']:6.0f} MB, scheduler {r['scheduler_ms']:.2f} / "
                              f"workers {r['workers_ms']:.2f} CPU-ms/scene", flush=True)
                        shutil.rmtree(out, ignore_errors=True)
        if "resume" in sections or "pack" in sections:
            largest = max(sizes)
            start = time.perf_counter()
            scenes = bench_scenes(root, largest)
            print(f"  made {largest} bench scenes in {time.perf_counter() - start:.1f} s",
                  flush=True)
            for n in sizes:
                subset = scenes if n == largest else root / f"subset-{n}"
                if n != largest:
                    subset.mkdir()
                    for seed in range(n):
                        os.symlink(scenes / f"scene_{seed:08d}", subset / f"scene_{seed:08d}")
                if "resume" in sections:
                    half = half_finished(scenes, root, n)
                    r = measure({"what": "resume", "out": str(half), "n": n})
                    results[("resume", "local", n)] = r
                    print(f"  resume local N={n:>6}: scan {r['scan']:6.2f} s, to do "
                          f"{r['todo']}, {r['maxrss_mb']:.0f} MB", flush=True)
                    start = time.perf_counter()
                    upload_markers(fs, half, f"bench/half-{n}")
                    upload = time.perf_counter() - start
                    r = measure({"what": "resume", "out": f"s3://bench/half-{n}", "n": n})
                    results[("resume", "s3", n)] = r
                    print(f"  resume s3    N={n:>6}: scan {r['scan']:6.2f} s, to do "
                          f"{r['todo']}, {r['maxrss_mb']:.0f} MB (upload {upload:.0f} s)",
                          flush=True)
                    fs.rm(f"bench/half-{n}", recursive=True)
                    shutil.rmtree(half)
                if "pack" in sections:
                    for where in ("local", "s3"):
                        out = str(root / f"ds-{n}") if where == "local" else f"s3://bench/ds-{n}"
                        r = measure({"what": "pack", "scenes": str(subset), "out": out})
                        results[("pack", where, n)] = r
                        print(f"  pack {where:5} N={n:>6}: {r['wall']:6.1f} s, "
                              f"{r['packed'] / r['wall']:6.1f} scenes/s, "
                              f"{r['maxrss_mb']:.0f} MB", flush=True)
                    if "load" in sections and n == args.load_size:
                        for arm, dataset in (("local", str(root / f"ds-{n}")),
                                             ("s3-cold", f"s3://bench/ds-{n}"),
                                             ("s3-warm", f"s3://bench/ds-{n}"),
                                             ("local-again", str(root / f"ds-{n}"))):
                            r = measure({"what": "load", "dataset": dataset})
                            results[("load", arm)] = r
                            print(f"  load {arm:11} N={n}: open {r['open']:5.2f} s, all "
                                  f"{r['examples']} examples {r['wall']:5.2f} s", flush=True)
    report(results, sizes, bench_sizes, arms, args.slots)
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(
            {"/".join(map(str, k)): v for k, v in results.items()}, indent=1))
    return 0


def report(results: dict, sizes, bench_sizes, arms, slots) -> None:
    print()
    if any(k[0] == "generate" for k in results):
        rows = []
        for workload, ns in (("stdlib", sizes), ("bench", bench_sizes)):
            for arm in arms:
                for n in ns:
                    r = results.get(("generate", workload, arm, n))
                    if r:
                        rows.append([workload, arm, n, f"{r['wall']:.1f}",
                                     f"{1000 * r['slot_s']:.1f}", f"{1000 * r['cpu'] / n:.2f}",
                                     f"{r['maxrss_mb']:.0f}", f"{r['scheduler_ms']:.2f}",
                                     f"{r['workers_ms']:.2f}"])
        print(table(rows, ["worker", "runner", "N", "wall s", f"slot-ms / scene ({slots} slots)",
                           "client CPU-ms / scene", "client peak MB",
                           "scheduler CPU-ms / scene", "Dask workers CPU-ms / scene"]))
        lo, hi = min(sizes), max(sizes)
        for arm in arms:
            a, b = results.get(("generate", "stdlib", arm, lo)), \
                results.get(("generate", "stdlib", arm, hi))
            if a and b and hi > lo:
                ratio = b["slot_s"] / a["slot_s"]
                print(f"{arm}: per-scene overhead N={hi} / N={lo}: {ratio:.2f}× (goal ≤ 1.2×: "
                      f"{verdict(ratio <= 1.2)})")
            m1, m2 = results.get(("generate", "stdlib", arm, 1000)), \
                results.get(("generate", "stdlib", arm, 10000))
            if m1 and m2:
                ratio = m2["maxrss_mb"] / m1["maxrss_mb"]
                print(f"{arm}: client memory N=10000 / N=1000: {ratio:.2f}× (goal ≤ 1.5×: "
                      f"{verdict(ratio <= 1.5)})")
    rows = []
    for n in sizes:
        for where in ("local", "s3"):
            r, p = results.get(("resume", where, n)), results.get(("pack", where, n))
            if r or p:
                rows.append([where, n, f"{r['scan']:.2f}" if r else "",
                             f"{p['wall']:.1f}" if p else "",
                             f"{p['packed'] / p['wall']:.0f}" if p else "",
                             f"{p['maxrss_mb']:.0f}" if p else ""])
    if rows:
        print()
        print(table(rows, ["store", "N", "resume scan s", "pack s", "pack scenes/s",
                           "pack peak MB"]))
    loads = {k[1]: v for k, v in results.items() if k[0] == "load"}
    if loads:
        base = (loads["local"]["wall"] + loads["local-again"]["wall"]) / 2
        reads = (loads["local"]["wall"] - loads["local"]["open"] + loads["local-again"]["wall"]
                 - loads["local-again"]["open"]) / 2
        print()
        print(table([[arm, r["examples"], f"{r['open']:.2f}", f"{r['wall']:.2f}",
                      f"{r['wall'] / base:.2f}×", f"{(r['wall'] - r['open']) / reads:.2f}×"]
                     for arm, r in loads.items()],
                    ["read the train split", "examples", "open s", "open + every example s",
                     "× local", "reads after open × local"]))
    r = results.get(("resume", "local", 10000))
    if r:
        print(f"resume of 10000 listed scenes, local: {r['scan']:.2f} s (goal < 10 s: "
              f"{verdict(r['scan'] < 10)})")
    for where in ("local", "s3"):
        a, b = results.get(("pack", where, 1000)), results.get(("pack", where, 10000))
        if a and b:
            ratio = b["maxrss_mb"] / a["maxrss_mb"]
            print(f"pack {where}: memory N=10000 / N=1000: {ratio:.2f}× (goal ≤ 1.5×: "
                  f"{verdict(ratio <= 1.5)})")


if __name__ == "__main__":
    sys.exit(main())
