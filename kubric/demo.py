"""``make demo`` / ``python -m kubric.demo``: a small MOVi dataset end to end.

Generates 4 MOVi-A and 2 MOVi-C scenes (128², 12 frames, few samples) with the local runner, then
writes a contact sheet for the first scene of each and prints where everything is. Re-running
resumes (complete scenes are kept).
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

from kubric.io.scene_dir import is_complete, scene_name
from kubric.pipeline.inspect import inspect_scene
from kubric.pipeline.recipe import get_recipe, recipe_spec
from kubric.pipeline.runner import LocalRunner

#: (recipe, number of scenes, option assignments)
DEMO_DATASETS = (
    ("movi_a", 4, ["resolution=128", "frame_end=12", "samples=16"]),
    ("movi_c", 2, ["resolution=128", "frame_end=12", "samples=16", "max_num_objects=6",
                    "collection_limit=50"]),
)


def run_demo(out: pathlib.Path, workers: int | None = None, progress: bool = True) -> int:
    start = time.time()
    failures = 0
    sheets = []
    for name, count, assignments in DEMO_DATASETS:
        cls = get_recipe(name)
        folder = out / cls.name
        print(f"== {cls.name}: {count} scenes ({', '.join(assignments)}) → {folder}", flush=True)
        cls.from_assignments(assignments).prepare()
        runner = LocalRunner(recipe_spec(cls), folder, range(count), assignments,
                             workers=workers, progress=progress)
        summary = runner.run()
        print(summary.format(runner.out_root), flush=True)
        if summary.interrupted:
            return 130
        failures += len(summary.failed)
        first = runner.out_root / scene_name(0)
        if is_complete(first):
            sheet = out / f"{cls.name}_{first.name}_contact_sheet.png"
            print(inspect_scene(first, sheet), flush=True)
            sheets.append(sheet)
    print(f"\ndemo finished in {time.time() - start:.0f} s: scenes under {out.resolve()}")
    for sheet in sheets:
        print(f"contact sheet: {sheet.resolve()}")
    return 1 if failures else 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m kubric.demo", description=__doc__.strip()
                                     .splitlines()[0])
    parser.add_argument("--out", default="demo_output", help="output folder (default "
                        "./demo_output)")
    parser.add_argument("--workers", type=int, default=None, help="parallel scenes (default: "
                        "cores)")
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    return run_demo(pathlib.Path(args.out), args.workers, not args.no_progress)


if __name__ == "__main__":
    sys.exit(main())
