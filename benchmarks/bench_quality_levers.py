"""Cycles' levers under the calibration's rule, alone and combined, on MOVi-A and MOVi-C: noise
levers (path guiding, clamping, filter glossy, adaptive sampling's minimum samples / threshold),
OIDN's guide passes / network / prefilter at 16–32 spp, the per-sample cost levers (bounces, fast
GI, light threshold, caustics, minimum light bounces, tile size, scrambling distance), and the
floor shadow catcher of MOVi-C (rendered unlit against the same reference).

The sibling of ``bench_quality_calibration.py`` with the same scenes, reference, measures, pooling
and rule (``choose_default``: error on every measure within 1.15× of 64 spp + OIDN HIGH/ACCURATE),
over :data:`LEVER_SETTINGS` (``--group levers``) or :data:`COMBINED_SETTINGS` (``--group
combined``: the cheap levers combined) instead of the calibration grid: for each recipe and seed
one fresh
process builds the scene, stops where the recipe would render and renders its middle frame under
every setting and once at the reference's sample count without denoising (Blender's defaults for
the levers, as in the calibration). Cost: CPU-s of that one-frame render after a warm-up, and its
ratio to 64 spp's in the same process. By default at 128² (``--set resolution=128``) to fit a
small CPU budget: the ratios, not the CPU-s, carry to 256².

Output: the rows in ``docs/data/render-levers.json`` (``render-levers-combined.json``) and the
tables in ``docs/render-cost.md`` between its levers (levers-combined) markers (date, load
average, size printed with them).

Run: ``.venv/bin/python benchmarks/bench_quality_levers.py [--group levers|combined]
[--recipes movi_a movi_c] [--seeds 1 2 3] [--set resolution=128]``. The levers group: about 30
min wall for both recipes and 3 seeds at 128² on the shared, loaded 2-core machine (a third of
it the 1024-spp references); the combined group about 15 min.
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

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import smoke_mode  # noqa: E402
from bench_quality_calibration import (  # noqa: E402
    measure_settings,
    recipe_options,
    recipe_rows,
    recipe_table,
    run_child,
    with_renderer,
    worst,
)

from kubric.recipes.render_quality import ANCHOR, RULE_FACTOR, choose_default  # noqa: E402
from kubric.recipes.render_quality import _oidn as oidn  # noqa: E402

ROOT = HERE.parent
DATA = ROOT / "docs" / "data" / "render-levers.json"
DOC = ROOT / "docs" / "render-cost.md"
BEGIN, END = "<!-- levers: begin -->", "<!-- levers: end -->"

TODAY = oidn(64, adaptive=0.1)  # MOVi-A and MOVi-C's calibrated default
#: the settings measured: the anchor and today's default, sample counts for the curve, then each
#: lever alone on today's default, then combinations at lower cost
LEVER_SETTINGS = (
    ANCHOR, TODAY, oidn(32), oidn(48),
    # path guiding (surface: MOVi has no volumes)
    replace(TODAY, path_guiding="surface"), replace(oidn(32), path_guiding="surface"),
    # clamping (Blender's defaults: direct 0 = off, indirect 10)
    replace(TODAY, clamp_indirect=3.0), replace(TODAY, clamp_indirect=1.0),
    replace(TODAY, clamp_direct=4.0, clamp_indirect=1.0), replace(oidn(32), clamp_indirect=1.0),
    # filter glossy (Blender's default 1)
    replace(TODAY, filter_glossy=0.0), replace(TODAY, filter_glossy=3.0),
    # adaptive sampling: threshold and minimum samples
    oidn(64, adaptive=0.2), oidn(64, adaptive=0.3),
    replace(TODAY, adaptive_min_samples=4), replace(TODAY, adaptive_min_samples=16),
    replace(oidn(64, adaptive=0.2), adaptive_min_samples=16),
    # combinations
    replace(oidn(64, adaptive=0.2), clamp_indirect=1.0, filter_glossy=3.0),
    replace(oidn(32), clamp_indirect=1.0, filter_glossy=3.0),
    replace(oidn(32), clamp_indirect=1.0, filter_glossy=3.0, path_guiding="surface"),
    # OIDN at low sample counts: guide passes, network, prefilter (the calibration has 16 spp
    # with the FAST / NONE prefilters and 32 spp with FAST)
    oidn(16), replace(oidn(16), denoising_input_passes="RGB_ALBEDO"),
    replace(oidn(32), denoising_input_passes="RGB_ALBEDO"),
    replace(oidn(32), denoising_input_passes="RGB"), oidn(32, "BALANCED"),
    oidn(32, prefilter="NONE"),
    # per-sample cost levers that change bias, alone on today's default
    replace(TODAY, total_bounces=4, diffuse_bounces=2, glossy_bounces=2, transmission_bounces=4),
    replace(TODAY, total_bounces=2, diffuse_bounces=1, glossy_bounces=1, transmission_bounces=2),
    replace(TODAY, fast_gi=1), replace(TODAY, light_threshold=0.1),
    replace(TODAY, caustics=False), replace(TODAY, min_light_bounces=2),
    # ... and those that only reorder the work (scrambling: fixed samples, Cycles ignores it
    # under adaptive sampling)
    replace(TODAY, tile_size=64), replace(oidn(32), scrambling_distance="auto"),
    replace(oidn(32), scrambling_distance=0.2),
    # combinations of the cost levers
    replace(oidn(32), total_bounces=4, diffuse_bounces=2, glossy_bounces=2,
            transmission_bounces=4, fast_gi=1, caustics=False),
    replace(TODAY, total_bounces=4, diffuse_bounces=2, glossy_bounces=2, transmission_bounces=4,
            fast_gi=1, caustics=False),
)
#: the floor shadow catcher (MOVi-C–F: a FlatMaterial with catch_shadows): where a scene has one,
#: these settings are also rendered with it turned off (the unlit floor, ``floor_shadows=false``)
#: and measured against the same reference (the shadowed floor)
UNLIT_FLOOR = (ANCHOR, TODAY)
#: the levers that cost no error alone on both recipes, or little (light threshold 0.1; OIDN's
#: NONE prefilter at 32 spp), combined on today's default and at fewer samples
#: (``--group combined``); 64 spp with the light threshold shows its per-sample saving
_CHEAP = {"denoising_prefilter": "NONE", "light_threshold": 0.1}
COMBINED_SETTINGS = (
    ANCHOR, TODAY, replace(ANCHOR, light_threshold=0.1), replace(TODAY, light_threshold=0.1),
    oidn(64, prefilter="NONE", adaptive=0.1), replace(TODAY, **_CHEAP),
    replace(oidn(64, adaptive=0.15), **_CHEAP), replace(oidn(48, adaptive=0.1), **_CHEAP),
)
#: --group → (settings, rows file, docs markers, whether the floor is also rendered unlit)
GROUPS = {
    "levers": (LEVER_SETTINGS, DATA, (BEGIN, END), True),
    "combined": (COMBINED_SETTINGS, DATA.with_name("render-levers-combined.json"),
                 ("<!-- levers-combined: begin -->", "<!-- levers-combined: end -->"), False),
}
#: the cost a new default must reach (× 64 spp's) to be proposed (issue 42)
TARGET_COST = 0.5


def child(recipe: str, seed: int, reference_samples: int, assignments: list[str],
          out: pathlib.Path, group: str = "levers") -> None:
    settings, _, _, floor = GROUPS[group]
    with tempfile.TemporaryDirectory(prefix="bench_levers_") as tmp:
        tmp = pathlib.Path(tmp)
        options = [*recipe_options(recipe, tmp / "objects"), *assignments]
        result = with_renderer(recipe, seed, options, tmp / "scene", lambda r: measure_settings(
            r, reference_samples, settings, floor_variants(r) if floor else ()))
    out.write_text(json.dumps({"recipe": recipe, "seed": seed, **result}))


def floor_variants(r) -> list:
    """(label, profile, change) of :data:`UNLIT_FLOOR` with the scene's shadow catchers turned
    off, for ``measure_settings``; none where the scene has no shadow catcher."""
    from kubric.core.materials import FlatMaterial
    catchers = [a for a in r.scene.assets if isinstance(a, FlatMaterial) and a.catch_shadows]
    if not catchers:
        return []

    def change(renderer, on: bool) -> None:
        for material in catchers:
            material.catch_shadows = not on

    return [(f"{p.label}, floor unlit", p, change) for p in UNLIT_FLOOR]


def summary(data: dict) -> list[str]:
    """The header lines and one row per setting: its cost ratio and worst error ratio on each
    recipe, and whether it meets the rule on every recipe at ≤ TARGET_COST × 64 spp's cost."""
    rows_of = recipe_rows(data)
    names = list(rows_of)
    load = ", ".join(f"{v:.1f}" for v in data["load"])
    lines = [
        f"Printed by `benchmarks/bench_quality_levers.py` ({data['date']}, {data['machine']}, "
        f"load average at start / end {load}; {' '.join(data['set']) or 'recipe defaults'}; "
        f"{data['reference_samples']}-spp reference). Rule as the calibration's: every error "
        f"measure within {RULE_FACTOR}× of {ANCHOR.label} in the same run; *pays* = meets the "
        f"rule on every recipe at ≤ {TARGET_COST}× 64 spp's cost.", "",
        "| setting | " + " | ".join(f"{n} × 64 spp cost | {n} worst ratio" for n in names)
        + " | pays |",
        "|---|" + "---|---|" * len(names) + "---|"]
    labels = list(dict.fromkeys(label for rows in rows_of.values() for label in rows))
    for label in labels:
        cells, pays = [], True
        for name in names:
            rows = rows_of[name]
            if label not in rows:  # e.g. the unlit floor of a recipe without a shadow catcher
                cells += ["–", "–"]
                pays = False
                continue
            cost = rows[label]["cpu"] / rows[ANCHOR.label]["cpu"]
            ratio = worst(rows[label], rows[ANCHOR.label])
            pays &= ratio <= RULE_FACTOR and cost <= TARGET_COST
            cells += [f"{cost:.2f}", f"{ratio:.2f}" + (" ✓" if ratio <= RULE_FACTOR else "")]
        lines.append(f"| {label} | {' | '.join(cells)} | {'**yes**' if pays else 'no'} |")
    chosen = {name: choose_default(rows) for name, rows in rows_of.items()}
    lines += ["", "Cheapest setting within the rule: " + "; ".join(
        f"{name}: {label} ({rows_of[name][label]['cpu'] / rows_of[name][ANCHOR.label]['cpu']:.2f}"
        "× 64 spp)" for name, label in chosen.items()) + ".", ""]
    return lines


