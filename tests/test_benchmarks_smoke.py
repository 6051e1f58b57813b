"""Every benchmark's entry point runs to its end at tiny size (``KUBRIC_BENCH_SMOKE=1``,
benchmarks/smoke_mode.py): exit 0, its result rows printed, and ``docs/`` untouched.

Each benchmark runs as ``make bench`` runs it (``python benchmarks/bench_x.py`` from the repository
root, a fresh process). A benchmark that needs a package of an extra the test environment lacks is
skipped with the package named. The numbers of a smoke run mean nothing; only that every code
path of the benchmark still runs (a refactor once broke ``bench_scale``'s pack section unnoticed).
"""

import hashlib
import importlib.util
import os
import pathlib
import re
import signal
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"

#: benchmark → regular expressions its output must match (its result rows; re.MULTILINE)
ROWS = {
    "bench_assets": [r'^\{"kubasic_seconds": [\d.]+', r'^\{"mesh": ".+", "faces": \d+, "vhacd_s"',
                     r'^\{"meshes": 1, "median_vhacd_s"'],
    "bench_characters": [r"^render \(RGB \+ layers\)\s+: +[\d.]+ CPU-s",
                         r"^characters' extra cost / render: [\d.]+%"],
    "bench_cloth_engines": [r"^\| pybullet \| (yes|no) \| [\d.]+ \| -?[\d.]+ \| [\d.]+ \| yes \|"],
    "bench_codecs": [r"^32² .+\n  codec +enc ms", r"^  handwritten +[\d.]+ +[\d.]+ +\d+ +yes"],
    "bench_datasets": [r"^pack, 2 worker\(s\): [\d.]+ s", r"^read, random order, video only: "
                       r"dataset [\d.]+ examples/s"],
    "bench_deformables": [r"^cloth simulation \(extra\) +: +[\d.]+ CPU-s",
                          r"^cloth simulation / render : [\d.]+% \(goal ≤ 25%\)"],
    "bench_events": [r"^\| frames \(event_subframes=0\) \| \d+ \| [\d.]+ \| [\d.]+ \|",
                     r"^\| flow K=2 \| \d+ \| [\d.]+ \| [\d.]+ \|"],
    "bench_extra_layers": [r"^\| extra_layers \| CPU-s \| × default scene \|",
                           r"^\| raw bits \(T·N·H·W / 8\) \| \d+ \| — \|"],
    "bench_file_io": [r"^handwritten : \d+ files, [\d.]+ MB", r"^kubric      : \d+ files, [\d.]+ MB"],
    "bench_hub": [r"^hf +4 +[\d.]+ +\d+ +-?[\d.]+$", r"^webdataset +4 +[\d.]+",
                  r"^webdataset: added peak"],
    "bench_import": [r'^\{"import_numpy_s": [\d.]+, "import_kubric_s": [\d.]+'],
    "bench_lens": [r"^  pinhole +[\d.]+ CPU-s/frame \(1\.00× pinhole;"],
    "bench_multiview": [r"^baseline movi_a .+: [\d.]+ s", r"^toybox +\d+ +[\d.]+ +[\d.]+"],
    "bench_pack_signals": [r'^\{"workers": 2, "signal": "SIGINT", "runs": 1, .*"guarantees_held": '
                           r"true\}"],
    "bench_placement": [r'^\{"rule": "upstream", "shape_half_size_m": 1\.0, .*"seconds": '],
    "bench_quality_calibration": [r"^tables → .+render-cost\.md; rows → .+render-calibration\.json"],
    "bench_quality_levers": [r"^\| ≤64 spp adaptive 0\.1 \+ OIDN HIGH/ACCURATE, guiding surface \| "
                             r"[\d.]+ \| [\d.]+", r"^rows → .+render-levers\.json",
                             r"^tables → .+render-cost\.md"],
    "bench_raycast": [r"^raycast exact layers: [\d.]+ s/frame",
                      r"^ratio Cycles / raycast \(exact layers\): wall [\d.]+×"],
    "bench_render": [r"^RGB +: +[\d.]+ CPU-s/frame", r"^total per frame: [\d.]+ CPU-s"],
    "bench_render_levers": [r"^4 spp \+ OIDN BALANCED/FAST \(draft\) +[\d.]+ +[\d.]+ +[\d.]+"],
    "bench_scale": [r"^\| stdlib \| dask-plain \| 10 \|", r"^\| s3 \| 10 \| [\d.]+ \| [\d.]+ \|",
                    r"^\| s3-warm \| \d+ \|"],
    "bench_scaling": [r"^dask, 2 worker\(s\): 2 MOVi-A scenes in", r"^scheduler \+ worker round trip"],
    "bench_scene_cost": [r"^default vs 64 spp: [\d.]+ CPU-s", r"^allocator lever over 2 pairs",
                         r"^throughput, 2 default scenes on \d+ cores"],
    "bench_shadows": [r'^\{"size": 32, "samples": 1, "cpu_s_per_frame": '],
    "bench_signals": [r'^\{"target": "runner", "signal": "SIGKILL", "runs": 1, .*"guarantees_held": '
                      r"true\}"],
    "bench_stereo": [r"^  mono +[\d.]+ CPU-s/scene", r"^  stereo +[\d.]+ CPU-s/scene \([\d.]+× mono"],
    "bench_simulator": [r"^ +2 +240 +[\d.]+ +[\d.]+ +[\d.]+ +[\d.]+ +\d+ +\d+$"],
    "bench_temporal_accumulation": [
        r"^\| 1 spp, 2 frames along the flow, changes > 3 levels rejected \| [\d.]+ \| [\d.]+",
        r"^\| movi_a \| 1 spp \+ OIDN \(denoised outside Cycles\) \| [\d.]+% / \d+% / ",
        r"^tables → .+render-cost\.md"],
    "bench_tracks": [r"^16 tracks +: +[\d.]+ CPU-s", r"^ratio tracks / render"],
    "bench_viewer": [r"^scene list  HTTP cold", r"^pixel probe \(cold frames\) median"],
}
#: benchmark → modules it cannot run without (from the `bench`, `cluster`, `s3` extras)
NEEDS = {"bench_codecs": ("tifffile", "cv2"), "bench_scale": ("distributed", "s3fs", "moto"),
         "bench_scaling": ("distributed",)}
