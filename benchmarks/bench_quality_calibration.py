"""Per-recipe render-quality calibration: cost and error of every calibration setting, every recipe.

For every built-in recipe that path-traces RGB (the :class:`~kubric.recipes.render_quality.
RenderQuality` recipes) and each seed (default 1, 2, 3), one fresh process builds the recipe's
scene at its own defaults (resolution, content, lights), stops where the recipe would render,
and renders its middle frame (or view) under every setting of ``CALIBRATION_SETTINGS``
(samples, OIDN network and prefilter, adaptive sampling) and once at 1024 spp without denoising,
the reference. Measured per setting: CPU-s (user + system, every thread) of the one-frame render
after a warm-up render, and the error of its 8-bit RGB against the reference:

* RMSE over **all** pixels; over **object** pixels (segmentation of the exact-layer pass, minus
  background assets such as the floor and dome); over **edge** pixels (±2 px of a label change);
  over **textured** pixels (not edge pixels, and the reference's luma has a local standard
  deviation ≥ 2 levels over 5×5 px: texture, highlights and shading detail — where a denoiser
  smooths first);
* 1 − SSIM of the luma (Gaussian window σ 1.5 px, K1 0.01, K2 0.03, L 255; mean over pixels).

Errors are pooled over seeds (RMSE: root of the mean per-seed MSE; 1 − SSIM: mean); cost is the
mean CPU-s per frame. ``choose_default`` (kubric/recipes/render_quality.py) applies the rule to
each recipe's pooled rows. Output: the raw rows in ``docs/data/render-calibration.json`` (written
after every scene, so a stopped run resumes where it stopped with ``--resume``) and the tables in
``docs/render-cost.md`` between its calibration markers.

Run: ``.venv/bin/python benchmarks/bench_quality_calibration.py [--recipes movi_a klevr]
[--seeds 1 2 3] [--resume]``. About 90 min on 2 cores for all 16 recipes and three seeds
(the 1024-spp references are two thirds of it; MOVi-F at 512² a quarter).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time
from dataclasses import replace

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import smoke_mode  # noqa: E402
from bench_scene_cost import edge_band  # noqa: E402

ROOT = HERE.parent
DATA = ROOT / "docs" / "data" / "render-calibration.json"
DOC = ROOT / "docs" / "render-cost.md"
BEGIN, END = "<!-- calibration: begin -->", "<!-- calibration: end -->"
CLASSES = ("all", "objects", "edges", "textured")
#: toybox needs a categorised asset source (ShapeNet or GSO in use): KuBasic with these
#: categories stands in (7 categories; toybox's default uses the 5 most common).
TOY_CATEGORIES = {"cube": "boxy", "sponge": "boxy", "sphere": "round", "cylinder": "round",
                  "cone": "pointed", "gear": "mechanical", "torus": "ring", "torus_knot": "ring",
                  "teapot": "kitchen", "suzanne": "figure", "spot": "figure"}


def recipe_options(recipe: str, scratch: pathlib.Path) -> list[str]:
    """Options a recipe needs beyond its defaults to run here (toybox: its object source)."""
    if recipe != "toybox":
        return []
    from kubric import asset_tools
    from kubric.recipes.klevr import with_categories
    return [f"objects={with_categories(asset_tools.ensure_kubasic(), TOY_CATEGORIES, scratch)}"]


class _Captured(Exception):
    pass


def with_renderer(recipe: str, seed: int, assignments: list[str], scratch: pathlib.Path,
                  measure) -> dict:
    """``measure(renderer)`` on the recipe's Blender renderer for ``seed``, called where the recipe
    would render (inside the recipe's own context: its temporary textures still exist); the
    recipe stops there. Returns what ``measure`` returned."""
    from kubric.pipeline.recipe import get_recipe
    from kubric.renderer import blender
    original, result = blender.Blender.render, {}

    def capture(self, *args, **kwargs):
        blender.Blender.render = original
        result["value"] = measure(self)
        raise _Captured

    blender.Blender.render = capture
    try:
        get_recipe(recipe).from_assignments(assignments).generate(seed, scratch)
    except _Captured:
        pass
    finally:
        blender.Blender.render = original
    if "value" not in result:
        raise SystemExit(f"{recipe} seed {seed} finished without a Blender render")
    return result["value"]


# -- measures (8-bit RGB, (H, W, 3)) --------------------------------------------------------------

def luma(rgb: np.ndarray) -> np.ndarray:
    return rgb[..., :3].astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])


def edge_pixels(seg: np.ndarray, width: int = 2) -> np.ndarray:
    """Pixels within ``width`` px of a label change (4-neighbourhood), one (H, W) frame."""
    return edge_band(seg[None], width)[0]


def textured_pixels(ref: np.ndarray, edges: np.ndarray, size: int = 5,
                    threshold: float = 2.0) -> np.ndarray:
    """Pixels off the edges where the reference's luma varies locally (std ≥ ``threshold``)."""
    from scipy import ndimage
    y = luma(ref)
    mean = ndimage.uniform_filter(y, size, mode="reflect")
    var = ndimage.uniform_filter(y * y, size, mode="reflect") - mean * mean
    return (np.sqrt(np.maximum(var, 0)) >= threshold) & ~edges


def ssim(img: np.ndarray, ref: np.ndarray, sigma: float = 1.5) -> float:
    """Mean SSIM of the two images' luma (Wang et al. 2004 constants, L = 255)."""
    from scipy import ndimage
    x, y = luma(img), luma(ref)
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2

    def blur(a):
        return ndimage.gaussian_filter(a, sigma, truncate=3.5, mode="reflect")

    mx, my = blur(x), blur(y)
    vx, vy, cxy = blur(x * x) - mx * mx, blur(y * y) - my * my, blur(x * y) - mx * my
    s = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))
    return float(s.mean())


