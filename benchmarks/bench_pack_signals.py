"""`kubric pack` under signals at random moments: no orphan process, no dataset that looks
complete unless it verifies, every rerun identical.

For each (workers, signal) in {1, 2} × {SIGKILL, SIGTERM, SIGINT}: start ``kubric pack --verify``
of 24 tiny toy scenes (``tests/hostile_fixtures.py``: no rendering; 4 examples per shard, so
there are many shard renames; each scene's encoding waits 50 ms through the ``KUBRIC_FAULT``
hook so the encoding phase is long enough to be hit), send the signal after a delay drawn from
``RandomState(seed)`` over the uninterrupted run's wall time (imports, encoding, final renames,
verification and the swap are all hit), then check

* **orphans**: the pack's child processes (pool workers, multiprocessing's resource tracker),
  listed just before the signal, are all gone 10 s after the pack ended;
* **nothing that looks complete unless it verifies**: a directory at ``--out`` after the signal
  must equal the uninterrupted run's dataset byte for byte;
* **rerun**: the same command without a signal exits 0, its dataset equals the reference byte for
  byte, and nothing of the packer is left beside it (work folder, lock, ``.old``).

Run: ``python benchmarks/bench_pack_signals.py [--runs 20] [--seed 0]``. Prints one JSON row per
configuration and exits 1 if any guarantee failed.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
import smoke_mode  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
FIXTURES = ROOT / "tests" / "hostile_fixtures.py"  # `kubric` with the toy recipe registered
SCENES = smoke_mode.size(24, 4)


def command(scenes: pathlib.Path, out: pathlib.Path, workers: int) -> list[str]:
    return [sys.executable, str(FIXTURES), "pack", str(scenes), "--out", str(out), "--verify",
            "--splits", "train=0.75,validation=0.25", "--examples-per-shard", "4",
            "--workers", str(workers), "--no-progress"]


def environment(tmp: pathlib.Path) -> dict:
    path = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    return dict(os.environ, PYTHONPATH=path, TMPDIR=str(tmp),
                KUBRIC_FAULT="pack.encode_scene:sleep", KUBRIC_FAULT_SLEEP="0.05")


def run(cmd, tmp, sig=None, delay=0.0) -> tuple[int, float, list[int]]:
    """(exit status, seconds, pids of the children seen last before the signal)."""
    import psutil
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, env=environment(tmp), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    children: list[int] = []
    if sig is not None:
        deadline = start + delay
        while time.perf_counter() < deadline and proc.poll() is None:
            try:
                children = [c.pid for c in psutil.Process(proc.pid).children(recursive=True)]
            except psutil.Error:
                break
            time.sleep(0.02)
        if proc.poll() is None:
            proc.send_signal(sig)
    rc = proc.wait(timeout=600)
    return rc, time.perf_counter() - start, children


def tree(folder: pathlib.Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()} if folder.is_dir() else {}


def alive(pids: list[int]) -> int:
    from kubric.pipeline.cleanup import pid_alive
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(pid_alive(p) for p in pids):
        time.sleep(0.1)
    return sum(pid_alive(p) for p in pids)


def packer_leftovers(out: pathlib.Path) -> list[str]:
    return sorted(p.name for p in out.parent.iterdir() if p.name.startswith(f".{out.name}."))


def measure(runs: int, seed: int) -> list[dict]:
    sys.path.insert(0, str(ROOT / "tests"))
    import hostile_fixtures
    rng = np.random.RandomState(seed)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_pack_signals_") as root:
        root = pathlib.Path(root)
        scenes = hostile_fixtures.make_scenes(root / "scenes", SCENES)
        for workers in (1, 2):
            ref, ref_tmp = root / f"ref{workers}" / "ds", root / f"ref{workers}_tmp"
            ref.parent.mkdir()
            ref_tmp.mkdir()
            rc, usual, _ = run(command(scenes, ref, workers), ref_tmp)
            if rc != 0:
                raise RuntimeError(f"uninterrupted pack (--workers {workers}) failed (exit {rc})")
            reference = tree(ref)
            for sig in (signal.SIGKILL, signal.SIGTERM, signal.SIGINT):
                row = {"workers": workers, "signal": sig.name, "runs": runs,
                       "usual_seconds": round(usual, 1), "ended_by_signal": 0,
                       "children_at_signal": 0, "orphans": 0, "output_after_signal": 0,
                       "output_not_reference": 0, "rerun_ok": 0, "rerun_identical": 0,
                       "left_after_rerun": 0}
                for i in range(runs):
                    base = root / f"w{workers}_{sig.name}_{i}"
                    out, tmp, rerun_tmp = base / "ds", base / "tmp", base / "rerun_tmp"
                    for folder in (base, tmp, rerun_tmp):
                        folder.mkdir()
                    delay = float(rng.uniform(0.1, usual))
                    rc, _, children = run(command(scenes, out, workers), tmp, sig, delay)
                    row["ended_by_signal"] += rc != 0
                    row["children_at_signal"] += len(children)
                    row["orphans"] += alive(children)
                    if out.exists():
                        row["output_after_signal"] += 1
                        row["output_not_reference"] += tree(out) != reference
                    rc, _, _ = run(command(scenes, out, workers) + ["--overwrite"], rerun_tmp)
                    row["rerun_ok"] += rc == 0
                    row["rerun_identical"] += tree(out) == reference
                    row["left_after_rerun"] += bool(packer_leftovers(out))
                row["guarantees_held"] = (row["orphans"] == 0 and row["output_not_reference"] == 0
                                          and row["rerun_ok"] == runs
                                          and row["rerun_identical"] == runs
                                          and row["left_after_rerun"] == 0)
                print(json.dumps(row), flush=True)
                rows.append(row)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=smoke_mode.size(20, 1),
                        help="signalled runs per configuration")
    parser.add_argument("--seed", type=int, default=0, help="seed of the signal delays")
    args = parser.parse_args(argv)
    rows = measure(args.runs, args.seed)
    return 0 if all(r["guarantees_held"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
