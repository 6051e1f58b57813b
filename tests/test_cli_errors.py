"""The one top-level error handler of the ``kubric`` command (issue 16): an ordinary mistake gives
one line ``kubric <command>: error: ...`` on stderr, exit 2 (usage) or 1 (failure), no traceback
unless ``--debug``, and nothing written."""

import os
import pathlib
import subprocess
import sys

import pytest


def kubric(*args, cwd, env=None):
    environ = dict(os.environ)
    environ.pop("KUBRIC_DEBUG", None)
    environ.update(env or {})
    return subprocess.run([sys.executable, "-m", "kubric", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=300, env=environ)


def listing(root: pathlib.Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def assert_one_line(r, command, code, *needles):
    lines = r.stderr.strip().splitlines()
    assert r.returncode == code, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr
    assert len(lines) == 1 and lines[0].startswith(f"kubric {command}: error: "), r.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


@pytest.fixture
def place(tmp_path):
    (tmp_path / "afile").write_text("not a directory\n")
    hdri = tmp_path / "hdris"
    hdri.mkdir()
    (hdri / "sky.hdr").write_text("just some text, named .hdr\n")
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    (meshes / "cube.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                                     "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    (meshes / "cube.json").write_text('{"category": "box",')  # truncated sidecar
    return tmp_path


TINY = ["--set", "resolution=8", "--set", "frame_end=2", "--set", "samples=1"]


@pytest.mark.parametrize("args,command,code,needles", [
    (["worker", "movi_a", "--seed", "0", "--out", "afile"], "worker", 2, ["afile", "not a directory"]),
    (["worker", "movi_a", "--seed", "0", "--out", "afile/sub"], "worker", 2, ["afile"]),
    (["worker", "movi_a", "--seed", "0", "--out", ""], "worker", 2, ["empty"]),
    (["generate", "movi_a", "--scenes", "1", "--out", ""], "generate", 2, ["empty"]),
    (["generate", "movi_a", "--scenes", "1", "--out", "afile"], "generate", 2, ["afile"]),
    (["worker", "movi_a", "--seed", "0", *TINY, "--out", "/proc/kubric-out"], "worker", 1,
     ["/proc/kubric-out"]),
    (["assets", "hdri", "hdris", "--license", "CC0", "--out", "h"], "assets", 1,
     ["sky.hdr", "not a valid .hdr image"]),
    (["assets", "hdri", "nowhere", "--license", "CC0", "--out", "h"], "assets", 1, ["nowhere"]),
    (["assets", "convert", "meshes", "--name", "m", "--license", "CC0", "--out", "m"], "assets", 1,
     ["cube.json", "not valid JSON"]),
    (["assets", "list", "nowhere"], "assets", 1, ["nowhere"]),
    (["assets", "list", "afile"], "assets", 1, ["afile"]),
    (["inspect", "nowhere"], "inspect", 2, ["nowhere"]),
])
def test_ordinary_mistakes_give_one_line(place, args, command, code, needles):
    before = listing(place)
    r = kubric(*args, cwd=place)
    assert_one_line(r, command, code, *needles)
    assert listing(place) == before  # nothing written, not even an empty output folder


def test_debug_flag_shows_the_traceback(place):
    args = ["assets", "convert", "meshes", "--name", "m", "--license", "CC0", "--out", "m"]
    for r in (kubric("--debug", *args, cwd=place), kubric(*args, cwd=place,
                                                           env={"KUBRIC_DEBUG": "1"})):
        assert r.returncode == 1
        assert "Traceback" in r.stderr and "InputError" in r.stderr
        assert r.stderr.strip().splitlines()[-1].startswith("kubric assets: error: sidecar")


def test_exit_codes_classify_errors():
    from kubric.cli import error_line, exit_code
    from kubric.pipeline.options import OptionError
    assert exit_code(OptionError("x")) == 2
    assert exit_code(FileNotFoundError(2, "No such file or directory", "a")) == 1
    assert exit_code(OSError(28, "No space left on device")) == 1
    assert exit_code(KeyError("bug")) is None  # a bug keeps its traceback
    assert error_line(PermissionError(13, "Permission denied", "/x")) == "/x: Permission denied"
    assert error_line(ValueError("two\nlines")) == "two lines"


BAD_INPUT_RECIPE = """
from kubric.errors import InputError
from kubric.pipeline import Recipe


class BadInput(Recipe, name="bad_input_test"):
    def generate(self, seed, out_dir):
        raise InputError(f"scene {seed}: an input file is bad")


class Buggy(Recipe, name="buggy_test"):
    def generate(self, seed, out_dir):
        raise ValueError(f"scene {seed}: operands could not be broadcast")
"""


def test_runner_logs_keep_the_traceback(tmp_path):
    (tmp_path / "bad_input.py").write_text(BAD_INPUT_RECIPE)
    r = kubric("generate", "bad_input.py:BadInput", "--scenes", "1", "--retries", "0",
               "--no-progress", "--out", "out", cwd=tmp_path)
    assert r.returncode != 0
    log = (tmp_path / "out" / "logs" / "scene_00000000.log").read_text()
    assert "Traceback" in log and "InputError: scene 0: an input file is bad" in log
    assert "kubric worker: error: scene 0: an input file is bad" in log


def test_an_unexpected_error_keeps_its_traceback(tmp_path):
    """Only kubric's own errors (KubricError) and OSErrors are one line: a ValueError from deep
    inside (a numpy shape bug, say) is a bug, printed with its traceback."""
    (tmp_path / "bad_input.py").write_text(BAD_INPUT_RECIPE)
    r = kubric("worker", "bad_input.py:Buggy", "--seed", "0", "--out", "out", cwd=tmp_path)
    assert r.returncode == 1
    assert "Traceback" in r.stderr and r.stderr.strip().endswith(
        "ValueError: scene 0: operands could not be broadcast")
    assert "kubric worker: error:" not in r.stderr


def test_failure_reason_names_a_timeout_not_the_logs_first_line(tmp_path):
    from kubric.pipeline.runner import RunSummary
    log = tmp_path / "scene_00000000.log"
    log.write_text("=== attempt 1 at 2026-01-01 00:00:00: kubric worker\n"
                   "ValueError: first attempt failed\n=== exit status 1\n"
                   "=== attempt 2 at 2026-01-01 00:00:09: kubric worker\n"
                   "pybullet build time: Jan 29 2025 23:17:20\n"
                   "=== timed out after 5.0 s\n=== exit status -9\n")
    summary = RunSummary(requested=1, failed={0: log})
    assert "FAILED scene_00000000: timed out after 5.0 s (--timeout)" in summary.format("out")
    log.write_text("=== attempt 1 at 2026-01-01 00:00:00: kubric worker\n=== exit status -9\n")
    assert "FAILED scene_00000000: exit status -9" in summary.format("out")


@pytest.fixture
def tiny_disk(tmp_path):
    """A 64 KiB tmpfs (needs mount rights: root in a container); skipped where not allowed."""
    mnt = tmp_path / "tiny_disk"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", str(mnt)], check=True)


def test_full_disk_during_extraction_is_not_called_corrupt(tmp_path, tiny_disk):
    import tarfile

    from kubric.assets.archive import safe_extract
    member = tmp_path / "big.bin"
    member.write_bytes(bytes(1 << 20))  # 1 MiB: does not fit on the 64 KiB disk
    archive = tmp_path / "a.tar.gz"
    with tarfile.open(archive, "w:gz") as tar:
        tar.add(member, arcname="big.bin")
    with pytest.raises(OSError) as err:
        safe_extract(archive, tiny_disk / "out", "a")
    assert err.value.errno == 28 and "corrupt" not in str(err.value)
    from kubric.cli import error_line, exit_code
    assert exit_code(err.value) == 1
    assert error_line(err.value).startswith(str(tiny_disk)) and "No space left" in \
        error_line(err.value) and "'big.bin'" in error_line(err.value)
    assert list(tiny_disk.iterdir()) == []  # the staging folder is removed too


def test_generate_on_a_full_disk_is_one_line(tiny_disk):
    (tiny_disk / "fill").write_bytes(bytes(64 * 1024))  # the disk is full before the run
    fake = pathlib.Path(__file__).with_name("fake_recipes.py")
    r = kubric("generate", f"{fake}:Fake", "--scenes", "2", "--no-progress", "--out",
               str(tiny_disk / "out"), cwd=tiny_disk.parent)
    assert_one_line(r, "generate", 1, "No space left on device")
    assert "Errno" not in r.stderr
