"""A command that needs an optional package which is not installed ends in one line naming the
extra to install — the core install as `make demo` makes it, simulated by a sitecustomize that
makes the package unimportable (as tests/no_bpy does for bpy) in the `kubric` process."""

import os
import pathlib
import re
import subprocess
import sys
import tomllib

import pytest

from kubric import extras
from kubric.pipeline.worker import run_scene
from kubric.recipes.bench import Bench

ROOT = pathlib.Path(__file__).resolve().parents[1]

BLOCKER = """
import sys

BLOCKED = {blocked!r}


class NotInstalled:
    '''As if the packages were absent: importing them (or their modules) fails, find_spec too.'''
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None


sys.meta_path.insert(0, NotInstalled())
"""


def kubric_without(tmp_path, blocked, *args, timeout=120):
    hook = tmp_path / "hook"
    hook.mkdir(exist_ok=True)
    (hook / "sitecustomize.py").write_text(BLOCKER.format(blocked=sorted(blocked)))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        filter(None, [str(hook), str(ROOT), os.environ.get("PYTHONPATH")])))
    return subprocess.run([sys.executable, "-m", "kubric", *args], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=timeout)


def one_line(proc) -> str:
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    return lines[0]


@pytest.fixture
def scenes(tmp_path):
    for seed in range(2):
        run_scene(Bench(), seed, tmp_path / "scenes")
    return tmp_path / "scenes"


def test_pack_without_tfds_names_the_datasets_extra(tmp_path, scenes):
    proc = kubric_without(tmp_path, {"tensorflow_datasets"}, "pack", str(scenes), "--out",
                          str(tmp_path / "ds"), "--no-progress")
    line = one_line(proc)
    assert proc.returncode == 1
    assert line == ("kubric pack: error: kubric pack needs the optional package "
                    "'tensorflow_datasets', which is not installed: pip install 'kubric[datasets]'")
    assert not (tmp_path / "ds").exists()


def test_generate_on_a_local_cluster_without_distributed_names_the_cluster_extra(tmp_path):
    proc = kubric_without(tmp_path, {"distributed", "dask"}, "generate", "bench", "--out",
                          str(tmp_path / "out"), "--scenes", "2", "--cluster", "local")
    assert proc.returncode == 1
    assert "pip install 'kubric[cluster]'" in one_line(proc)
    assert "'dask'" in one_line(proc) and "--cluster local" in one_line(proc)
    proc = kubric_without(tmp_path, {"dask_jobqueue"}, "generate", "bench", "--out",
                          str(tmp_path / "out"), "--scenes", "2", "--cluster", "slurm",
                          "--print-job-script")
    assert proc.returncode == 1 and "'dask_jobqueue'" in one_line(proc)


def test_any_other_optional_import_under_the_cli_is_one_line(tmp_path, scenes):
    """`kubric datasets info` reads shards with array_record, imported where it is used: the command's
    one handler turns its ModuleNotFoundError into the extra's line."""
    from kubric.datasets import pack
    pack(scenes, tmp_path / "ds", splits="train=1", progress=False)
    proc = kubric_without(tmp_path, {"array_record"}, "datasets", "info",
                          str(tmp_path / "ds"))
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert one_line(proc) == ("kubric datasets: error: needs the optional package 'array_record', "
                              "which is not installed: pip install 'kubric[datasets]'")
    # a module missing from an installed package is a broken install, not a missing extra
    assert extras.missing_extra(ModuleNotFoundError("x", name="tensorflow_datasets.nope")) is None


def test_the_table_follows_pyproject():
    optional = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]
    alias = {"cv2": "opencv_python_headless", "tensorflow": "tensorflow_cpu", "jaxlib": "jax"}
    for module, extra in extras.EXTRA_OF.items():
        names = {re.split(r"[<>=\[;! ]", r, maxsplit=1)[0].replace("-", "_").lower()
                 for r in optional[extra]}
        assert alias.get(module, module) in names, (module, extra, names)