def errors(img: np.ndarray, ref: np.ndarray, masks: dict[str, np.ndarray]) -> dict:
    """{"mse_<class>": mean squared error (None for an empty class), "dssim": 1 − SSIM}."""
    d2 = ((img[..., :3].astype(np.float64) - ref[..., :3].astype(np.float64)) ** 2).mean(-1)
    out = {f"mse_{c}": float(d2[m].mean()) if m.any() else None for c, m in masks.items()}
    out["dssim"] = 1.0 - ssim(img, ref)
    return out


# -- one scene, in a child process -----------------------------------------------------------------

def apply_profile(r, p) -> None:
    """Set every field of the quality profile ``p`` on the Blender renderer ``r`` (levers too)."""
    from kubric.renderer.blender_sampling import BLENDER_DEFAULTS
    r.samples_per_pixel, r.use_denoising = p.samples, p.denoise
    r.denoising_quality, r.denoising_prefilter = p.denoising_quality, p.denoising_prefilter
    r.adaptive_sampling = p.adaptive_threshold is not None
    if p.adaptive_threshold is not None:
        r.adaptive_threshold = p.adaptive_threshold
    for name in BLENDER_DEFAULTS:
        setattr(r, name, getattr(p, name))


def measure_settings(r, reference_samples: int, settings=None, variants=()) -> dict:
    """The calibration of one scene's middle frame on renderer ``r`` (see the module doc) under
    ``settings`` (quality profiles; default CALIBRATION_SETTINGS), then under each of
    ``variants``: (label, profile, change) with ``change(r, on)`` changing the scene (on) and
    back (off) around the variant's render (after a 1-sample warm-up), measured against the
    same reference."""
    from kubric.recipes.render_quality import ANCHOR, CALIBRATION_SETTINGS
    settings = CALIBRATION_SETTINGS if settings is None else settings
    frame = (r.scene.frame_start + r.scene.frame_end) // 2
    seg = r.render([frame], ("segmentation",))["segmentation"][0, ..., 0]
    background = [i for i, a in enumerate(r.scene.assets, start=1)
                  if getattr(a, "background", False)]

    def render(p):
        apply_profile(r, p)
        c0, w0 = time.process_time(), time.perf_counter()
        rgb = r.render([frame], ("rgba",))["rgba"][0]
        return rgb, time.process_time() - c0, time.perf_counter() - w0

    render(replace(ANCHOR, samples=1, denoise=False))  # warm-up: kernels, textures, ...
    ref, ref_cpu, _ = render(replace(ANCHOR, samples=reference_samples, denoise=False))
    edges = edge_pixels(seg)
    masks = {"all": np.ones(seg.shape, bool),
             "objects": (seg > 0) & ~np.isin(seg, background),
             "edges": edges, "textured": textured_pixels(ref, edges)}
    rows = {}
    for label, p, change in [(p.label, p, None) for p in settings] + list(variants):
        if change is not None:
            change(r, True)
            render(replace(p, samples=1, denoise=False))  # warm-up: the changed shaders
        rgb, cpu, wall = render(p)
        if change is not None:
            change(r, False)
        rows[label] = {"cpu": cpu, "wall": wall, **errors(rgb, ref, masks)}
        print(f"  {label:44s} {cpu:7.2f} CPU-s  RMSE {np.sqrt(rows[label]['mse_all']):6.3f}",
              flush=True)
    h, w = seg.shape
    return {"frame": frame, "resolution": [w, h], "reference_cpu": ref_cpu,
            "fractions": {c: float(m.mean()) for c, m in masks.items()}, "settings": rows}