#: benchmarks that render or import with bpy
BLENDER = {"bench_assets", "bench_characters", "bench_cloth_engines", "bench_datasets",
           "bench_deformables", "bench_lens", "bench_multiview",
           "bench_quality_calibration", "bench_quality_levers", "bench_raycast", "bench_render",
           "bench_render_levers",
           "bench_scaling", "bench_scene_cost", "bench_shadows", "bench_signals", "bench_stereo",
           "bench_temporal_accumulation", "bench_tracks", "bench_viewer"}


def docs_state() -> dict[str, str]:
    """{path under docs/: sha256 of its bytes} for every file of the docs tree."""
    return {str(p.relative_to(ROOT)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted((ROOT / "docs").rglob("*")) if p.is_file()}


def test_every_benchmark_has_a_smoke_run():
    found = {p.stem for p in BENCHMARKS.glob("bench_*.py")}
    assert found == set(ROWS), f"benchmarks without a smoke entry: {sorted(found - set(ROWS))}; " \
        f"entries without a benchmark: {sorted(set(ROWS) - found)}"


def test_smoke_mode_rejects_a_bad_value():
    env = dict(os.environ, KUBRIC_BENCH_SMOKE="yes")
    proc = subprocess.run([sys.executable, str(BENCHMARKS / "bench_import.py")], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0
    assert "KUBRIC_BENCH_SMOKE='yes': allowed values are '', '0' and '1'" in proc.stderr


@pytest.mark.slow
@pytest.mark.parametrize("name", [
    pytest.param(n, marks=[pytest.mark.blender] if n in BLENDER else []) for n in sorted(ROWS)])
def test_benchmark_smoke_run(name):
    missing = [m for m in NEEDS.get(name, ()) if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"{name} needs {missing} (pip install -e '.[bench,cluster,s3]')")
    before = docs_state()
    env = dict(os.environ, KUBRIC_BENCH_SMOKE="1")
    proc = subprocess.Popen([sys.executable, str(BENCHMARKS / f"{name}.py")], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # its own group: killed whole on a hang
    try:
        stdout, stderr = proc.communicate(timeout=300)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        stdout, stderr = proc.communicate()
        pytest.fail(f"{name} ran over 300 s:\n{(stdout + stderr)[-4000:]}")
    assert proc.returncode == 0, f"{name} exited {proc.returncode}:\n{(stdout + stderr)[-4000:]}"
    for pattern in ROWS[name]:
        assert re.search(pattern, stdout, re.MULTILINE), \
            f"{name} printed no row matching {pattern!r}:\n{stdout[-4000:]}"
    assert docs_state() == before, f"{name} changed docs/ in a smoke run"
