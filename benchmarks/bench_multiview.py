"""Time ``kubric generate`` for one scene of every multi-view recipe at demo size, against MOVi-A
at `make demo` size measured in the same run, and write each scene's contact sheet.

Demo size: 128² (``nvs``: its default 128²), 16 samples, each recipe's default number of views
(klevr, toybox, texture_nerf, robust_nerf: 32; multiview_matting, nvs: 10). ``toybox`` is timed on a
copy of KuBasic with categories (it needs a categorised source). Baseline: ``movi_a`` with
``make demo``'s settings (128², 12 frames, 16 samples). Each run is one fresh ``kubric generate``
process (asset sources built beforehand, so only generating is timed).

Run: ``.venv/bin/python benchmarks/bench_multiview.py [--out DIR] [RECIPE ...]``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys
import tempfile
import time

import smoke_mode  # noqa: E402

DEMO = smoke_mode.size(["resolution=128", "samples=16"], ["resolution=16", "samples=1"])
RECIPES = {
    "klevr": DEMO,
    "toybox": DEMO + ["num_categories=3"],
    "texture_nerf": DEMO,
    "robust_nerf": DEMO,
    "multiview_matting": DEMO + ["difficulty=hard"],
    "nvs": DEMO,
}
BASELINE = ("movi_a", smoke_mode.size(["resolution=128", "frame_end=12", "samples=16"],
                                      ["resolution=16", "frame_end=2", "samples=1"]))
#: toybox: categories given to KuBasic shapes for the benchmark
TOY_CATEGORIES = {"cube": "box", "sponge": "box", "sphere": "ball", "torus": "ring",
                  "gear": "ring", "teapot": "kitchen", "cylinder": "kitchen"}


def categorised_kubasic(out: pathlib.Path) -> pathlib.Path:
    from kubric import asset_tools
    from kubric.recipes.klevr import with_categories
    return with_categories(asset_tools.ensure_kubasic(), TOY_CATEGORIES, out)


def generate(recipe: str, options: list[str], out: pathlib.Path) -> float:
    """Wall seconds of one ``kubric generate`` of one scene (raises on failure)."""
    cmd = [sys.executable, "-m", "kubric", "generate", recipe, "--out", str(out), "--scenes", "1",
           "--workers", "1", "--no-progress"]
    for o in options:
        cmd += ["--set", o]
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if proc.returncode:
        raise RuntimeError(f"{recipe} failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
    return seconds


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument("recipes", nargs="*", help=f"subset of {sorted(RECIPES)}")
    parser.add_argument("--out", type=pathlib.Path, default=None,
                        help="keep the scenes and contact sheets here (default: a temp dir)")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.recipes) - set(RECIPES))
    if unknown:
        parser.error(f"unknown recipes {unknown}; allowed: {sorted(RECIPES)}")
    if smoke_mode.SMOKE and not args.recipes:  # toybox: the generic path and its own objects=
        args.recipes = ["toybox"]
    from kubric.pipeline import get_recipe
    from kubric.pipeline.inspect import inspect_scene

    with tempfile.TemporaryDirectory(prefix="bench_multiview_") as tmp:
        root = args.out or pathlib.Path(tmp)
        toys = categorised_kubasic(root / "toys")
        runs = {name: list(opts) for name, opts in RECIPES.items()
                if not args.recipes or name in args.recipes}
        if "toybox" in runs:
            runs["toybox"].append(f"objects={toys}")
        for name, opts in [BASELINE, *runs.items()]:
            get_recipe(name).from_assignments(opts).prepare()  # build assets outside the timing
        base = generate(BASELINE[0], BASELINE[1], root / "baseline")
        print(f"baseline movi_a (128², 12 frames, 16 spp): {base:.1f} s")
        print(f"{'recipe':20s} {'views':>5s} {'seconds':>8s} {'x movi_a':>9s}  contact sheet")
        for name, opts in runs.items():
            seconds = generate(name, opts, root / name)
            scene = root / name / "scene_00000000"
            views = json.loads((scene / "metadata.json").read_text())["metadata"]["num_views"]
            sheet = root / f"{name}_contact_sheet.png"
            inspect_scene(scene, sheet)
            print(f"{name:20s} {views:5d} {seconds:8.1f} {seconds / base:9.2f}  "
                  f"{sheet if args.out else '(temp)'}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