def child(recipe: str, seed: int, reference_samples: int, assignments: list[str],
          out: pathlib.Path) -> None:
    with tempfile.TemporaryDirectory(prefix="bench_calibration_") as tmp:
        tmp = pathlib.Path(tmp)
        options = [*recipe_options(recipe, tmp / "objects"), *assignments]
        result = with_renderer(recipe, seed, options, tmp / "scene",
                               lambda r: measure_settings(r, reference_samples))
    out.write_text(json.dumps({"recipe": recipe, "seed": seed, **result}))


# -- pooling, the rule, the tables -----------------------------------------------------------------

def pooled(scenes: list[dict]) -> dict[str, dict]:
    """{label: {"cpu", "rmse_<class>", "dssim", "cpu_min", "cpu_max"}} over the recipe's seeds
    (the labels of every seed)."""
    labels = [label for label in scenes[0]["settings"]
              if all(label in s["settings"] for s in scenes)]
    out = {}
    for label in labels:
        rows = [s["settings"][label] for s in scenes]
        cpu = [r["cpu"] for r in rows]
        row = {"cpu": float(np.mean(cpu)), "cpu_min": min(cpu), "cpu_max": max(cpu),
               "dssim": float(np.mean([r["dssim"] for r in rows]))}
        for c in CLASSES:
            mses = [r[f"mse_{c}"] for r in rows if r[f"mse_{c}"] is not None]
            row[f"rmse_{c}"] = float(np.sqrt(np.mean(mses))) if mses else None
        out[label] = row
    return out


def recipe_rows(data: dict) -> dict[str, dict[str, dict]]:
    """{recipe: pooled rows} from the calibration file's scenes."""
    by_recipe: dict[str, list[dict]] = {}
    for scene in data["scenes"]:
        by_recipe.setdefault(scene["recipe"], []).append(scene)
    return {name: pooled(scenes) for name, scenes in by_recipe.items()}


def _fmt(v, spec=".3f"):
    return "–" if v is None else format(v, spec)


def worst(row: dict, anchor: dict) -> float:
    """The largest error ratio of ``row`` to ``anchor`` over the rule's measures."""
    from kubric.recipes.render_quality import RULE_MEASURES
    return max(row[m] / anchor[m] for m in RULE_MEASURES if row[m] is not None and anchor[m])


