"""How long ``import kubric`` takes in a fresh interpreter, against ``import numpy`` (which it
needs anyway) measured in the same run, and the heavy modules it must not load (not a test).

Run: ``python benchmarks/bench_import.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys

import smoke_mode

HEAVY = ("bpy", "pybullet", "trimesh", "torch", "tensorflow")


def time_import(module: str, repeats: int) -> float:
    """Median seconds of ``import module`` in a fresh interpreter (start-up excluded)."""
    code = (f"import time; t = time.perf_counter(); import {module}; "
            "print(time.perf_counter() - t)")
    runs = [float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                 check=True).stdout) for _ in range(repeats)]
    return statistics.median(runs)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=smoke_mode.size(7, 1))
    args = parser.parse_args(argv)
    numpy_s = time_import("numpy", args.repeats)
    kubric_s = time_import("kubric", args.repeats)
    loaded = subprocess.run([sys.executable, "-c", "import kubric, sys; print(' '.join(sorted("
                             f"set({HEAVY!r}) & set(sys.modules))))"],
                            capture_output=True, text=True, check=True).stdout.split()
    result = {"import_numpy_s": round(numpy_s, 4), "import_kubric_s": round(kubric_s, 4),
              "kubric_over_numpy": round(kubric_s / numpy_s, 2), "heavy_modules_loaded": loaded,
              "repeats": args.repeats}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
