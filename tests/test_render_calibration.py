"""The per-recipe render defaults follow from the calibration by the stated rule.

The calibration (docs/data/render-calibration.json, written by
benchmarks/bench_quality_calibration.py) covers every recipe that path-traces RGB on several
seeds and every calibration setting; re-applying the rule to it gives each recipe's default in
code; docs/render-cost.md holds the tables of exactly that file; and a recipe's ``default``
resolves to its calibrated setting, recorded in metadata, while ``quality=`` overrides it.
"""

from __future__ import annotations

import json
import pathlib

import numpy as np
import pytest

from benchmarks import bench_quality_calibration as cal
from kubric.pipeline.recipe import get_recipe, load_builtin
from kubric.recipes.render_quality import (
    ANCHOR,
    CALIBRATED_DEFAULTS,
    CALIBRATION_SETTINGS,
    PROFILES,
    RULE_FACTOR,
    RULE_MEASURES,
    RenderQuality,
    choose_default,
    profile_by_label,
)

ROOT = pathlib.Path(__file__).resolve().parents[1]
DATA = json.loads((ROOT / "docs" / "data" / "render-calibration.json").read_text())
RECIPES = sorted(name for name, cls in load_builtin().items() if issubclass(cls, RenderQuality))


def test_the_calibration_covers_every_recipe_on_several_seeds_and_every_setting():
    assert DATA["reference_samples"] == 1024 and DATA["set"] == []
    assert DATA["settings"] == [p.label for p in CALIBRATION_SETTINGS]
    seeds: dict[str, set] = {}
    for scene in DATA["scenes"]:
        seeds.setdefault(scene["recipe"], set()).add(scene["seed"])
        assert list(scene["settings"]) == DATA["settings"]
    assert sorted(seeds) == RECIPES
    assert all(len(s) >= 3 for s in seeds.values()), seeds


@pytest.mark.parametrize("recipe", RECIPES)
def test_each_recipe_default_is_what_the_rule_picks_from_its_calibration(recipe):
    rows = cal.recipe_rows(DATA)[recipe]
    chosen = choose_default(rows)
    assert CALIBRATED_DEFAULTS[recipe].label == chosen
    anchor = rows[ANCHOR.label]
    for m in RULE_MEASURES:  # the rule, checked on the numbers themselves
        if anchor[m] is not None and rows[chosen][m] is not None:
            assert rows[chosen][m] <= RULE_FACTOR * anchor[m], (recipe, m)
    cheaper = [label for label, row in rows.items() if row["cpu"] < rows[chosen]["cpu"]]
    for label in cheaper:  # and nothing cheaper passes it
        assert any(rows[label][m] > RULE_FACTOR * anchor[m] for m in RULE_MEASURES
                   if anchor[m] is not None and rows[label][m] is not None), (recipe, label)


def test_the_docs_hold_the_tables_of_the_calibration_file():
    text = (ROOT / "docs" / "render-cost.md").read_text()
    section = text.split(cal.BEGIN, 1)[1].split(cal.END, 1)[0]
    assert section.strip() == cal.tables(DATA).strip(), \
        "docs/render-cost.md is stale: rerun benchmarks/bench_quality_calibration.py --resume"


def test_the_rule_takes_the_cheapest_setting_within_the_factor_on_every_measure():
    def row(cpu, err, **other):
        return {"cpu": cpu, **{m: err for m in RULE_MEASURES}, **other}
    rows = {ANCHOR.label: row(8.0, 1.0), "a": row(1.0, 1.2), "b": row(2.0, 1.1),
            "c": row(1.5, 1.0, rmse_edges=1.16), "d": row(3.0, 1.0)}
    assert choose_default(rows) == "b"
    rows["e"] = row(0.5, 1.0, rmse_textured=None)  # a class absent from every seed is skipped
    assert choose_default(rows) == "e"
    with pytest.raises(ValueError, match="no '64 spp"):
        choose_default({"a": row(1.0, 1.0)})


def test_ssim_equals_a_direct_window_by_window_computation():
    rng = np.random.default_rng(0)
    ref = rng.integers(0, 256, (12, 14, 3)).astype(np.uint8)
    img = np.clip(ref + rng.normal(0, 20, ref.shape), 0, 255).astype(np.uint8)
    assert cal.ssim(ref, ref) == pytest.approx(1.0)
    x, y = cal.luma(img), cal.luma(ref)
    r = np.arange(-5, 6)
    g = np.exp(-(r[:, None] ** 2 + r[None] ** 2) / (2 * 1.5 ** 2))
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    xp, yp = np.pad(x, 5, mode="symmetric"), np.pad(y, 5, mode="symmetric")
    values = []
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            wx, wy = xp[i:i + 11, j:j + 11], yp[i:i + 11, j:j + 11]
            w = g / g.sum()
            mx, my = (w * wx).sum(), (w * wy).sum()
            vx, vy = (w * (wx - mx) ** 2).sum(), (w * (wy - my) ** 2).sum()
            cov = (w * (wx - mx) * (wy - my)).sum()
            values.append((2 * mx * my + c1) * (2 * cov + c2) /
                          ((mx ** 2 + my ** 2 + c1) * (vx + vy + c2)))
    assert cal.ssim(img, ref) == pytest.approx(np.mean(values), abs=1e-9)


def test_textured_and_edge_pixels_find_what_they_name():
    seg = np.zeros((20, 20), np.uint32)
    seg[5:15, 5:15] = 2
    edges = cal.edge_pixels(seg)
    assert edges[4, 10] and edges[7, 10] and not edges[10, 10] and not edges[0, 0]
    ref = np.full((20, 20, 3), 100, np.uint8)
    ref[:, 16:][::2] = 200  # stripes: texture on the right, flat elsewhere
    textured = cal.textured_pixels(ref, edges)
    assert textured[10, 18] and not textured[10, 2] and not textured[10, 10]


def test_default_resolves_to_the_recipes_calibrated_setting_and_quality_overrides_it():
    assert sorted(CALIBRATED_DEFAULTS) == RECIPES
    for recipe in RECIPES:
        if recipe == "toybox":  # needs a categorised asset source to construct; same mixin
            continue
        r = get_recipe(recipe).from_assignments([])
        p = CALIBRATED_DEFAULTS[recipe]
        assert r.quality_profile() == p
        kw = r.renderer_quality()
        assert kw["samples_per_pixel"] == p.samples
        assert kw.get("adaptive_threshold") == p.adaptive_threshold
        final = get_recipe(recipe).from_assignments(["quality=final"])
        assert final.quality_profile() == PROFILES["final"]
    adaptive = next(n for n in RECIPES if CALIBRATED_DEFAULTS[n].adaptive_threshold)
    fixed = get_recipe(adaptive).from_assignments(["samples=16"])  # exactly 16: adaptive off
    assert fixed.quality_profile().adaptive_threshold is None
    assert "adaptive_sampling" not in fixed.renderer_quality()
    assert fixed.renderer_quality()["samples_per_pixel"] == 16
    assert profile_by_label(ANCHOR.label) == ANCHOR
    with pytest.raises(ValueError, match="unknown render setting 'ultra'"):
        profile_by_label("ultra")
