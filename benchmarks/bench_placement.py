"""How KuBasic's shape size decides whether upstream-style placements can succeed (not a test).

Two placements from the paper and upstream's recipes, each with KuBasic shapes at their built size
(unit-sized, ±0.5 m, as upstream's) and at twice that size (±1 m, our KuBasic 1.x) as the baseline
measured in the same run:

* MOVi-A: 10 CLEVR shapes (cube / cylinder / sphere at scale 0.7 or 1.4) placed without overlap
  in (−5, −5, 1)–(5, 5, 5) above a floor, 100 trials each (upstream's worker aborts the scene
  when one placement fails). Counted: scenes in which all 10 were placed.
* Figure 3: the paper's listing, 8 random KuBasic shapes in [[−1, −1, 0], [1, 1, 1]] above a floor
  whose top is z = 0, and in ``examples/figure3.py``'s default region [[−2.5, −2.5, 0], [2.5, 2.5, 2.5]].
  Counted: objects placed before the first failure.

Each is run with our placement rule (the rotated bounding box must lie inside the region) and with
upstream's (the position is drawn between region − box bounds, so a box larger than the region
overhangs it). Run: ``python benchmarks/bench_placement.py [--scenes N]``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import smoke_mode

import kubric as kb
from kubric import randomness

MOVI_REGION = [(-5, -5, 1), (5, 5, 5)]
FIGURE3_REGION = [[-1, -1, 0], [1, 1, 1]]
FIGURE3_DEFAULT_REGION = [[-2.5, -2.5, 0], [2.5, 2.5, 2.5]]


def upstream_position_sampler(region):
    """Upstream Kubric's rule: uniform between (region_min − box_min, region_max − box_max)."""
    region = np.asarray(region, dtype=np.float64)

    def sample(obj, rng):
        obj.position = (0, 0, 0)
        low, high = region - np.asarray(obj.aabbox, dtype=np.float64)
        obj.position = rng.uniform(low, high)
    return sample


def _place_all(source, picks, region, rng) -> int:
    """Add the (asset id, scale) picks one by one; return how many were placed."""
    scene = kb.Scene(resolution=(16, 16))
    simulator = kb.simulator.PyBullet(scene)
    scene += kb.Cube(name="floor", scale=(40, 40, 0.1), position=(0, 0, -0.1), static=True)
    placed = 0
    try:
        for asset_id, scale in picks(rng):
            obj = source.create(asset_id, scale=scale)
            scene += obj
            try:
                kb.move_until_no_overlap(obj, simulator, spawn_region=region, rng=rng)
            except RuntimeError:
                break
            placed += 1
    finally:
        simulator.close()
    return placed


def movi_a_picks(factor):
    def picks(rng):
        for _ in range(10):
            shape = ["cube", "cylinder", "sphere"][rng.randint(3)]
            yield shape, [0.7, 1.4][rng.randint(2)] * factor
    return picks


def figure3_picks(factor, shapes):
    def picks(rng):
        for _ in range(8):
            yield shapes[rng.randint(len(shapes))], factor
    return picks


def measure(scenes: int) -> list[dict]:
    from kubric.asset_tools import ensure_kubasic

    source = ensure_kubasic()
    shapes = [i for i in source.all_asset_ids if i != "dome"]
    ours = randomness.position_sampler
    rows = []
    for rule in ("ours", "upstream"):
        randomness.position_sampler = ours if rule == "ours" else upstream_position_sampler
        try:
            for factor in (1.0, 2.0):
                t0 = time.perf_counter()
                movi = [_place_all(source, movi_a_picks(factor), MOVI_REGION,
                                   np.random.RandomState(seed)) for seed in range(scenes)]
                fig3 = [_place_all(source, figure3_picks(factor, shapes), FIGURE3_REGION,
                                   np.random.RandomState(seed)) for seed in range(scenes)]
                wide = [_place_all(source, figure3_picks(factor, shapes), FIGURE3_DEFAULT_REGION,
                                   np.random.RandomState(seed)) for seed in range(scenes)]
                rows.append({"rule": rule, "shape_half_size_m": 0.5 * factor,
                             "movi_a_scenes_with_all_10": f"{sum(n == 10 for n in movi)}/{scenes}",
                             "movi_a_mean_placed": round(float(np.mean(movi)), 2),
                             "figure3_scenes_with_all_8": f"{sum(n == 8 for n in fig3)}/{scenes}",
                             "figure3_mean_placed": round(float(np.mean(fig3)), 2),
                             "figure3_default_region_all_8": f"{sum(n == 8 for n in wide)}/{scenes}",
                             "seconds": round(time.perf_counter() - t0, 1)})
                print(json.dumps(rows[-1]), flush=True)
        finally:
            randomness.position_sampler = ours
    return rows


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=smoke_mode.size(100, 1), help="seeds per configuration")
    return measure(parser.parse_args(argv).scenes)


if __name__ == "__main__":
    main()
