"""``make demo`` / ``python -m kubric.demo``: a small MOVi dataset end to end.

Generates 4 MOVi-A and 2 MOVi-C scenes (128², 12 frames, few samples) with the local runner, then
writes a contact sheet for the first scene of each and prints where everything is. Re-running
resumes (complete scenes are kept). ``--figure PATH`` also writes the README's picture: frame
:data:`FIGURE_FRAME` of the first scene of each recipe, RGB next to its layers, one row per recipe.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np

from kubric.io.json_io import read_json
from kubric.io.layers import read_frame
from kubric.io.scene_dir import METADATA_FILE, is_complete, scene_name
from kubric.pipeline.inspect import colourise, inspect_scene
from kubric.pipeline.recipe import get_recipe, recipe_spec
from kubric.pipeline.runner import LocalRunner

#: (recipe, number of scenes, option assignments)
DEMO_DATASETS = (
    ("movi_a", 4, ["resolution=128", "frame_end=12", "samples=16"]),
    ("movi_c", 2, ["resolution=128", "frame_end=12", "samples=16", "max_num_objects=6",
                    "collection_limit=50"]),
)


#: the README figure's frame and columns (layer, caption)
FIGURE_FRAME = 6
FIGURE_COLUMNS = (("rgba", "RGB"), ("segmentation", "segmentation"), ("depth", "depth"),
                  ("forward_flow", "forward flow"), ("normal", "normals"),
                  ("object_coordinates", "object coords"))


def write_figure(out: pathlib.Path, path: pathlib.Path, frame: int = FIGURE_FRAME) -> pathlib.Path:
    """One row per demo recipe (its first scene, ``frame``): RGB and its layers, with
    a caption strip on top (colours as in ``kubric inspect``'s contact sheet)."""
    from PIL import Image, ImageDraw

    rows = []
    for name, _, _ in DEMO_DATASETS:
        scene = out / name / scene_name(0)
        if not is_complete(scene):
            raise FileNotFoundError(f"{scene} is not complete: run the demo first")
        background = read_json(scene / METADATA_FILE)["metadata"].get("background_depth")
        tiles = []
        for layer, _ in FIGURE_COLUMNS:
            data = read_frame(scene, layer, frame)[None]
            if layer == "object_coordinates":
                tiles.append((np.clip(data[0], 0, 1) * 255).astype(np.uint8))
            else:
                tiles.append(colourise(layer, data, background)[0])
        rows.append(np.concatenate(tiles, axis=1))
    grid = np.concatenate(rows, axis=0)
    tile_w = grid.shape[1] // len(FIGURE_COLUMNS)
    caption = Image.new("RGB", (grid.shape[1], 16), "white")
    draw = ImageDraw.Draw(caption)
    for k, (_, text) in enumerate(FIGURE_COLUMNS):
        draw.text((k * tile_w + 4, 2), text, fill="black")
    image = Image.new("RGB", (grid.shape[1], grid.shape[0] + 16), "white")
    image.paste(caption, (0, 0))
    image.paste(Image.fromarray(grid), (0, 16))
    path.parent.mkdir(parents=True, exist_ok=True)
    image.save(path, optimize=True)
    return path


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
    parser.add_argument("--figure", default=None, metavar="PATH", help="also write the README "
                        "figure (RGB next to its layers) to PATH, e.g. docs/img/demo_layers.png")
    args = parser.parse_args(argv)
    code = run_demo(pathlib.Path(args.out), args.workers, not args.no_progress)
    if code == 0 and args.figure:
        print(f"figure: {write_figure(pathlib.Path(args.out), pathlib.Path(args.figure))}")
    return code


if __name__ == "__main__":
    sys.exit(main())
