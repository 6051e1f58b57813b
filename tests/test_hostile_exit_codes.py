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
                 ("export", "bop", scenes, "--out", tmp_path / "b", "--depth-scale", "inf"),
                 ("export", "bop", scenes, "--out", tmp_path / "b", "--depth-scale", "nan"),
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


MEMORY_LIMITED = """
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))
from kubric.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_running_out_of_memory_within_the_option_bounds_is_one_line(tmp_path):
    """resolution=8192 is allowed; under a 3 GiB address-space limit it cannot be rendered: one
    line, exit status 1, no scene."""
    import os
    import subprocess
    import sys
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    proc = subprocess.run([sys.executable, "-c", MEMORY_LIMITED, "worker", "movi_a", "--seed", "1",
                           "--out", str(tmp_path / "o"), "--set", "renderer=raycast", "--set",
                           "resolution=8192", "--set", "frame_end=2", "--set",
                           "max_num_objects=3"], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=600)
    lines = [ln for ln in proc.stderr.strip().splitlines() if not ln.startswith("pybullet build")]
    assert proc.returncode == 1 and len(lines) == 1, proc.stderr[-3000:]
    assert lines[0].startswith("kubric worker: error: out of memory"), lines[0]
    assert not list((tmp_path / "o").glob("scene_*"))


SWALLOWER = """
import os, signal, time
try:
    os.kill(os.getpid(), signal.SIGINT)   # Ctrl-C lands while this module imports ...
    for _ in range(40):                   # (short sleeps: the handler runs between them even
        time.sleep(0.05)                  # when another thread took the signal, under load)
except BaseException:                     # ... and is swallowed, as trimesh's imports do
    pass
"""


def test_a_ctrl_c_during_a_swallowing_import_is_not_lost(tmp_path):
    import os
    import subprocess
    import sys
    (tmp_path / "swallow_a.py").write_text(SWALLOWER)
    (tmp_path / "swallow_b.py").write_text(SWALLOWER)
    code = ("import importlib, signal, sys\n"
            # Ctrl-C as in a terminal: a test run started as a background job (CI, `make test &`)
            # hands its children SIGINT ignored, and an ignored Ctrl-C is rightly not raised
            "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
            "from kubric.core.imports import uninterrupted_import\n"
            "importlib.import_module('swallow_a')\n"
            "print('plain import: the interrupt was lost', flush=True)\n"
            "try:\n"
            "    uninterrupted_import('swallow_b')\n"
            "except KeyboardInterrupt:\n"
            "    print('held import: interrupted after it', flush=True)\n"
            "    sys.exit(130)\n")
    env = dict(os.environ, PYTHONPATH=f"{tmp_path}{os.pathsep}{ROOT}")
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          timeout=60)
    assert proc.stdout.splitlines() == ["plain import: the interrupt was lost",
                                        "held import: interrupted after it"], proc.stderr
    assert proc.returncode == 130