def recipe_table(name: str, rows: dict[str, dict], scenes: list[dict]) -> list[str]:
    """The markdown lines of one recipe's table: every setting of ``rows`` (pooled over
    ``scenes``, that recipe's calibration scenes) with its cost, errors and the rule's verdict."""
    from kubric.recipes.render_quality import ANCHOR, RULE_FACTOR, choose_default
    anchor, chosen = rows[ANCHOR.label], choose_default(rows)
    w, h = scenes[0]["resolution"]
    fr = np.mean([[s["fractions"][c] for c in CLASSES] for s in scenes], axis=0)
    ref_cpu = np.mean([s["reference_cpu"] for s in scenes])
    lines = [
        f"#### {name}", "",
        f"{w}×{h}, frame/view {scenes[0]['frame']} of seeds "
        f"{', '.join(str(s) for s in sorted(s['seed'] for s in scenes))}; reference "
        f"{ref_cpu:.0f} CPU-s per frame; pixels: objects {fr[1]:.1%}, edges {fr[2]:.1%}, "
        f"textured {fr[3]:.1%}.", "",
        "| setting | CPU-s / frame (min–max) | × 64 spp | RMSE all | objects | edges | "
        "textured | 1 − SSIM | worst ratio | rule |",
        "|---|---|---|---|---|---|---|---|---|---|"]
    for label, row in rows.items():
        ratio = worst(row, anchor)
        mark = "**chosen**" if label == chosen else ("passes" if ratio <= RULE_FACTOR else "")
        lines.append(
            f"| {label} | {row['cpu']:.2f} ({row['cpu_min']:.2f}–{row['cpu_max']:.2f}) | "
            f"{row['cpu'] / anchor['cpu']:.2f} | {_fmt(row['rmse_all'])} | "
            f"{_fmt(row['rmse_objects'])} | {_fmt(row['rmse_edges'])} | "
            f"{_fmt(row['rmse_textured'])} | {row['dssim']:.4f} | {ratio:.2f} | {mark} |")
    return lines + [""]


def tables(data: dict) -> str:
    """The markdown of the calibration section: the summary, then one table per recipe."""
    from kubric.recipes.render_quality import (
        ANCHOR,
        CALIBRATED_DEFAULTS,
        PROFILES,
        RULE_FACTOR,
        RULE_MEASURES,
        choose_default,
    )
    rows_of = recipe_rows(data)
    seeds: dict[str, list[int]] = {}
    for s in data["scenes"]:
        seeds.setdefault(s["recipe"], []).append(s["seed"])
    meta = {s["recipe"]: s for s in data["scenes"]}
    names = ", ".join(m.replace("rmse_", "RMSE ").replace("dssim", "1 − SSIM")
                      for m in RULE_MEASURES)
    lines = [
        f"Printed by `benchmarks/bench_quality_calibration.py` ({data['date']}, "
        f"{data['reference_samples']}-spp reference, {data['machine']}). Rule: **the cheapest "
        f"setting whose error on every measure ({names}) is at most {RULE_FACTOR}× that of "
        f"{ANCHOR.label}**, errors pooled over the seeds. Cost: CPU-s of one frame's (or view's) "
        "RGB render, mean over seeds; × 64 spp is its ratio to the anchor's cost in the same run. "
        "*worst ratio* is the largest error ratio to the anchor over the five measures.",
        "",
        "| recipe | resolution | seeds | chosen default | CPU-s / frame | × 64 spp cost | worst "
        "ratio | previous default (16 spp) worst ratio | in code |",
        "|---|---|---|---|---|---|---|---|---|"]

    for name, rows in rows_of.items():
        anchor, chosen = rows[ANCHOR.label], choose_default(rows)
        old = rows.get(PROFILES["default"].label)
        code = CALIBRATED_DEFAULTS.get(name)
        w, h = meta[name]["resolution"]
        lines.append(
            f"| {name} | {w}×{h} | {', '.join(map(str, sorted(seeds[name])))} | {chosen} | "
            f"{rows[chosen]['cpu']:.2f} | {rows[chosen]['cpu'] / anchor['cpu']:.2f} | "
            f"{worst(rows[chosen], anchor):.2f} | {_fmt(old and worst(old, anchor), '.2f')} | "
            f"{'yes' if code is not None and code.label == chosen else 'NO'} |")
    lines.append("")
    for name, rows in rows_of.items():
        lines += recipe_table(name, rows, [s for s in data["scenes"] if s["recipe"] == name])
    return "\n".join(lines)


def write_doc(data: dict, doc: pathlib.Path = DOC) -> None:
    text = doc.read_text()
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{doc} has no {BEGIN} … {END} section to fill")
    head, rest = text.split(BEGIN, 1)
    tail = rest.split(END, 1)[1]
    doc.write_text(f"{head}{BEGIN}\n{tables(data)}\n{END}{tail}")


