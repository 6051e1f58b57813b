"""What one MOVi-A scene costs at each render quality, and what the quality is.

For MOVi-A at its defaults (256², 24 frames; seed 3) and each quality profile (``final``, 64 spp
+ OIDN; ``default``, the recipe's calibrated setting; ``fast``, 8 spp with OIDN's FAST prefilter;
``draft``, 4 spp) one whole worker process
(``benchmarks/scene_profile.py``, a fresh interpreter as ``kubric worker``): its CPU seconds (user +
sys, every thread) and peak RSS from ``wait4``, its wall time, and its profile by stage. Quality:
RMSE of the RGB frames 1–4 (8-bit values) against a 1024-spp undenoised reference of the same
frames rendered in the same run — over all pixels (the issue's measure), over object pixels and
over a band of ±2 px around segmentation edges (where a denoiser blurs first). The exact layers of all
profiles are compared byte for byte. The allocator lever (``kubric/renderer/allocator.py``) is
measured as the fast profile with glibc's defaults (``KUBRIC_MALLOC_TUNING=0``), once in the
table and then in ``--allocator-pairs`` more alternating pairs. Then throughput on this machine:
two scenes at the default profile one after the other with all cores each, side by side with all cores each
(oversubscribed: what the process pool does), and side by side with cores // 2 render threads
each (``KUBRIC_RENDER_THREADS``, what Dask's ``--threads-per-scene 1`` does on 2 cores).

Any MOVi recipe with ``--recipe`` (e.g. ``movi_c``: textured objects, HDRI light).

Run: ``.venv/bin/python benchmarks/bench_scene_cost.py [--recipe movi_a] [--seed 3] [--json F]
[--crops docs/img/render_cost_crops.png] [--no-throughput] [--allocator-pairs 3]``. About 14 min
on 2 cores for MOVi-A.
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

import numpy as np
import smoke_mode

from kubric.recipes.render_quality import RULE_FACTOR

HERE = pathlib.Path(__file__).resolve().parent
PROFILER = HERE / "scene_profile.py"
#: (key, quality profile, label, extra environment): the last row is the fast profile again with
#: glibc's allocator defaults (kubric/renderer/allocator.py off), that lever's A/B.
PROFILES = (("final", "final", "final (64 spp)", {}), ("default", "default", "default", {}),
            ("fast", "fast", "fast", {}), ("draft", "draft", "draft", {}),
            ("fast_plain_malloc", "fast", "fast, glibc malloc defaults",
             {"KUBRIC_MALLOC_TUNING": "0"}))
EXACT = ("depth", "segmentation", "forward_flow", "backward_flow", "normal",
         "object_coordinates", "uv")
TARGET_RMSE = 1.07  # upstream Kubric's MOVi-A RMSE level (the fast profile's quality target)
FAST_CPU = 23.0  # the fast profile's target: upstream's RMSE level at ≤ 23 CPU-s per scene


def run_child(args: list[str], env=None) -> dict:
    """Run scene_profile.py in a fresh process → {cpu, wall, rss_mib, profile}."""
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        profile_path = f.name
    cmd = [sys.executable, str(PROFILER), *args[:-1], profile_path, *args[-1]]
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=HERE.parent, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    err = proc.stderr.read()
    proc.stderr.close()
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{err[-2000:]}")
    profile = json.loads(pathlib.Path(profile_path).read_text())
    os.unlink(profile_path)
    return {"cpu": usage.ru_utime + usage.ru_stime, "wall": wall,
            "rss_mib": usage.ru_maxrss / 1024, "profile": profile}


def scene_dir(root: pathlib.Path) -> pathlib.Path:
    found = sorted(root.glob("scene_*"))
    if len(found) != 1:
        raise SystemExit(f"expected one scene in {root}, found {found}")
    return found[0]


def read_frames(directory: pathlib.Path, prefix: str, count: int) -> np.ndarray:
    from PIL import Image
    return np.stack([np.asarray(Image.open(directory / f"{prefix}_{i:05d}.png"))
                     for i in range(count)])


def edge_band(seg: np.ndarray, width: int = 1) -> np.ndarray:
    """Pixels within ``width`` px of a label change (per frame), 4-neighbourhood."""
    from scipy import ndimage
    band = np.zeros(seg.shape, bool)
    for t, s in enumerate(seg):
        e = np.zeros(s.shape, bool)
        dy, dx = s[:-1] != s[1:], s[:, :-1] != s[:, 1:]
        e[:-1] |= dy
        e[1:] |= dy
        e[:, :-1] |= dx
        e[:, 1:] |= dx
        band[t] = ndimage.binary_dilation(e, iterations=width)
    return band


def rmse(img: np.ndarray, ref: np.ndarray, mask=None) -> float:
    d2 = ((img.astype(np.float64) - ref.astype(np.float64)) ** 2).mean(-1)
    return float(np.sqrt(d2[mask].mean() if mask is not None else d2.mean()))


def exact_files(directory: pathlib.Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())
            if p.name.split("_0")[0] in EXACT or p.name == "data_ranges.json"}


def save_crops(path: pathlib.Path, images: list[tuple[str, np.ndarray]], worst: np.ndarray
               ) -> None:
    """Side-by-side crops of frame 1 (64 px, 3× nearest-neighbour) where the RGB of ``worst``
    (frames, H, W, 3) is farthest from the reference (the first image): the honest close-up."""
    from PIL import Image, ImageDraw
    from scipy import ndimage
    half = 32
    err = ((worst[0].astype(np.float64) - images[0][1][0].astype(np.float64)) ** 2).mean(-1)
    window = ndimage.uniform_filter(err, size=2 * half, mode="constant")
    h, w = err.shape
    window[:half, :] = window[h - half:, :] = window[:, :half] = window[:, w - half:] = -1
    cy, cx = np.unravel_index(np.argmax(window), window.shape) if h > 2 * half and \
        w > 2 * half else (h // 2, w // 2)
    y0, x0 = max(0, min(cy - half, h - 2 * half)), max(0, min(cx - half, w - 2 * half))
    scale, pad = 3, 18
    tiles = []
    for title, img in images:
        crop = Image.fromarray(np.ascontiguousarray(img[0, y0:y0 + 2 * half, x0:x0 + 2 * half, :3]))
        tile = Image.new("RGB", (crop.width * scale, crop.height * scale + pad), "white")
        tile.paste(crop.resize((crop.width * scale, crop.height * scale), Image.NEAREST), (0, pad))
        ImageDraw.Draw(tile).text((4, 3), title, fill="black")
        tiles.append(tile)
    sheet = Image.new("RGB", (sum(t.width for t in tiles) + 4 * (len(tiles) - 1), tiles[0].height),
                      "white")
    x = 0
    for t in tiles:
        sheet.paste(t, (x, 0))
        x += t.width + 4
    path.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(path)
    print(f"crops (frame 1, rows {y0}-{y0 + 2 * half}, columns {x0}-{x0 + 2 * half}) → {path}")


def throughput(work: pathlib.Path, recipe: str = "movi_a", seeds=(4, 4),
               assignments: list[str] = ()) -> dict:
    """Wall seconds for len(seeds) default scenes (fresh ``kubric worker`` processes): one after
    the other with all cores each; side by side with all cores each (oversubscribed: the process
    pool); side by side with cores // scenes threads each (one Dask slot per core). The same
    seed twice by default: side by side, two different scenes would leave a core idle once the
    shorter one ends, which a long run's pool does not. ``assignments``: recipe options
    (``key=value``, as ``--set``)."""
    def workers(tag, threads, parallel):
        env = dict(os.environ)
        env.pop("KUBRIC_RENDER_THREADS", None)
        if threads:
            env["KUBRIC_RENDER_THREADS"] = str(threads)
        start = time.perf_counter()
        procs = []
        for k, s in enumerate(seeds):
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "kubric", "worker", recipe, "--seed", str(s), "--out",
                 str(work / f"{tag}_{k}"), *[a for o in assignments for a in ("--set", o)]],
                cwd=HERE.parent, env=env,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            if not parallel and procs[-1].wait():
                raise SystemExit(f"throughput worker {tag} seed {s} failed")
        if any(p.wait() for p in procs):
            raise SystemExit(f"a throughput worker ({tag}) failed")
        return time.perf_counter() - start

    cores = len(os.sched_getaffinity(0))
    return {"scenes": len(seeds), "cores": cores,
            "sequential_wall": workers("seq", None, False),
            "oversubscribed_wall": workers("over", None, True),
            "parallel_wall": workers("par", max(1, cores // len(seeds)), True)}


def print_throughput(t: dict) -> None:
    print(f"throughput, {t['scenes']} default scenes on {t['cores']} cores (wall s): one after "
          f"the other, all threads each {t['sequential_wall']:.1f}; side by side, all threads "
          f"each (oversubscribed) {t['oversubscribed_wall']:.1f}; side by side, "
          f"{max(1, t['cores'] // t['scenes'])} thread(s) each {t['parallel_wall']:.1f} → "
          f"{t['sequential_wall'] / t['parallel_wall']:.2f}× and "
          f"{t['oversubscribed_wall'] / t['parallel_wall']:.2f}× the scenes per hour")


def allocator_pairs(work: pathlib.Path, recipe: str, seed: int, pairs: int,
                    assignments: list[str]) -> list[dict]:
    """The allocator lever's A/B: the fast profile ``pairs`` times with kubric's mallopt tuning
    and with glibc's defaults, alternating (so that drift of the machine hits both alike)."""
    rows = []
    for i in range(pairs):
        row = {}
        for key, tuning in (("tuned", "1"), ("plain", "0")):
            run = run_child([recipe, str(seed), str(work / f"alloc_{key}_{i}"),
                             ["quality=fast", *assignments]],
                            env={**os.environ, "KUBRIC_MALLOC_TUNING": tuning})
            row[key] = {"cpu": run["cpu"], "rss_mib": run["rss_mib"]}
        rows.append(row)
        print(f"  pair {i + 1}: tuned {row['tuned']['cpu']:.1f} CPU-s, glibc defaults "
              f"{row['plain']['cpu']:.1f} CPU-s", flush=True)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--recipe", default="movi_a", help="any MOVi recipe (default movi_a)")
    parser.add_argument("--reference-samples", type=int, default=smoke_mode.size(1024, 4))
    parser.add_argument("--json", type=pathlib.Path, help="also write the numbers here")
    parser.add_argument("--crops", type=pathlib.Path, help="write a crop comparison PNG here")
    parser.add_argument("--no-throughput", action="store_true")
    parser.add_argument("--allocator-pairs", type=int, default=smoke_mode.size(3, 1), metavar="N",
                        help="extra alternating runs of the fast profile with and without the "
                             "allocator tuning (its A/B; default 3 pairs, 0 to skip)")
    parser.add_argument("--throughput-only", action="store_true")
    parser.add_argument("--set", action="append", metavar="KEY=VALUE",
                        default=smoke_mode.size([], ["resolution=16", "frame_end=4"]),
                        help="extra recipe options for every run (smoke runs: resolution=64)")
    args = parser.parse_args(argv)
    os.environ.setdefault("KUBRIC_CACHE_DIR", str(HERE.parent / ".cache" / "kubric"))
    frames = 4
    results: dict = {"seed": args.seed, "profiles": {}}
    if args.throughput_only:
        with tempfile.TemporaryDirectory(prefix="bench_scene_cost_") as tmp:
            t = throughput(pathlib.Path(tmp), args.recipe, assignments=args.set)
        print_throughput(t)
        return 0
    with tempfile.TemporaryDirectory(prefix="bench_scene_cost_") as tmp:
        work = pathlib.Path(tmp)
        print(f"reference: {args.reference_samples} spp, no denoising, frames 1-{frames} of "
              f"{args.recipe} seed {args.seed} ...", flush=True)
        ref_run = run_child(["--reference", f"1-{frames}", args.recipe, str(args.seed),
                             str(work / "ref"), [f"samples={args.reference_samples}",
                                                 "denoise=false", "quality=final", *args.set]])
        ref = np.load(work / "ref" / "reference.npy")[..., :3]
        print(f"  {ref_run['cpu']:.0f} CPU-s", flush=True)
        exact, images, seg = {}, [(f"{args.reference_samples} spp reference", ref)], None
        rgb_of: dict = {}
        for key, quality, label, env in PROFILES:
            run = run_child([args.recipe, str(args.seed), str(work / key),
                             [f"quality={quality}", *args.set]], env={**os.environ, **env})
            scene = scene_dir(work / key)
            rgb = read_frames(scene, "rgba", frames)[..., :3]
            if seg is None:
                seg = read_frames(scene, "segmentation", frames)
                seg = seg[..., 0] if seg.ndim == 4 else seg
            if not env:
                images.append((label, rgb))
            rgb_of[key] = rgb
            meta = json.loads((scene / "metadata.json").read_text())["metadata"]["renderer"]
            exact[key] = exact_files(scene)
            results["profiles"][key] = {
                "label": label, "samples": meta["samples_per_pixel"],
                "denoiser": f"{meta['denoising_quality']}/{meta['denoising_prefilter']}"
                if meta["denoising"] else "off",
                "cpu": run["cpu"], "wall": run["wall"], "rss_mib": run["rss_mib"],
                "rmse": rmse(rgb, ref), "rmse_objects": rmse(rgb, ref, seg > 0),
                "rmse_edges": rmse(rgb, ref, edge_band(seg)),
                "stages": run["profile"]["stages"]}
            print(f"  {label}: {run['cpu']:.1f} CPU-s", flush=True)
        identical = all(exact[q] == exact["final"] for q in exact)
        results["allocator_rgb_identical"] = bool(np.array_equal(rgb_of["fast"],
                                                                 rgb_of["fast_plain_malloc"]))
        results["exact_layers_identical"] = identical
        results["exact_files"] = len(exact["final"])
        if args.allocator_pairs:
            print(f"allocator A/B: fast profile, {args.allocator_pairs} alternating pairs ...",
                  flush=True)
            results["allocator_pairs"] = allocator_pairs(work, args.recipe, args.seed,
                                                         args.allocator_pairs, args.set)
        if args.crops:
            save_crops(args.crops, images, dict(images)["default"])
        if not args.no_throughput:
            print("throughput: 2 default scenes, sequential vs side by side ...", flush=True)
            results["throughput"] = throughput(work, args.recipe, assignments=args.set)

    p = results["profiles"]
    old = p["final"]
    shown = ", ".join(args.set) if args.set else "defaults"
    print(f"\n{args.recipe} seed {args.seed} ({shown}); RMSE of frames 1-{frames} (8-bit RGB) vs "
          f"{args.reference_samples}-spp undenoised reference ({ref_run['cpu']:.0f} CPU-s)")
    print(f"{'profile':28s} {'spp':>4s} {'denoiser':>16s} {'CPU-s':>7s} {'× 64':>6s} "
          f"{'wall s':>7s} {'peak RSS':>9s} {'RMSE':>6s} {'objects':>8s} {'edges':>6s}")
    for q in p.values():
        print(f"{q['label']:28s} {q['samples']:4d} {q['denoiser']:>16s} {q['cpu']:7.1f} "
              f"{q['cpu'] / old['cpu']:6.2f} {q['wall']:7.1f} {q['rss_mib']:5.0f} MiB "
              f"{q['rmse']:6.3f} {q['rmse_objects']:8.3f} {q['rmse_edges']:6.3f}")
    new = p["default"]
    shown_keys = [key for key, _, _, env in PROFILES if not env]
    print("\nprofile by stage (CPU-s):\n  " + " " * 42
          + "".join(f"{p[key]['label'].split(' (')[0]:>10s}" for key in shown_keys))
    for stage in new["stages"]:
        print(f"  {stage:42s}" + "".join(f"{p[key]['stages'].get(stage, [0])[0]:10.2f}"
                                         for key in shown_keys))
    print(f"\nexact layers ({results['exact_files']} files) byte-identical across profiles: "
          f"{identical}")
    ratios = {m: new[m] / old[m] for m in ("rmse", "rmse_objects", "rmse_edges")}
    print(f"default vs 64 spp: {new['cpu']:.1f} CPU-s ({new['cpu'] / old['cpu']:.2f}×); RMSE "
          f"ratios all {ratios['rmse']:.2f}, objects {ratios['rmse_objects']:.2f}, edges "
          f"{ratios['rmse_edges']:.2f} (the calibration rule allows {RULE_FACTOR}); peak RSS "
          f"{new['rss_mib']:.0f} MiB")
    fast = p.get("fast")
    if args.recipe == "movi_a" and fast:
        print(f"fast profile: {fast['cpu']:.1f} CPU-s ≤ {FAST_CPU} "
              f"({'met' if fast['cpu'] <= FAST_CPU else 'NOT met'}) at RMSE {fast['rmse']:.3f} ≤ "
              f"{TARGET_RMSE} ({'met' if fast['rmse'] <= TARGET_RMSE else 'NOT met'}); "
              f"{old['cpu'] / fast['cpu']:.2f}× cheaper than 64 spp, "
              f"{new['cpu'] / fast['cpu']:.2f}× cheaper than default")
    plain = p["fast_plain_malloc"]
    print(f"allocator lever (fast profile): {fast['cpu']:.1f} CPU-s, peak RSS "
          f"{fast['rss_mib']:.0f} MiB with kubric's mallopt thresholds vs {plain['cpu']:.1f} CPU-s, "
          f"{plain['rss_mib']:.0f} MiB with glibc's defaults ({plain['cpu'] / fast['cpu']:.3f}×); "
          f"RGB identical: {results['allocator_rgb_identical']}")
    if results.get("allocator_pairs"):
        rows = [{"tuned": fast, "plain": plain}, *results["allocator_pairs"]]
        mean = {k: float(np.mean([r[k]["cpu"] for r in rows])) for k in ("tuned", "plain")}
        rss = {k: float(np.mean([r[k]["rss_mib"] for r in rows])) for k in ("tuned", "plain")}
        wins = sum(r["tuned"]["cpu"] < r["plain"]["cpu"] for r in rows)
        print(f"allocator lever over {len(rows)} pairs: tuned {mean['tuned']:.1f} CPU-s, glibc "
              f"defaults {mean['plain']:.1f} CPU-s (mean; {mean['plain'] / mean['tuned']:.3f}×), "
              f"tuned cheaper in {wins} of {len(rows)} pairs; peak RSS {rss['tuned']:.0f} vs "
              f"{rss['plain']:.0f} MiB")
    if results.get("throughput"):
        print_throughput(results["throughput"])
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0 if identical else 1


if __name__ == "__main__":
    raise SystemExit(main())
