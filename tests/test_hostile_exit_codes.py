"""Round three (issue 41): one exit-status table for every command (docs/exit-codes.md) — the
same situation gives the same status everywhere: no complete scene 1, a refused output 2, a
bad option 2, a busy (locked) output 3 — and ``datasets info`` fails on damage it used to miss.
Each case runs the real ``kubric`` command in a subprocess and expects one line on stderr."""

import json
import pathlib
import re

import pytest
from hostile_fixtures import kubric, make_scenes

from kubric.errors import InputError, KubricError, UsageError
from kubric.io.output_lock import OutputBusy, OutputLock
from kubric.pipeline.runner import LOCK_FILE

ROOT = pathlib.Path(__file__).resolve().parents[1]
FAKE = f"{ROOT / 'tests' / 'fake_recipes.py'}:Fake"


def one_line(proc, code, *words):
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == code, (proc.returncode, proc.stderr[-2000:])
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert lines[0].startswith("kubric "), lines[0]
    for word in words:
        assert word in lines[0], lines[0]


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    return make_scenes(tmp_path_factory.mktemp("codes") / "scenes", 3)


def test_no_complete_scene_is_1_in_every_command(tmp_path):
    empty = tmp_path / "empty"
    (empty / "scene_00000001").mkdir(parents=True)  # incomplete: no _SUCCESS
    for args in (("pack", empty, "--out", tmp_path / "ds"),
                 ("export", "coco", empty, "--out", tmp_path / "c.json"),
                 ("export", "bop", empty, "--out", tmp_path / "bop"),
                 ("export", "tapvid", empty, "--out", tmp_path / "t.pkl"),
                 ("export", "nerf", empty, "--out", tmp_path / "nerf"),
                 ("export", "lasr", empty / "scene_00000001", "--out", tmp_path / "lasr"),
                 ("view", tmp_path / "nowhere"),
                 ("inspect", empty / "scene_00000001")):
        one_line(kubric(*args), 1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty"]


def test_a_busy_output_is_3_in_generate_and_pack(scenes, tmp_path):
    out = tmp_path / "run"
    with OutputLock(out / LOCK_FILE, f"--out {str(out)!r}"):
        one_line(kubric("generate", FAKE, "--out", out, "--scenes", "1", "--no-progress"), 3,
                 "is being written by another run")
    from kubric.datasets import packer
    with packer.output_lock(tmp_path / "ds"):
        one_line(kubric("pack", scenes, "--out", tmp_path / "ds", "--splits", "train=1",
                        "--no-progress"), 3, "is being written by another run")


def test_refused_outputs_and_bad_options_are_2(scenes, tmp_path):
    scene = scenes / "scene_00000000"
    for args in (("pack", scenes, "--out", scene / "ds"),
                 ("export", "coco", scenes, "--out", scene / "metadata.json"),
                 ("export", "coco", scenes, "--out", "s3://bucket/c.json"),
                 ("export", "bop", scenes, "--out", tmp_path / "b", "--depth-scale", "0"),
                 ("pack", scenes, "--out", tmp_path / "ds", "--splits", "train=0.5")):
        one_line(kubric(*args), 2)


def test_datasets_info_fails_on_unparsable_metadata(scenes, tmp_path):
    ds = tmp_path / "ds"
    proc = kubric("pack", scenes, "--out", ds, "--splits", "train=1", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert kubric("datasets", "info", ds).returncode == 0
    json.loads((ds / "features.json").read_text())  # valid before the damage
    for damage in ('{"type": ', "[1, 2]", None):
        if damage is None:
            (ds / "features.json").unlink()
        else:
            (ds / "features.json").write_text(damage)
        one_line(kubric("datasets", "info", ds), 1, "features.json")


def test_the_documented_table_is_the_error_classes():
    page = (ROOT / "docs" / "exit-codes.md").read_text()
    rows = dict(re.findall(r"^\| (\d+) \| \*?\*?([a-z]+)", page, re.M))
    assert rows == {"0": "success", "1": "bad", "2": "usage", "3": "busy", "130": "interrupted",
                    "143": "terminated"}
    assert (UsageError.exit_code, InputError.exit_code, KubricError.exit_code,
            OutputBusy.exit_code) == (2, 1, 1, 3)