def write_doc(text: str, doc: pathlib.Path, markers=(BEGIN, END)) -> None:
    begin, end = markers
    page = doc.read_text()
    if begin not in page or end not in page:
        raise SystemExit(f"{doc} has no {begin} … {end} section to fill")
    head, rest = page.split(begin, 1)
    doc.write_text(f"{head}{begin}\n{text}\n{end}{rest.split(end, 1)[1]}")


def write_tables(data: dict, doc: pathlib.Path, markers=(BEGIN, END), summarize=None) -> int:
    """Print the summary (``summarize(data)``, default :func:`summary`) and write it with every
    recipe's table into ``doc`` between ``markers``."""
    lines = (summarize or summary)(data)
    print("\n".join(lines))
    for name, rows in recipe_rows(data).items():
        lines += recipe_table(name, rows, [s for s in data["scenes"] if s["recipe"] == name])
    write_doc("\n".join(lines), doc, markers)
    print(f"tables → {doc}")
    return 0


def add_scene_arguments(parser: argparse.ArgumentParser) -> None:
    """--recipes (MOVi-A and MOVi-C), --seeds (1–3), --reference-samples (1024); smoke sizes."""
    parser.add_argument("--recipes", nargs="*", default=smoke_mode.size(["movi_a", "movi_c"],
                                                                         ["movi_a"]))
    parser.add_argument("--seeds", nargs="*", type=int, default=smoke_mode.size([1, 2, 3], [1]))
    parser.add_argument("--reference-samples", type=int, default=smoke_mode.size(1024, 4))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_scene_arguments(parser)
    parser.add_argument("--group", choices=tuple(GROUPS), default="levers",
                        help="levers: every lever alone and the first combinations (default); "
                        "combined: the levers that cost little or no error, combined")
    parser.add_argument("--json", type=pathlib.Path, default=None,
                        help="default: docs/data/render-levers.json (…-combined.json)")
    parser.add_argument("--doc", type=pathlib.Path, default=smoke_mode.output(DOC))
    parser.add_argument("--set", action="append", metavar="KEY=VALUE", default=None,
                        help="options for every recipe (default: resolution=128)")
    parser.add_argument("--tables-only", action="store_true",
                        help="print and write the tables of the scenes already in --json")
    parser.add_argument("--child", nargs=3, metavar=("RECIPE", "SEED", "OUT"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.set is None:
        args.set = smoke_mode.size(["resolution=128"], ["resolution=16"])
    settings, default_json, markers, _ = GROUPS[args.group]
    args.json = args.json or smoke_mode.output(default_json)
    os.environ.setdefault("KUBRIC_CACHE_DIR", str(ROOT / ".cache" / "kubric"))
    if args.child:
        recipe, seed, out = args.child
        child(recipe, int(seed), args.reference_samples, args.set, pathlib.Path(out), args.group)
        return 0
    if args.tables_only:  # e.g. a run stopped after some seeds
        data = json.loads(args.json.read_text())
        data["load"] = data["load"][:1] + [os.getloadavg()[0]]
        return write_tables(data, args.doc, markers)
    data = {"reference_samples": args.reference_samples, "set": args.set, "group": args.group,
            "settings": [p.label for p in settings], "scenes": [],
            "date": time.strftime("%Y-%m-%d"), "load": [os.getloadavg()[0]],
            "machine": f"{len(os.sched_getaffinity(0))} cores"}
    for seed in args.seeds:  # seed-major: a stopped run still covers every recipe
        for recipe in args.recipes:
            print(f"{recipe} seed {seed}", flush=True)
            data["scenes"].append(run_child(__file__, recipe, seed, args.reference_samples,
                                            args.set, ("--group", args.group)))
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps(data, indent=1))  # kept if the run is stopped
    data["load"].append(os.getloadavg()[0])
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(data, indent=1))
    print(f"rows → {args.json}")
    return write_tables(data, args.doc, markers)


if __name__ == "__main__":
    raise SystemExit(main())
