"""Run every ``benchmarks/bench_*.py`` in a fresh process (Blender keeps global state), in order.

Usage: ``python -m benchmarks [NAME ...]`` — NAME filters by substring (e.g. ``render``).
Each benchmark prints its own numbers, including ratios against a baseline measured in the same run.
"""

import pathlib
import subprocess
import sys
import time


def main(argv: list[str]) -> int:
    here = pathlib.Path(__file__).resolve().parent
    scripts = sorted(here.glob("bench_*.py"))
    if argv:
        scripts = [s for s in scripts if any(a in s.stem for a in argv)]
        if not scripts:
            print(f"no benchmark matches {argv}; available: {[s.stem for s in here.glob('bench_*.py')]}")
            return 2
    failures = []
    for script in scripts:
        print(f"=== {script.stem}", flush=True)
        start = time.perf_counter()
        result = subprocess.run([sys.executable, str(script)], cwd=here.parent)
        print(f"=== {script.stem}: exit {result.returncode}, {time.perf_counter() - start:.1f} s wall\n",
              flush=True)
        if result.returncode:
            failures.append(script.stem)
    if failures:
        print(f"failed: {failures}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
