"""Signals at random moments leave nothing that looks complete, and a rerun finishes the job.

For each (target, signal) in {worker, runner} × {SIGTERM, SIGKILL}: start ``kubric worker`` (one
tiny MOVi-A scene) or ``kubric generate`` (two tiny scenes, 1 worker), send the signal after a
delay drawn from ``RandomState(seed)`` over the process's usual run time, then check

* no final-named ``scene_*`` directory without ``_SUCCESS``;
* after SIGTERM: no ``.scene_…incomplete-PID`` directory and nothing in the process's TMPDIR
  (Blender's ``blender_*`` folders, our ``kubric-tmp-*``); after SIGKILL the process cannot clean
  up, so leftovers are counted, and the rerun must remove them;
* a rerun (same command, no signal) completes every scene, leaves no work directory, and the
  scenes' files equal an uninterrupted run's byte for byte (all but ``_SUCCESS``, which holds
  the run time).

Run: ``python benchmarks/bench_signals.py [--runs 20] [--seed 0]``. Prints one row per
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

TINY = ["--set", "resolution=16", "--set", "frame_end=3", "--set", "samples=1"]


def command(target: str, out: pathlib.Path) -> list[str]:
    if target == "worker":
        return ["worker", "movi_a", "--seed", "0", *TINY, "--out", str(out)]
    return ["generate", "movi_a", "--scenes", str(smoke_mode.size(2, 1)), "--workers", "1",
            "--no-progress", *TINY,
            "--out", str(out)]


def run(args: list[str], tmp: pathlib.Path, sig=None, delay: float = 0.0) -> tuple[int, float]:
    env = dict(os.environ, TMPDIR=str(tmp))
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "kubric", *args], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    if sig is not None:
        try:
            proc.wait(timeout=delay)
        except subprocess.TimeoutExpired:
            proc.send_signal(sig)
    rc = proc.wait(timeout=600)
    return rc, time.perf_counter() - start


def scene_files(out: pathlib.Path) -> dict:
    files = {}
    for scene in sorted(out.glob("scene_*")):
        for path in sorted(scene.iterdir()):
            if path.name == "_SUCCESS":
                continue
            files[f"{scene.name}/{path.name}"] = path.read_bytes()
    return files


def leftovers(out: pathlib.Path, tmp: pathlib.Path) -> dict:
    work = [p.name for p in out.iterdir() if ".incomplete-" in p.name] if out.is_dir() else []
    incomplete = [p.name for p in out.glob("scene_*") if not (p / "_SUCCESS").is_file()] \
        if out.is_dir() else []
    return {"work_dirs": len(work), "incomplete_final": len(incomplete),
            "tmp_entries": len(list(tmp.iterdir()))}


def measure(runs: int, seed: int) -> list[dict]:
    rng = np.random.RandomState(seed)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_signals_") as root:
        root = pathlib.Path(root)
        for target in ("worker", "runner"):
            ref_out, ref_tmp = root / f"ref_{target}", root / f"ref_{target}_tmp"
            ref_tmp.mkdir()
            rc, usual = run(command(target, ref_out), ref_tmp)
            if rc != 0:
                raise RuntimeError(f"uninterrupted {target} run failed (exit {rc})")
            reference = scene_files(ref_out)
            for sig in (signal.SIGTERM, signal.SIGKILL):
                row = {"target": target, "signal": sig.name, "runs": runs,
                       "usual_seconds": round(usual, 1), "ended_by_signal": 0,
                       "incomplete_final_dirs": 0, "left_after_signal": 0,
                       "left_after_rerun": 0, "rerun_identical": 0}
                for i in range(runs):
                    out, tmp = root / f"{target}_{sig.name}_{i}", root / f"{target}_{sig.name}_{i}t"
                    tmp.mkdir()
                    delay = float(rng.uniform(0.2, usual))
                    rc, _ = run(command(target, out), tmp, sig, delay)
                    row["ended_by_signal"] += rc != 0
                    left = leftovers(out, tmp)
                    row["incomplete_final_dirs"] += left["incomplete_final"]
                    row["left_after_signal"] += left["work_dirs"] + left["tmp_entries"] > 0
                    rerun_tmp = root / f"{target}_{sig.name}_{i}r"
                    rerun_tmp.mkdir()
                    run(command(target, out), rerun_tmp)
                    after = leftovers(out, rerun_tmp)
                    row["left_after_rerun"] += after["work_dirs"] + after["incomplete_final"] > 0
                    row["rerun_identical"] += scene_files(out) == reference
                ok = (row["incomplete_final_dirs"] == 0 and row["left_after_rerun"] == 0
                      and row["rerun_identical"] == runs
                      and (sig == signal.SIGKILL or row["left_after_signal"] == 0))
                row["guarantees_held"] = ok
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