def run_child(script: str, recipe: str, seed: int, reference_samples: int,
              assignments: list[str], extra: tuple[str, ...] = ()) -> dict:
    """Run ``script --child recipe seed OUT`` (with ``extra`` arguments) in a fresh process and
    return the scene it wrote."""
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        out = pathlib.Path(f.name)
    cmd = [sys.executable, str(pathlib.Path(script).resolve()), "--child", recipe, str(seed),
           str(out), "--reference-samples", str(reference_samples), *extra]
    for s in assignments:
        cmd += ["--set", s]
    proc = subprocess.run(cmd, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    if proc.returncode:
        raise SystemExit(f"{recipe} seed {seed} failed ({proc.returncode}):\n"
                         f"{proc.stderr[-3000:]}")
    scene = json.loads(out.read_text())
    out.unlink()
    return scene


def calibrated_recipes() -> list[str]:
    from kubric.pipeline.recipe import load_builtin
    from kubric.recipes.render_quality import RenderQuality
    return [name for name, cls in load_builtin().items() if issubclass(cls, RenderQuality)]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recipes", nargs="*", help="default: every RenderQuality recipe")
    parser.add_argument("--seeds", nargs="*", type=int, default=smoke_mode.size([1, 2, 3], [1]))
    parser.add_argument("--reference-samples", type=int, default=smoke_mode.size(1024, 4))
    parser.add_argument("--json", type=pathlib.Path, default=smoke_mode.output(DATA))
    parser.add_argument("--doc", type=pathlib.Path, default=smoke_mode.output(DOC))
    parser.add_argument("--no-doc", action="store_true", help="leave the docs page as it is")
    parser.add_argument("--resume", action="store_true",
                        help="keep the scenes already in --json (same settings and reference)")
    parser.add_argument("--set", action="append", metavar="KEY=VALUE",
                        default=smoke_mode.size([], ["resolution=16"]),
                        help="extra options for every recipe (smoke runs only: resolution=32)")
    parser.add_argument("--child", nargs=3, metavar=("RECIPE", "SEED", "OUT"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    os.environ.setdefault("KUBRIC_CACHE_DIR", str(ROOT / ".cache" / "kubric"))
    if args.child:
        recipe, seed, out = args.child
        child(recipe, int(seed), args.reference_samples, args.set, pathlib.Path(out))
        return 0
    from kubric.recipes.render_quality import CALIBRATION_SETTINGS
    available = calibrated_recipes()
    recipes = args.recipes or smoke_mode.size(available, available[:1])
    unknown = sorted(set(recipes) - set(available))
    if unknown:
        raise SystemExit(f"not a calibrated recipe: {unknown}; allowed: {available}")
    grid = [p.label for p in CALIBRATION_SETTINGS]
    data = {"reference_samples": args.reference_samples, "settings": grid, "scenes": [],
            "set": args.set}
    if args.resume and args.json.exists():
        old = json.loads(args.json.read_text())
        if (old["reference_samples"], old["settings"], old.get("set", [])) == \
                (args.reference_samples, grid, args.set):
            data["scenes"] = old["scenes"]
    done = {(s["recipe"], s["seed"]) for s in data["scenes"]}
    data["date"] = time.strftime("%Y-%m-%d")
    data["machine"] = f"{len(os.sched_getaffinity(0))} cores"
    todo = [(r, s) for r in recipes for s in args.seeds if (r, s) not in done]
    start = time.perf_counter()
    for k, (recipe, seed) in enumerate(todo, 1):
        print(f"[{k}/{len(todo)}] {recipe} seed {seed} ({time.perf_counter() - start:.0f} s "
              "elapsed)", flush=True)
        data["scenes"].append(run_child(__file__, recipe, seed, args.reference_samples,
                                        args.set))
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(data, indent=1))
    if not data["scenes"]:
        raise SystemExit("nothing calibrated")
    data["scenes"].sort(key=lambda s: (available.index(s["recipe"]), s["seed"]))
    args.json.write_text(json.dumps(data, indent=1))
    text = tables(data)
    print(text.split("\n\n#### ")[0])
    if not args.no_doc:
        write_doc(data, args.doc)
        print(f"tables → {args.doc}; rows → {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
