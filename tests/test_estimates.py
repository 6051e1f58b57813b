"""Time estimates before long work and a bar for long renders (issue 40, item 5).

* The cost table is the calibration's measurement (docs/data/render-calibration.json, recomputed
  here as the mean over seeds of each quality's setting).
* A whole MOVi-A scene's estimate agrees with the separate whole-scene measurement in
  docs/render-cost.md (bench_scene_cost: CPU-s per scene under each profile) within 15 %.
* `kubric generate` prints the estimate before the first scene; a Python-API render shows a bar
  over its frames once it runs for a while; `kubric worker` does not (its output is a log).
"""

import json
import os
import pathlib
import re
import subprocess
import sys
from collections import defaultdict

import pytest

from kubric.pipeline.estimate import RGB_CPU_PER_FRAME, estimate_line, scene_cpu
from kubric.pipeline.recipe import get_recipe
from kubric.pipeline.runner import LocalRunner
from kubric.recipes.render_quality import CALIBRATED_DEFAULTS, PROFILES

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_the_table_is_the_calibration_measurement():
    data = json.loads((ROOT / "docs" / "data" / "render-calibration.json").read_text())
    cpu, size = defaultdict(list), {}
    for scene in data["scenes"]:
        size[scene["recipe"]] = tuple(scene["resolution"])
        for label, row in scene["settings"].items():
            cpu[scene["recipe"], label].append(row["cpu"])
    assert set(RGB_CPU_PER_FRAME) == set(size)
    for recipe, (resolution, costs) in RGB_CPU_PER_FRAME.items():
        assert resolution == size[recipe]
        labels = {q: PROFILES[q].label for q in ("draft", "fast", "final")}
        labels["default"] = CALIBRATED_DEFAULTS[recipe].label
        for quality, label in labels.items():
            values = cpu[recipe, label]
            assert costs[quality] == pytest.approx(sum(values) / len(values), abs=0.006), \
                (recipe, quality)


def measured_scene_cpu() -> dict[str, float]:
    """bench_scene_cost's CPU-s per MOVi-A scene (256², 24 frames) by profile, from the docs."""
    text = (ROOT / "docs" / "render-cost.md").read_text()
    section = text.split("## The fast profile and the levers behind it", 1)[1]
    out = {}
    for name in ("final", "default", "fast", "draft"):
        row = re.search(rf"^\| (?:\*\*)?`{name}`(?:\*\*)?(?: \(MOVi-A's\))? \| [^|]+ \| "
                        rf"(?:\*\*)?([\d.]+)", section, re.M)
        out[name] = float(row.group(1))
    return out


def test_a_movi_a_scene_estimate_agrees_with_the_whole_scene_measurement():
    measured = measured_scene_cpu()
    values = get_recipe("movi_a")().values  # 256², 24 frames: bench_scene_cost's scene
    for quality, cpu in measured.items():
        assert scene_cpu("movi_a", values, quality) == pytest.approx(cpu, rel=0.15), quality


def test_the_estimate_line_scales_and_suggests_fast():
    runner = LocalRunner("movi_a", "unused", range(100), ["resolution=128"], progress=False)
    line = runner.estimate(100)
    per_scene = scene_cpu("movi_a", get_recipe("movi_a").from_assignments(
        ["resolution=128"]).values)
    # 128² is a quarter of the measured 256² pixels: the render share scales by 1/4
    full = scene_cpu("movi_a", get_recipe("movi_a")().values)
    assert per_scene < full / 3
    assert line.startswith("estimate: ~") and "100 movi_a scenes" in line
    assert "128x128, 24 frames, quality=default" in line and "docs/render-cost.md" in line
    assert "--set quality=fast" in line
    fast = estimate_line("movi_a", get_recipe("movi_a").from_assignments(
        ["resolution=128", "quality=fast"]).values, 100, runner.cores())
    assert "quality=fast" in fast and "to explore" not in fast
    spp = get_recipe("movi_a").from_assignments(["samples=16"]).values  # 16/64 of final's cost
    assert "24 frames, samples=16;" in estimate_line("movi_a", spp, 1, 2)
    assert scene_cpu("movi_a", spp) == pytest.approx(
        0.5 + (RGB_CPU_PER_FRAME["movi_a"][1]["final"] * 16 / 64 + 0.1) * 24)
    raycast = get_recipe("movi_a").from_assignments(["renderer=raycast"]).values
    assert estimate_line("movi_a", raycast, 100, 2) is None  # not measured: nothing said


@pytest.mark.blender
def test_generate_prints_the_estimate_before_rendering(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "kubric", "generate", "movi_a", "--out",
                           str(tmp_path / "s"), "--scenes", "1", "--set", "resolution=32",
                           "--set", "frame_end=2", "--set", "quality=draft"], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("estimate: ~") and "1 movi_a scene (" in lines[0]
    assert lines[-1].startswith("1 generated")
    log = (tmp_path / "s" / "logs" / "scene_00000000.log").read_text()
    assert "Blender RGB" not in log  # no frame bar in a worker's log


RENDER = """
import kubric as kb
scene = kb.Scene(resolution=(48, 48), frame_start=1, frame_end=3)
renderer = kb.renderer.Blender(scene, samples_per_pixel=4)
scene += kb.Cube(name="floor", scale=(10, 10, 0.1), position=(0, 0, -0.1))
scene += kb.Sphere(name="ball", scale=1, position=(0, 0, 1.0))
scene += kb.DirectionalLight(name="sun", position=(-1, -0.5, 3), look_at=(0, 0, 0))
scene += kb.PerspectiveCamera(name="camera", position=(3, -1, 4), look_at=(0, 0, 1))
print("rendered", renderer.render()["rgba"].shape)
"""


@pytest.mark.blender
def test_a_python_api_render_shows_a_frame_bar(tmp_path):
    def run(**env):
        return subprocess.run([sys.executable, "-c", RENDER], cwd=tmp_path, capture_output=True,
                              text=True, timeout=300, env=dict(os.environ, **env))
    shown = run(KUBRIC_RENDER_PROGRESS_DELAY="0")  # a long render's bar, at once
    assert shown.returncode == 0 and "rendered (3, 48, 48, 4)" in shown.stdout, shown.stderr
    assert "Blender RGB" in shown.stderr and "3/3" in shown.stderr
    assert "Blender exact layers" in shown.stderr
    quiet = run(KUBRIC_RENDER_PROGRESS_DELAY="0", KUBRIC_RENDER_PROGRESS="0")
    assert quiet.returncode == 0 and "Blender RGB" not in quiet.stderr
    short = run(KUBRIC_RENDER_PROGRESS_DELAY="600")  # a render shorter than the delay: silent
    assert short.returncode == 0 and "Blender RGB" not in short.stderr
