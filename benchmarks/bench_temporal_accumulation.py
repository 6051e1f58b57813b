"""Temporal accumulation along the exact backward flow, under the calibration's rule (issue 42).

A video's frames are rendered at a few samples each with a different sampling seed; each frame's
noisy radiance is then averaged with the previous frames' at the same surface point — found by
chaining the exact ``backward_flow`` and kept only where the exact ``segmentation`` and
``object_coordinates`` say it is the same point (within 2 % of the object's box) — and the
average is denoised (OIDN with prefiltered albedo and normal guides, accumulated alike). Optional
rejection: a history pixel is dropped where its frame's own denoised image differs from the
current frame's by more than T 8-bit levels (moving shadows, highlights). Cost per frame: the
low-sample render + the accumulation and denoising (+ one denoise per frame for the rejection).

Every image of this benchmark — the 1024-spp reference, 64 spp (Cycles' own OIDN), today's
default and the accumulated frames — is read as linear radiance from a multilayer EXR and
converted to 8-bit sRGB the same way (the Standard view transform's curve), so the comparison
shares one pipeline (no dither). Measures, pooling and rule: the calibration's
(``bench_quality_calibration.py``: RMSE on all / object / edge / textured pixels, 1 − SSIM; each
within 1.15× of 64 spp in the same run), on its scenes (MOVi-A and MOVi-C, seeds 1–3, the middle
frame, 128²).

Also printed per recipe: where a single low-sample frame's error is (its share of the squared
error on object, edge and other pixels against 64 spp's), and an error bound for spending the
samples where the objects are: the 64-spp image pasted over the object and edge pixels (dilated
by 0 / 8 px) of the low-sample frame — the best any object-aware sampling could do with the
low-sample count elsewhere (no cost: it is not a render) — and that lever rendered: 64 spp in
the bounding box of each connected part of the 8-px region (Cycles' render border, one render per
box) pasted into the low-sample frame, its cost the low-sample frame's plus the boxes'.

Output: rows in ``docs/data/render-temporal.json``, tables in ``docs/render-cost.md`` between its
temporal markers. Run: ``.venv/bin/python benchmarks/bench_temporal_accumulation.py [--recipes
movi_a movi_c] [--seeds 1 2 3]`` (about 12 min wall on the shared 2-core machine).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys
import tempfile
import time
from dataclasses import replace

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import oidn_ctypes  # noqa: E402
import smoke_mode  # noqa: E402
from bench_quality_calibration import (  # noqa: E402
    CLASSES,
    apply_profile,
    edge_pixels,
    errors,
    recipe_options,
    recipe_rows,
    run_child,
    textured_pixels,
    with_renderer,
    worst,
)
from bench_quality_levers import add_scene_arguments, write_tables  # noqa: E402

from kubric.recipes.render_quality import ANCHOR, RULE_FACTOR  # noqa: E402
from kubric.recipes.render_quality import _oidn as oidn  # noqa: E402

ROOT = HERE.parent
DATA = ROOT / "docs" / "data" / "render-temporal.json"
DOC = ROOT / "docs" / "render-cost.md"
MARKERS = ("<!-- temporal: begin -->", "<!-- temporal: end -->")
TODAY = oidn(64, adaptive=0.1)
TARGET_COST = 0.5
#: a history pixel is the same surface point when its object coordinates (in [0, 1] of the
#: object's box) are within this of the current pixel's
SAME_POINT = 0.02


def srgb8(linear: np.ndarray) -> np.ndarray:
    """Linear radiance → 8-bit sRGB (the Standard view transform's piecewise curve), (H, W, 3)."""
    x = np.clip(linear[..., :3], 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(s * 255).astype(np.uint8)


def render_linear(r, frames, profile, seeds: bool, guides: bool):
    """Render ``frames`` one by one under ``profile`` → ({frame: {pass: (H, W, C)}}, {frame:
    CPU-s}); ``seeds``: Cycles' animated seed (a different sampling pattern per frame);
    ``guides``: also write the denoising albedo / normal passes."""
    from kubric.renderer import blender_passes as bp
    apply_profile(r, profile)
    r._sync()
    prefix = r.scratch_dir / "linear_"
    r._configure_rgb(prefix)
    s = r.bpy_scene
    img = s.render.image_settings
    img.media_type, img.file_format = "MULTI_LAYER_IMAGE", "OPEN_EXR_MULTILAYER"
    img.color_depth, img.exr_codec = "32", "NONE"
    s.view_layers[0].cycles.denoising_store_passes = guides
    s.cycles.use_animated_seed = seeds
    images, cpu = {}, {}
    for f in frames:
        c0 = time.process_time()
        files = r._render_runs([f], str(prefix), ".exr")
        cpu[f] = time.process_time() - c0
        images[f] = bp.read_multilayer_exr(files[f])
    s.view_layers[0].cycles.denoising_store_passes = False
    s.cycles.use_animated_seed = False
    return images, cpu


def _nearest(a: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    h, w = a.shape[:2]
    return a[np.clip(np.rint(rows).astype(int), 0, h - 1), np.clip(np.rint(cols).astype(int),
                                                                    0, w - 1)]


def bilinear(a: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``a`` (H, W, C) at fractional pixel positions (rows, cols), bilinear."""
    h, w = a.shape[:2]
    r0 = np.clip(np.floor(rows).astype(int), 0, h - 2)
    c0 = np.clip(np.floor(cols).astype(int), 0, w - 2)
    fr = np.clip(rows - r0, 0, 1)[..., None]
    fc = np.clip(cols - c0, 0, 1)[..., None]
    return ((1 - fr) * (1 - fc) * a[r0, c0] + (1 - fr) * fc * a[r0, c0 + 1]
            + fr * (1 - fc) * a[r0 + 1, c0] + fr * fc * a[r0 + 1, c0 + 1])


def correspondences(exact: dict, frames: list[int]) -> dict[int, tuple]:
    """{history frame j: (rows, cols, same)}: where each pixel of the last frame's surface point
    is in frame j (backward flows chained, (Δrow, Δcol) px), and whether it is that point there
    (inside the image, same segmentation label, object coordinates within SAME_POINT)."""
    seg, flow = exact["segmentation"][..., 0], exact["backward_flow"]
    oc = exact["object_coordinates"].astype(np.float64)
    scale = 65535.0 if exact["object_coordinates"].dtype.kind == "u" else 1.0
    h, w = seg.shape[1:]
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float64)
    same = np.ones((h, w), bool)
    out = {}
    for i in range(len(frames) - 1, 0, -1):  # i: the frame the flow leaves; i - 1 its history
        step = _nearest(flow[i], rows, cols)
        rows, cols = rows + step[..., 0], cols + step[..., 1]
        inside = (rows >= 0) & (rows <= h - 1) & (cols >= 0) & (cols <= w - 1)
        same = (same & inside & (_nearest(seg[i - 1], rows, cols) == seg[-1])
                & (np.abs(_nearest(oc[i - 1], rows, cols) - oc[-1]).max(-1) / scale
                   < SAME_POINT))
        out[frames[i - 1]] = (rows.copy(), cols.copy(), same.copy())
    return out


def accumulate(images: dict, corr: dict, frames: list[int], k: int, denoised: dict | None,
               threshold: float | None):
    """The last frame's colour / albedo / normal averaged with its ``k`` − 1 previous frames' at
    the same surface points → (colour, albedo, normal, samples per pixel in frames)."""
    names = ("Combined", "Denoising Albedo", "Denoising Normal")
    m = frames[-1]
    sums = [images[m][n][..., :3].astype(np.float64) for n in names]
    count = np.ones(sums[0].shape[:2])
    for j in frames[-k:-1]:
        rows, cols, same = corr[j]
        weight = same.astype(np.float64)
        if threshold is not None:
            change = np.abs(bilinear(denoised[j].astype(np.float64), rows, cols)
                            - denoised[m]).max(-1)
            weight *= change <= threshold
        for total, n in zip(sums, names, strict=True):
            total += weight[..., None] * bilinear(images[j][n][..., :3], rows, cols)
        count += weight
    return [(t / count[..., None]).astype(np.float32) for t in sums] + [count]


def region_render(r, frame: int, region: np.ndarray, base8: np.ndarray):
    """``base8`` with ``region``'s pixels replaced by 64 spp (Cycles' OIDN) rendered in the
    bounding box of each connected part of ``region`` (Cycles' render border, one render per box)
    → (8-bit image, CPU-s of the box renders, fraction of the frame in boxes)."""
    from scipy import ndimage
    s = r.bpy_scene
    h, w = region.shape
    out, cpu, area = base8.copy(), 0.0, 0
    labels, _ = ndimage.label(region)
    try:
        for rows, cols in ndimage.find_objects(labels):
            s.render.use_border, s.render.use_crop_to_border = True, False
            s.render.border_min_x, s.render.border_max_x = cols.start / w, cols.stop / w
            s.render.border_min_y, s.render.border_max_y = 1 - rows.stop / h, 1 - rows.start / h
            images, cost = render_linear(r, [frame], ANCHOR, False, False)
            cpu += cost[frame]
            area += (rows.stop - rows.start) * (cols.stop - cols.start)
            inside = region[rows, cols]
            out[rows, cols][inside] = srgb8(images[frame]["Combined"])[rows, cols][inside]
    finally:
        s.render.use_border = False
    return out, cpu, area / (h * w)


def measure(r, reference_samples: int, spps, ks, thresholds) -> dict:
    """One scene: see the module doc."""
    from scipy import ndimage
    m = (r.scene.frame_start + r.scene.frame_end) // 2
    frames = list(range(max(r.scene.frame_start, m - max(ks) + 1), m + 1))
    exact = r.render(frames, ("segmentation", "backward_flow", "object_coordinates"))
    seg = exact["segmentation"][-1, ..., 0]
    background = [i for i, a in enumerate(r.scene.assets, start=1)
                  if getattr(a, "background", False)]
    render_linear(r, [m], replace(ANCHOR, samples=1, denoise=False), False, False)  # warm-up
    ref_images, ref_cpu = render_linear(r, [m], replace(ANCHOR, samples=reference_samples,
                                                        denoise=False), False, False)
    ref = srgb8(ref_images[m]["Combined"])
    edges = edge_pixels(seg)
    objects = (seg > 0) & ~np.isin(seg, background)
    masks = {"all": np.ones(seg.shape, bool), "objects": objects, "edges": edges,
             "textured": textured_pixels(ref, edges)}
    rows, images8 = {}, {}

    def record(label, image8, cpu, **extra):
        rows[label] = {"cpu": cpu, **errors(image8, ref, masks), **extra}
        images8[label] = image8
        print(f"  {label:60s} {cpu:6.2f} CPU-s  RMSE {np.sqrt(rows[label]['mse_all']):6.3f}",
              flush=True)

    for p in (ANCHOR, TODAY):  # the same frames, Cycles' own OIDN
        out, cpu = render_linear(r, frames, p, False, False)
        record(p.label, srgb8(out[m]["Combined"]), float(np.mean(list(cpu.values()))))
        if p is ANCHOR:
            anchor_frames = {f: srgb8(out[f]["Combined"]).astype(np.float64) for f in frames}
    # the denoiser outside Cycles, checked on 64 spp's noisy frame and guides
    out, cpu = render_linear(r, [m], replace(ANCHOR, denoise=False), False, True)
    c0 = time.process_time()
    image8 = srgb8(oidn_ctypes.denoise(*(out[m][n] for n in (
        "Combined", "Denoising Albedo", "Denoising Normal"))))
    record(f"{ANCHOR.label.split(' +')[0]} + OIDN (denoised outside Cycles)", image8,
           cpu[m] + time.process_time() - c0)
    corr = correspondences(exact, frames)
    same = {str(m - j): float(c[2].mean()) for j, c in corr.items()}
    # the light on surface points that do not move: 64 spp's frames m − k against frame m
    h, w = seg.shape
    grid = np.mgrid[0:h, 0:w]
    still = np.ones((h, w), bool)
    for rows_j, cols_j, same_j in corr.values():
        still &= same_j & (np.abs(rows_j - grid[0]) < 1e-6) & (np.abs(cols_j - grid[1]) < 1e-6)
    light = {"pixels": float(still.mean()), "error_64": float(np.sqrt(
        ((anchor_frames[m] - ref) ** 2).mean(-1)[still].mean())) if still.any() else None}
    light["change"] = {str(m - j): float(np.sqrt(((anchor_frames[j] - anchor_frames[m]) ** 2)
                                                 .mean(-1)[still].mean())) if still.any() else None
                       for j in frames[:-1]}
    bounds, shares = {}, {}
    for spp in spps:
        images, cpu = render_linear(r, frames, replace(ANCHOR, samples=spp, denoise=False),
                                    True, True)
        render_cpu = float(np.mean(list(cpu.values())))
        c0 = time.process_time()
        denoised = {f: oidn_ctypes.denoise(*(images[f][n] for n in (
            "Combined", "Denoising Albedo", "Denoising Normal"))) for f in frames}
        guide = {f: srgb8(d).astype(np.float64) for f, d in denoised.items()}
        denoise_cpu = (time.process_time() - c0) / len(frames)
        single = f"{spp} spp + OIDN (denoised outside Cycles)"
        record(single, srgb8(denoised[m]), render_cpu + denoise_cpu, frames=1.0)
        for k in ks:
            for t in thresholds:
                c0 = time.process_time()
                colour, albedo, normal, count = accumulate(images, corr, frames, k, guide, t)
                image8 = srgb8(oidn_ctypes.denoise(colour, albedo, normal))
                extra = time.process_time() - c0 + (denoise_cpu if t is not None else 0.0)
                label = f"{spp} spp, {k} frames along the flow" + (
                    "" if t is None else f", changes > {t:g} levels rejected")
                record(label, image8, render_cpu + extra, frames=float(count.mean()))
        # where the single frame's error is, and the object-aware bound
        e_low = ((images8[single].astype(float) - ref) ** 2).mean(-1)
        e_64 = ((images8[ANCHOR.label].astype(float) - ref) ** 2).mean(-1)
        rest = ~objects & ~edges
        shares[single] = {name: {"pixels": float(mask.mean()),
                                 "share": float(e_low[mask].sum() / e_low.sum()),
                                 "mse": float(e_low[mask].mean()),
                                 "mse_64": float(e_64[mask].mean())}
                          for name, mask in (("objects", objects), ("edges", edges & ~objects),
                                             ("rest", rest))}
        for grow in (0, 8):
            region = (ndimage.binary_dilation(objects | edges, iterations=grow) if grow
                      else objects | edges)
            composite = np.where(region[..., None], images8[ANCHOR.label], images8[single])
            bounds[f"{single}, 64 spp over objects and edges + {grow} px"] = {
                "pixels": float(region.mean()), **errors(composite, ref, masks)}
        # the same, rendered: 64 spp in each box of that region (Cycles' render border)
        image8, cpu, area = region_render(r, m, region, images8[single])
        record(f"{spp} spp + 64 spp in the boxes of objects and edges + 8 px", image8,
               rows[single]["cpu"] + cpu, frames=1.0, box_pixels=area)
    return {"frame": m, "frames": frames, "resolution": [w, h],
            "reference_cpu": float(ref_cpu[m]),
            "fractions": {c: float(mask.mean()) for c, mask in masks.items()},
            "same_point": same, "light": light, "settings": rows, "bounds": bounds, "shares": shares}


def child(recipe: str, seed: int, reference_samples: int, assignments: list[str],
          out: pathlib.Path, spps, ks, thresholds) -> None:
    with tempfile.TemporaryDirectory(prefix="bench_temporal_") as tmp:
        tmp = pathlib.Path(tmp)
        options = [*recipe_options(recipe, tmp / "objects"), *assignments]
        result = with_renderer(recipe, seed, options, tmp / "scene", lambda r: measure(
            r, reference_samples, spps, ks, thresholds))
    out.write_text(json.dumps({"recipe": recipe, "seed": seed, **result}))


# -- tables ----------------------------------------------------------------------------------------

def _ratios(row: dict, anchor: dict) -> dict[str, float]:
    return {c: np.sqrt(row[f"mse_{c}"] / anchor[f"mse_{c}"]) for c in CLASSES
            if row[f"mse_{c}"] is not None and anchor[f"mse_{c}"]} | {
        "dssim": row["dssim"] / anchor["dssim"]}


def summary(data: dict) -> list[str]:
    rows_of = recipe_rows(data)
    names = list(rows_of)
    load = ", ".join(f"{v:.1f}" for v in data["load"])
    lines = [
        f"Printed by `benchmarks/bench_temporal_accumulation.py` ({data['date']}, "
        f"{data['machine']}, load average at start / end {load}; "
        f"{' '.join(data['set']) or 'recipe defaults'}; {data['reference_samples']}-spp "
        f"reference; seeds {', '.join(map(str, data['seeds']))}). Rule as the calibration's: "
        f"every error measure within {RULE_FACTOR}× of {ANCHOR.label} in the same run; *pays* = "
        f"meets it on every recipe at ≤ {TARGET_COST}× 64 spp's cost; *frames* = mean frames "
        "averaged per pixel.", "",
        "| setting | " + " | ".join(f"{n} × 64 spp cost | {n} worst ratio | {n} frames"
                                   for n in names) + " | pays |",
        "|---|" + "---|---|---|" * len(names) + "---|"]
    for label in rows_of[names[0]]:
        cells, pays = [], True
        for name in names:
            rows = rows_of[name]
            cost = rows[label]["cpu"] / rows[ANCHOR.label]["cpu"]
            ratio = worst(rows[label], rows[ANCHOR.label])
            pays &= ratio <= RULE_FACTOR and cost <= TARGET_COST
            frames = np.mean([s["settings"][label].get("frames", 1.0) for s in data["scenes"]
                              if s["recipe"] == name])
            cells += [f"{cost:.2f}", f"{ratio:.2f}" + (" ✓" if ratio <= RULE_FACTOR else ""),
                      f"{frames:.2f}"]
        lines.append(f"| {label} | {' | '.join(cells)} | {'**yes**' if pays else 'no'} |")
    boxes = {(name, label): np.mean([s["settings"][label]["box_pixels"] for s in data["scenes"]
                                     if s["recipe"] == name])
             for name in names for label in rows_of[name]
             if "box_pixels" in data["scenes"][0]["settings"].get(label, {})}
    if boxes:
        lines += ["", "Frame area in the render-border boxes: " + "; ".join(
            f"{name}, {label.split(' +')[0]}: {v:.0%}" for (name, label), v in boxes.items())
            + "."]
    lines += ["", "Where a single low-sample frame's error is (pooled over seeds; *share* of its "
              "squared error; MSE against 64 spp's on the same pixels), and the object-aware "
              "bound (64 spp pasted over the object and edge pixels; error ratios to 64 spp):", "",
              "| recipe | frame | objects: pixels / share / MSE (64 spp) | edges | rest |",
              "|---|---|---|---|---|"]
    for name in names:
        scenes = [s for s in data["scenes"] if s["recipe"] == name]
        for label in scenes[0]["shares"]:
            cells = []
            for part in ("objects", "edges", "rest"):
                v = [s["shares"][label][part] for s in scenes]
                cells.append(f"{np.mean([x['pixels'] for x in v]):.1%} / "
                             f"{np.mean([x['share'] for x in v]):.0%} / "
                             f"{np.mean([x['mse'] for x in v]):.2f} "
                             f"({np.mean([x['mse_64'] for x in v]):.2f})")
            lines.append(f"| {name} | {label} | {' | '.join(cells)} |")
    lines += ["", "The light on surface points that do not move (same label, zero flow over "
              "every frame): RMS 8-bit difference between 64 spp's frame m − k and frame m, "
              "against 64 spp's own error there (pooled over seeds):", ""]
    ks = sorted({k for s in data["scenes"] for k in s["light"]["change"]}, key=int)
    lines += ["| recipe | pixels | 64 spp's error | " + " | ".join(
        f"change from m − {k}" for k in ks) + " |", "|---|---|---|" + "---|" * len(ks)]
    for name in names:
        scenes = [s for s in data["scenes"] if s["recipe"] == name and s["light"]["error_64"]]
        if not scenes:
            continue

        def rms(values):
            return float(np.sqrt(np.mean(np.square(values))))

        changes = [rms([s["light"]["change"][k] for s in scenes if k in s["light"]["change"]])
                   for k in ks]
        lines.append(f"| {name} | {np.mean([s['light']['pixels'] for s in scenes]):.0%} | "
                     f"{rms([s['light']['error_64'] for s in scenes]):.2f} | "
                     + " | ".join(f"{c:.2f}" for c in changes) + " |")
    lines += ["", "| recipe | bound | pixels at 64 spp | ratios all / objects / edges / textured / "
              "1 − SSIM | worst |", "|---|---|---|---|---|"]
    for name in names:
        scenes = [s for s in data["scenes"] if s["recipe"] == name]
        anchor = rows_of[name][ANCHOR.label]
        for label in scenes[0]["bounds"]:
            pooled = {f"mse_{c}": float(np.mean([s["bounds"][label][f"mse_{c}"] for s in scenes]))
                      for c in CLASSES}
            pooled["dssim"] = float(np.mean([s["bounds"][label]["dssim"] for s in scenes]))
            anchor_mse = {f"mse_{c}": anchor[f"rmse_{c}"] ** 2 for c in CLASSES} | {
                "dssim": anchor["dssim"]}
            r = _ratios(pooled, anchor_mse)
            pixels = np.mean([s["bounds"][label]["pixels"] for s in scenes])
            lines.append(f"| {name} | {label} | {pixels:.0%} | "
                         f"{' / '.join(f'{v:.2f}' for v in r.values())} | "
                         f"{max(r.values()):.2f} |")
    return lines + [""]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_scene_arguments(parser)
    parser.add_argument("--spp", nargs="*", type=int, default=smoke_mode.size([8, 16], [1]),
                        help="samples per frame of the accumulated renders")
    parser.add_argument("--frames", nargs="*", type=int, default=smoke_mode.size([2, 4], [2]),
                        help="frames averaged (the current one and its history)")
    parser.add_argument("--reject", nargs="*", type=float, default=smoke_mode.size([3.0], [3.0]),
                        help="rejection thresholds in 8-bit levels (also run without)")
    parser.add_argument("--json", type=pathlib.Path, default=smoke_mode.output(DATA))
    parser.add_argument("--doc", type=pathlib.Path, default=smoke_mode.output(DOC))
    parser.add_argument("--set", action="append", metavar="KEY=VALUE", default=None,
                        help="options for every recipe (default: resolution=128)")
    parser.add_argument("--tables-only", action="store_true")
    parser.add_argument("--child", nargs=3, metavar=("RECIPE", "SEED", "OUT"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.set is None:
        args.set = smoke_mode.size(["resolution=128"], ["resolution=16"])
    thresholds = [None, *args.reject]
    os.environ.setdefault("KUBRIC_CACHE_DIR", str(ROOT / ".cache" / "kubric"))
    if args.child:
        recipe, seed, out = args.child
        child(recipe, int(seed), args.reference_samples, args.set, pathlib.Path(out), args.spp,
              args.frames, thresholds)
        return 0
    if args.tables_only:
        return write_tables(json.loads(args.json.read_text()), args.doc, MARKERS, summary)
    data = {"reference_samples": args.reference_samples, "set": args.set, "seeds": args.seeds,
            "scenes": [], "date": time.strftime("%Y-%m-%d"), "load": [os.getloadavg()[0]],
            "machine": f"{len(os.sched_getaffinity(0))} cores"}
    extra = ("--spp", *map(str, args.spp), "--frames", *map(str, args.frames),
             "--reject", *map(str, args.reject))
    for seed in args.seeds:
        for recipe in args.recipes:
            print(f"{recipe} seed {seed}", flush=True)
            data["scenes"].append(run_child(__file__, recipe, seed, args.reference_samples,
                                            args.set, extra))
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps(data, indent=1))
    data["load"].append(os.getloadavg()[0])
    args.json.write_text(json.dumps(data, indent=1))
    print(f"rows → {args.json}")
    return write_tables(data, args.doc, MARKERS, summary)


if __name__ == "__main__":
    raise SystemExit(main())
