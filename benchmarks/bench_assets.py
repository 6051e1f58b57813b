"""Asset-source measurements (not a test): KuBasic build time, the full pybullet_data conversion,
and V-HACD vs CoACD on the non-convex meshes of the test collection.

Run: ``python benchmarks/bench_assets.py [--out DIR] [--workers N] [--limit N] [--skip-full]``.
CoACD is optional (``pip install coacd``); without it only V-HACD is measured.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
import smoke_mode

#: a smoke run's subsets (a full run takes all): KuBasic shapes built, pybullet_data objects
#: converted, textured models and KuBasic shapes whose convex decomposition is timed
KUBASIC_SHAPES = smoke_mode.size(None, ["cube", "sphere"])
CONVERTED = smoke_mode.size(None, ["jenga", "textured_cube"])
DECOMPOSED_MODELS = smoke_mode.size(None, ["concave_box"])
DECOMPOSED_SHAPES = smoke_mode.size(("gear", "sponge", "teapot", "torus", "torus_knot", "spot"), ())


def bench_kubasic(out: Path, workers: int) -> dict:
    """A fresh KuBasic build through ``ensure_kubasic`` and then the cached path (what every later
    use costs), with the ratio of the two."""
    from kubric.asset_tools.kubasic import NAME, build_kubasic, ensure_kubasic
    from kubric.assets.asset_source import build_once

    def ensure():
        if KUBASIC_SHAPES is None:
            return ensure_kubasic(cache=out, workers=workers)
        return build_once(out / NAME, lambda tmp: build_kubasic(tmp, workers=workers,
                                                                 shapes=KUBASIC_SHAPES))

    t0 = time.perf_counter()
    ensure()
    built = time.perf_counter() - t0
    t0 = time.perf_counter()
    ensure()
    cached = time.perf_counter() - t0
    return {"kubasic_seconds": round(built, 1), "kubasic_cached_seconds": round(cached, 4),
            "cached_over_build": round(cached / built, 5), "workers": workers}


def bench_full_conversion(out: Path, workers: int, limit: int | None) -> dict:
    from kubric.asset_tools.pybullet_collection import build_pybullet_collection

    t0 = time.perf_counter()
    report = build_pybullet_collection(out / "PybulletObjects", limit=limit, workers=workers,
                                       only=CONVERTED)
    seconds = time.perf_counter() - t0
    manifest = json.loads((out / "PybulletObjects" / "manifest.json").read_text())
    methods: dict[str, int] = {}
    for entry in manifest["assets"].values():
        m = entry["metadata"]["collision_method"]
        methods[m] = methods.get(m, 0) + 1
    return {"seconds": round(seconds, 1), "total": report["total"],
            "converted": report["converted"], "reused": report["reused"],
            "skipped": report["skipped"], "decomposition_methods": methods,
            "workers": workers}


def verify_source(path: Path) -> dict:
    """Load every asset of a source in PyBullet (drop test: comes to rest on a plane) and in
    Blender (glTF/OBJ import; bounds equal the manifest's). Returns failure lists."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from asset_checks import assert_rests_on_floor, blender_import_bounds, drop_test

    from kubric.assets import AssetSource

    source = AssetSource(path)
    failures = {"pybullet": [], "blender": [], "still_rolling_after_10s": []}
    t0 = time.perf_counter()
    for asset_id in source.all_asset_ids:
        obj = source.create(asset_id)
        if obj.static:
            continue
        state = drop_test(obj.simulation_filename, obj.bounds, obj.mass)
        try:
            assert_rests_on_floor(state, obj.mass)
        except AssertionError as err:
            size = state["size"]
            on_floor = -0.02 * size - 0.005 < state["aabb"][0, 2] < 0.05 * size + 0.005
            if on_floor and abs(state["mass"] - obj.mass) <= 1e-5 * obj.mass:
                failures["still_rolling_after_10s"].append(
                    f"{asset_id}: |v| {state['speed']:.4f} m/s, |w| {state['spin']:.3f} rad/s")
            else:
                failures["pybullet"].append(f"{asset_id}: {err}")
        bounds = np.asarray(obj.bounds, dtype=np.float64)
        got = blender_import_bounds(obj.render_filename, dict(obj.render_import_kwargs))
        if not np.allclose(got, bounds, atol=1e-5 + 1e-4 * np.ptp(bounds)):
            failures["blender"].append(f"{asset_id}: {got.tolist()} vs {bounds.tolist()}")
    return {"checked": len(source), "seconds": round(time.perf_counter() - t0, 1), **failures}


def bench_decomposition() -> list[dict]:
    """Time, hull count and Σ hull volume / mesh volume for each non-convex test mesh."""
    from kubric.asset_tools import physics, shapes
    from kubric.asset_tools.converter import load_mesh
    from kubric.asset_tools.pybullet_collection import TEXTURED_MODELS, pybullet_jobs

    meshes = {}
    for job in pybullet_jobs(limit=0):
        if job.asset_id in TEXTURED_MODELS and job.asset_id in (DECOMPOSED_MODELS or TEXTURED_MODELS):
            mesh = load_mesh(job.mesh_path, job.up, job.scale)
            closed, ok = physics.make_watertight(mesh)
            if physics.convex_parts_if_any(closed if ok else mesh) is None:
                meshes[job.asset_id] = (closed if ok else mesh, ok)
    for name in DECOMPOSED_SHAPES:
        m = getattr(shapes, name)()
        meshes[f"kubasic/{name}"] = (m, bool(m.is_watertight))
    try:
        import coacd  # noqa: F401
        methods = {"vhacd": physics.vhacd, "coacd": physics.coacd}
    except ImportError:
        methods = {"vhacd": physics.vhacd}
    rows = []
    for name, (mesh, watertight) in sorted(meshes.items())[:smoke_mode.size(None, 1)]:
        row = {"mesh": name, "faces": len(mesh.faces)}
        for method, fn in methods.items():
            t0 = time.perf_counter()
            hulls = fn(mesh)
            row[f"{method}_s"] = round(time.perf_counter() - t0, 2)
            row[f"{method}_hulls"] = len(hulls)
            if watertight:
                row[f"{method}_vol_ratio"] = round(sum(h.volume for h in hulls) / mesh.volume, 3)
        rows.append(row)
    return rows


def summarize_decomposition(rows: list[dict]) -> dict:
    """Medians over the meshes: seconds, hulls, Σ hull / mesh volume per method, and the
    per-mesh time ratio CoACD / V-HACD (the baseline measured in the same run)."""
    out = {"meshes": len(rows)}
    for method in ("vhacd", "coacd"):
        if f"{method}_s" not in rows[0]:
            continue
        for key in ("s", "hulls", "vol_ratio"):
            vals = [r[f"{method}_{key}"] for r in rows if f"{method}_{key}" in r]
            out[f"median_{method}_{key}"] = round(float(np.median(vals)), 3)
    if "coacd_s" in rows[0]:
        ratios = [r["coacd_s"] / r["vhacd_s"] for r in rows]
        out["coacd_over_vhacd_time"] = {"min": round(min(ratios), 2),
                                        "median": round(float(np.median(ratios)), 2),
                                        "max": round(max(ratios), 2)}
    return out


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None, help="output folder (default: a temp folder)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--limit", type=int, default=smoke_mode.size(None, 0),
                        help="random_urdfs (default all)")
    parser.add_argument("--skip-full", action="store_true", help="skip the full conversion")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out or tmp)
        results = {"kubasic": bench_kubasic(out, args.workers)}
        print(json.dumps(results["kubasic"]))
        if not args.skip_full:
            results["pybullet_data"] = bench_full_conversion(out, args.workers, args.limit)
            print(json.dumps(results["pybullet_data"], indent=1))
            results["verify"] = verify_source(out / "PybulletObjects")
            print(json.dumps(results["verify"], indent=1))
        results["decomposition"] = bench_decomposition()
        for row in results["decomposition"]:
            print(json.dumps(row))
        print(json.dumps(summarize_decomposition(results["decomposition"])))
    return results


if __name__ == "__main__":
    main()
