"""Upstream-style worker script helpers: kb.ArgumentParser, kb.setup, kb.done."""

import numpy as np
import pytest

import kubric as kb
from kubric.utils import parse_resolution


def test_argument_parser_defaults_and_resolution():
    parser = kb.ArgumentParser()
    parser.set_defaults(frame_end=12, resolution=256)
    flags = parser.parse_args([])
    assert flags.resolution == (256, 256) and flags.frame_end == 12 and flags.seed is None
    flags = parser.parse_args(["--resolution", "320x240", "--seed", "0", "--job-dir", "x"])
    assert flags.resolution == (320, 240) and flags.seed == 0 and flags.job_dir == "x"
    with pytest.raises(SystemExit):
        parser.parse_args(["--resolution", "-3"])
    with pytest.raises(SystemExit):
        parser.parse_args(["--resolution", "12x"])


@pytest.mark.parametrize("value, expected", [
    (256, (256, 256)), (np.int64(64), (64, 64)), (32.0, (32, 32)), ("48", (48, 48)),
    (" 48 ", (48, 48)), ("320x240", (320, 240)), ("320X240", (320, 240)),
    ("320×240", (320, 240)), ("320,240", (320, 240)), ("320 x 240", (320, 240)),
    ("320, 240", (320, 240)), ((320, 240), (320, 240)), ([320, 240], (320, 240)),
    (np.array([320.0, 240.0]), (320, 240)), ((np.uint16(3), 2), (3, 2)),
])
def test_every_resolution_spelling_parses_the_same_everywhere(value, expected):
    """One parser: the function, the worker flags, Scene, Scene.from_flags and recipe options."""
    from types import SimpleNamespace

    from kubric.pipeline import resolution as option_resolution
    got = parse_resolution(value)
    assert got == expected and all(type(v) is int for v in got)
    assert kb.Scene(resolution=value).resolution == expected
    flags = SimpleNamespace(frame_start=1, frame_end=2, frame_rate=24, step_rate=240,
                            resolution=value)
    assert kb.Scene.from_flags(flags).resolution == expected
    assert option_resolution(value) == expected
    if isinstance(value, str):
        assert kb.ArgumentParser().parse_args(["--resolution", value]).resolution == expected


@pytest.mark.parametrize("value", [
    0, -3, 2.5, True, float("nan"), float("inf"), "", " ", "x", "12x", "x12", "1x2x3", "0x5",
    "-3", "+3", "3.5x2", "big", "320;240", "３２０", (1,), (1, 2, 3), (0, 5), (True, 2),
    ("320", "240"), None, {"w": 1},
])
def test_bad_resolutions_raise_one_line_naming_value_and_spellings(value):
    with pytest.raises(ValueError) as err:
        parse_resolution(value)
    message = str(err.value)
    assert "\n" not in message and repr(value) in message
    assert message.startswith("resolution must be N or WxH with positive integers (e.g. 256, "
                              "320x240, 320,240 or (320, 240))")
    with pytest.raises(ValueError, match=r"^Scene.resolution must be N or WxH"):
        kb.Scene(resolution=value)


def test_setup_seed_zero_is_zero_and_done_marks_output(tmp_path):
    parser = kb.ArgumentParser()
    flags = parser.parse_args(["--seed", "0", "--job-dir", str(tmp_path / "out"),
                               "--scratch_dir", str(tmp_path / "scratch"), "--resolution", "32",
                               "--frame_rate", "12"])
    scene, rng, output_dir, scratch_dir = kb.setup(flags)
    assert flags.seed == 0 and scene.metadata["seed"] == 0
    assert rng.randint(1 << 30) == np.random.RandomState(0).randint(1 << 30)
    assert scene.resolution == (32, 32) and scene.frame_rate == 12 and scene.frame_end == 24
    assert output_dir.is_dir() and scratch_dir.is_dir()
    assert not (output_dir / "_SUCCESS").exists()
    marker = kb.done()
    assert marker == output_dir / "_SUCCESS" and marker.exists()


def test_setup_without_seed_records_drawn_seed(tmp_path):
    flags = kb.ArgumentParser().parse_args(["--job-dir", str(tmp_path)])
    scene, rng, _, _ = kb.setup(flags)
    assert isinstance(flags.seed, int) and scene.metadata["seed"] == flags.seed
    assert rng.rand() == np.random.RandomState(flags.seed).rand()


@pytest.mark.blender
def test_upstream_style_script_runs_unchanged(tmp_path):
    import json
    import pathlib
    import subprocess
    import sys

    from kubric.asset_tools import ensure_kubasic
    root = pathlib.Path(__file__).resolve().parents[1]
    kubasic = ensure_kubasic().manifest_path
    out = tmp_path / "job"
    proc = subprocess.run([sys.executable, str(root / "tests" / "upstream_style_worker.py"),
                           "--seed", "0", "--job-dir", str(out), "--kubasic_assets",
                           str(kubasic)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    meta = json.loads((out / "metadata.json").read_text())
    assert meta["flags"]["seed"] == 0 and meta["metadata"]["seed"] == 0  # 0 stays 0
    assert meta["metadata"]["resolution"] == [32, 32] and meta["metadata"]["num_frames"] == 3
    assert 1 <= meta["metadata"]["num_instances"] == len(meta["instances"]) <= 2
    assert len(list(out.glob("rgba_*.png"))) == 3 and (out / "_SUCCESS").exists()
    assert "collisions" in json.loads((out / "events.json").read_text())
