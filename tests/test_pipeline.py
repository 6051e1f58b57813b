"""Worker contract: options, registry, atomic scene directories, `kubric worker` / `recipes`."""

import json
import os
import pathlib
import subprocess
import sys
import time

import numpy as np
import pytest

from kubric.pipeline import Option, OptionError, Recipe, get_recipe, recipe, recipe_spec
from kubric.pipeline.worker import is_complete, run_scene, scene_name, stale_work_dirs

ROOT = pathlib.Path(__file__).resolve().parents[1]
FAKE = f"{ROOT / 'tests' / 'fake_recipes.py'}:Fake"


def kubric(*args, timeout=60):
    return subprocess.run([sys.executable, "-m", "kubric", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


def test_options_convert_and_reject_with_one_line_errors(tmp_path):
    fake = get_recipe(FAKE)
    r = fake.from_assignments(["resolution=16x12", "frames=5", "flaky=yes",
                               f"assets={tmp_path}"])
    assert r.resolution == (16, 12) and r.frames == 5 and r.flaky is True
    assert r.assets == tmp_path and r.sleep == 0.0
    cases = {
        "resolution=-3": "(allowed: N or WxH with positive integers",
        "frames=2.5": "option frames='2.5'",
        "frames=101": "out of range",
        "nope=1": "unknown option 'nope'",
        "flaky=maybe": "expected a boolean",
        f"assets={tmp_path / 'missing'}": "path does not exist",
        "frames": "--set expects key=value",
    }
    for pair, message in cases.items():
        with pytest.raises(OptionError) as err:
            fake.from_assignments([pair])
        assert message in str(err.value) and "\n" not in str(err.value), pair
    with pytest.raises(OptionError, match="unknown recipe 'no_such'"):
        get_recipe("no_such")


def test_class_and_function_recipes_register(tmp_path):
    class Mine(Recipe, name="test_mine"):
        """Mine."""
        n = Option(2, "count", low=0)

        def generate(self, seed, out_dir):
            (out_dir / "n.txt").write_text(str(self.n + seed))

    @recipe("test_fn", k=Option("a", "letter", choices=("a", "b")))
    def fn(seed, values, out_dir):
        (out_dir / "k.txt").write_text(values["k"])

    assert get_recipe("test_mine") is Mine and get_recipe("test_fn") is fn
    assert Mine.description() == "Mine." and list(fn.options) == ["k"]
    with pytest.raises(OptionError, match="allowed: one of a, b"):
        fn(k="c")
    res = run_scene(fn(k="b"), 4, tmp_path)
    assert (res.path / "k.txt").read_text() == "b" and res.status == "done"
    assert Mine(n=1).flags(7) == {"recipe": "test_mine", "seed": 7, "n": 1}
    assert recipe_spec(get_recipe(FAKE)).endswith("fake_recipes.py:Fake")

    class NoGenerate(Recipe):
        pass
    with pytest.raises(TypeError):
        NoGenerate()


def test_run_scene_is_atomic_skips_and_redoes(tmp_path):
    fake = get_recipe(FAKE)
    res = run_scene(fake(), 5, tmp_path)
    assert res.path == tmp_path / "scene_00000005" and is_complete(res.path)
    assert sorted(p.name for p in res.path.iterdir())[-1] == "segmentation_00002.png"
    assert json.loads((res.path / "_SUCCESS").read_text())["seed"] == 5
    mtime = (res.path / "metadata.json").stat().st_mtime_ns
    assert run_scene(fake(), 5, tmp_path).status == "skipped"
    assert (res.path / "metadata.json").stat().st_mtime_ns == mtime
    # a failing recipe leaves nothing behind
    with pytest.raises(RuntimeError, match="on purpose"):
        run_scene(fake(fail=True), 6, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene_00000005"]
    # an incomplete final dir and a dead process's work dir are discarded and redone
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    (tmp_path / "scene_00000007").mkdir()
    (tmp_path / "scene_00000007" / "junk").write_text("x")
    work = tmp_path / f".scene_00000007.incomplete-{dead}"
    work.mkdir()
    assert stale_work_dirs(tmp_path) == [work]
    res = run_scene(fake(), 7, tmp_path)
    assert is_complete(res.path) and not (res.path / "junk").exists() and not work.exists()
    with pytest.raises(ValueError, match="seed"):
        scene_name(-1)


def test_success_is_written_before_the_rename_so_the_final_name_appears_complete(tmp_path,
                                                                                   monkeypatch):
    """The rename of the work directory is the single step that publishes a scene: at that
    instant the work directory already holds _SUCCESS (and no temporary marker), and a crash of
    the rename leaves no final-named directory at all."""
    from kubric.pipeline import worker
    seen = []
    real_rename = os.rename

    def rename(src, dst):
        seen.append(sorted(p.name for p in pathlib.Path(src).iterdir()))
        if len(seen) == 2:
            raise OSError("rename fails on purpose")
        real_rename(src, dst)

    monkeypatch.setattr(worker.os, "rename", rename)
    res = run_scene(get_recipe(FAKE)(), 11, tmp_path)
    assert "_SUCCESS" in seen[0] and not [n for n in seen[0] if n.endswith(".tmp")]
    assert json.loads((res.path / "_SUCCESS").read_text())["seed"] == 11
    with pytest.raises(OSError, match="on purpose"):
        run_scene(get_recipe(FAKE)(), 12, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene_00000011"]


@pytest.mark.skipif(not pathlib.Path("/proc/self/stat").exists(), reason="needs procfs")
def test_work_dir_of_an_unreaped_exited_worker_is_stale(tmp_path):
    # a worker of a SIGKILLed runner can stay a zombie (exited, never reaped) in containers
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    try:
        deadline = time.time() + 30
        while pathlib.Path(f"/proc/{child.pid}/stat").read_text().rsplit(")", 1)[-1].split()[0] != "Z":
            assert time.time() < deadline, "child did not exit"
            time.sleep(0.02)
        work = tmp_path / f".scene_00000003.incomplete-{child.pid}"
        work.mkdir()
        assert stale_work_dirs(tmp_path) == [work]
    finally:
        child.wait()


def test_worker_cli_determinism_errors_and_index(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        proc = kubric("worker", FAKE, "--seed", "11", "--out", str(out), "--set", "frames=2")
        assert proc.returncode == 0, proc.stderr
    meta_a = (a / "scene_00000011" / "metadata.json").read_text()
    assert meta_a == (b / "scene_00000011" / "metadata.json").read_text()
    assert json.loads(meta_a)["flags"]["seed"] == 11
    assert json.loads(meta_a)["flags"]["frames"] == 2
    proc = kubric("worker", FAKE, "--index", "3", "--first-seed", "10", "--out", str(a))
    assert proc.returncode == 0, proc.stderr
    other = json.loads((a / "scene_00000013" / "metadata.json").read_text())
    assert other["value"] != json.loads(meta_a)["value"]
    for pair, text in (("resolution=-3", "resolution"), ("bogus=1", "unknown option 'bogus'"),
                       (f"assets={tmp_path / 'nope'}", "does not exist")):
        proc = kubric("worker", FAKE, "--seed", "1", "--out", str(tmp_path / "c"),
                      "--set", pair)
        assert proc.returncode == 2
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and text in lines[0] and lines[0].startswith("kubric worker:")
        assert not (tmp_path / "c").exists()


def test_recipes_command_lists_options():
    proc = kubric("recipes", FAKE)
    assert proc.returncode == 0, proc.stderr
    assert "test_fake: Tiny random scene" in proc.stdout
    assert "resolution" in proc.stdout and "frames" in proc.stdout
    proc = kubric("recipes", "nonexistent_recipe")
    assert proc.returncode == 2 and "unknown recipe" in proc.stderr
    assert os.environ.get("KUBRIC_RUNNER_PID") is None


def test_movi_bad_options_fail_before_rendering(tmp_path):
    for pair, text in (("resolution=-3", "option resolution='-3'"),
                       ("colour=red", "unknown option 'colour'"),
                       (f"kubasic_source={tmp_path / 'nope'}", "path does not exist"),
                       (f"kubasic_source={tmp_path}", "is not an asset source"),
                       ("frame_end=0", "option frame_end='0'"),
                       ("step_rate=250", "must be a multiple of frame_rate"),
                       ("min_num_objects=8", "must be ≤ max_num_objects")):
        extra = ["--set", "max_num_objects=5"] if "min_num" in pair else []
        proc = kubric("worker", "movi_a", "--seed", "0", "--out", str(tmp_path / "o"),
                      "--set", pair, *extra)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1, proc.stderr
        assert text in lines[0] and "movi_a" in lines[0], lines[0]
    proc = kubric("worker", "movi_c", "--seed", "0", "--out", str(tmp_path / "o"),
                  "--set", f"hdri_source={tmp_path / 'none'}")
    assert proc.returncode == 2 and "hdri_source" in proc.stderr
    assert not (tmp_path / "o").exists()
    proc = kubric("recipes")
    for name in ("movi_a", "movi_b", "movi_c", "movi_d", "movi_e", "movi_f"):
        assert f"\n{name}: " in "\n" + proc.stdout
    assert "max_motion_blur" in proc.stdout and "max_camera_movement" in proc.stdout


@pytest.mark.parametrize("name", ["movi_a", "movi_b", "movi_c", "movi_d", "movi_e", "movi_f"])
def test_movi_cameras_follow_upstream_settings(name):
    """Every MOVi camera is upstream's 35 mm lens on a 32 mm sensor; A sits at CLEVR's position
    + U[0,1)³, B–D in the shell r ∈ [7, 9], E/F move inside the shell [8, 12] by at most 4 m."""
    import kubric as kb
    for seed in range(5):
        scene = kb.Scene(frame_end=6)
        get_recipe(name)().build_camera(scene, np.random.RandomState(seed))
        cam = scene.camera
        assert (cam.focal_length, cam.sensor_width) == (35.0, 32.0)
        path = cam.get_values_over_time("position", range(0, 8)).astype(np.float64)
        r = np.linalg.norm(path, axis=1)
        if name == "movi_a":
            offset = path[0] - (7.48113, -6.50764, 5.34367)
            assert np.all((offset >= 0) & (offset < 1)) and np.ptp(r) == 0
        elif name in ("movi_b", "movi_c", "movi_d"):
            assert 7 <= r[0] <= 9 and path[0, 2] >= 0.1 and np.ptp(r) == 0
        else:
            assert np.all((r >= 8 - 1e-5) & (r <= 12 + 1e-5)) and np.all(path[:, 2] > 0.1)
            assert np.linalg.norm(path[-1] - path[0]) <= 4.0 + 1e-5
