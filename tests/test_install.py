"""What `make demo` installs, and `pip install .` without make.

* The demo's environment is the core package without extras: `make -n demo` shows the one
  `pip install` it runs, and the closure of the core requirements (resolved against the
  distributions installed here, markers evaluated, no extras) holds no torch, jax, Dask or TFDS.
* A wheel built from the repository holds every module and the viewer's static files, installs
  into an empty venv, and its `kubric` command renders a tiny scene from outside the checkout.
"""

import importlib.metadata as md
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = pathlib.Path(__file__).resolve().parents[1]
HEAVY = {"torch", "jax", "jaxlib", "dask", "distributed", "tensorflow", "tensorflow-datasets",
         "grain", "array-record", "selenium", "moto", "boto3", "opencv-python-headless"}


def core_closure() -> set[str]:
    """Canonical names of the core requirements and, recursively, theirs (no extras)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    todo = [Requirement(r) for r in project["dependencies"]]
    seen: set[str] = set()
    while todo:
        req = todo.pop()
        if req.marker is not None and not req.marker.evaluate({"extra": ""}):
            continue
        name = canonicalize_name(req.name)
        if name in seen:
            continue
        seen.add(name)
        try:
            requires = md.distribution(req.name).requires or []
        except md.PackageNotFoundError:
            pytest.fail(f"core requirement {req.name} is not installed here")
        todo.extend(Requirement(r) for r in requires)
    return seen


def test_demo_installs_the_core_package_only():
    dry = subprocess.run(["make", "-n", "-B", "demo"], cwd=ROOT, capture_output=True, text=True)
    assert dry.returncode == 0, dry.stderr
    installs = [line for line in dry.stdout.splitlines() if "pip install" in line
                and "--upgrade pip" not in line]
    assert len(installs) == 1, installs
    assert ".venv-demo/bin/python" in installs[0] and re.search(r"install (--quiet )?-e \.$",
                                                                  installs[0]), installs[0]
    commands = [line for line in dry.stdout.splitlines() if not line.startswith("make[")]
    assert "python -m kubric.demo" in commands[-1]  # (make test runs this in a sub-make)
    closure = core_closure()
    assert {"bpy", "pybullet", "numpy"} <= closure
    assert not closure & HEAVY, sorted(closure & HEAVY)


@pytest.mark.slow
@pytest.mark.blender
def test_wheel_installs_and_runs_kubric_worker(tmp_path):
    dist = tmp_path / "dist"
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps",
                            "--no-build-isolation", "-w", str(dist), str(ROOT)],
                           capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert build.returncode == 0, build.stderr[-2000:]
    wheel = next(dist.glob("kubric-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    tracked = subprocess.run(["git", "ls-files", "kubric"], cwd=ROOT, capture_output=True,
                             text=True).stdout.split()
    missing = [f for f in tracked if f not in names]
    assert not missing, missing  # every module and the viewer's static files
    # An empty venv with the wheel alone; the dependencies (bpy alone is a 300 MB download)
    # come from this environment's site-packages through a .pth path line, which adds the folder
    # without running its own .pth files: the editable kubric of this checkout stays invisible.
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    site = pathlib.Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig."
                                        "get_paths()['purelib'])"], capture_output=True,
                                       text=True, check=True).stdout.strip())
    import numpy  # where this environment's dependencies are (not a path a test put first)
    deps = pathlib.Path(numpy.__file__).resolve().parents[1]
    assert (deps / "bpy").is_dir() and (deps / "pybullet_data").is_dir(), deps
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    install = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install",
                              "--no-deps", "--quiet", str(wheel)], capture_output=True, text=True,
                             timeout=300, env=env)
    assert install.returncode == 0, install.stderr[-2000:]
    (site / "zz_dependencies.pth").write_text(f"{deps}\n")
    where = subprocess.run([str(python), "-c", "import kubric, importlib.resources as r; "
                            "print(kubric.__file__); print((r.files('kubric.viewer') / 'static' /"
                            " 'index.html').is_file())"], capture_output=True, text=True,
                           env=env, cwd=tmp_path)
    assert where.returncode == 0, where.stderr
    module, static = where.stdout.split()
    assert pathlib.Path(module).is_relative_to(venv) and static == "True"
    kubric = venv / "bin" / "kubric"
    assert shutil.which(str(kubric))
    run = subprocess.run([str(kubric), "worker", "movi_a", "--seed", "0", "--out",
                          str(tmp_path / "out"), "--set", "resolution=32", "--set",
                          "frame_end=2", "--set", "samples=1", "--set", "denoise=false"],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=400)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert (tmp_path / "out" / "scene_00000000" / "_SUCCESS").is_file()
