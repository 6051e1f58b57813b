"""`kubric generate` run from a folder that holds a folder named `kubric` (the clone, run from its
parent): the workers import the installed package, not that folder.

An editable install (`pip install -e .`, as `make demo` does) finds kubric through a meta-path
finder that Python consults after the module path, and `python -m` puts the current directory
first on that path: a folder named `kubric` there became a namespace package in every worker
("module 'kubric' has no attribute 'Scene'"). The tests below install the same kind of finder
(pointing at this checkout) instead of putting the checkout on PYTHONPATH, and run the `kubric`
command as its console script does.
"""

import os
import pathlib
import subprocess
import sys

import pytest

from kubric.io.scene_dir import is_complete

ROOT = pathlib.Path(__file__).resolve().parents[1]

FINDER = f"""
import importlib.machinery, importlib.util, sys

class CheckoutFinder:
    '''kubric from {str(ROOT)!r}, consulted after the module path (as an editable install's).'''
    def find_spec(self, name, path=None, target=None):
        if name != "kubric":
            return None
        return importlib.util.spec_from_file_location(
            name, {str(ROOT / "kubric" / "__init__.py")!r},
            submodule_search_locations=[{str(ROOT / "kubric")!r}])

at = sys.meta_path.index(importlib.machinery.PathFinder) + 1
sys.meta_path.insert(at, CheckoutFinder())
"""

TINY = ["--set", "renderer=raycast", "--set", "resolution=32x32", "--set", "frame_end=2"]
CONSOLE_SCRIPT = ("import sys\nfrom kubric.cli import main\nif __name__ == '__main__':\n"
                  "    sys.exit(main())\n")  # what pip writes for [project.scripts]


@pytest.fixture
def installed(tmp_path):
    """(env, console script): kubric found through a finder only, as after `pip install -e`."""
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(FINDER)
    script = tmp_path / "bin" / "kubric"
    script.parent.mkdir()
    script.write_text(CONSOLE_SCRIPT)
    keep = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep)
            if p and pathlib.Path(p).resolve() != ROOT]  # e.g. tests/no_bpy
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(hook), *keep]))
    return env, script


def shadowed(cwd: pathlib.Path, env) -> str:
    """What `python -m` in ``cwd`` imports as kubric (the situation the workers were in)."""
    proc = subprocess.run([sys.executable, "-c", "import kubric; print(kubric.__file__)"],
                          cwd=cwd, env=env, capture_output=True, text=True, timeout=60)
    return proc.stdout.strip()


def generate_in(cwd: pathlib.Path, installed) -> subprocess.CompletedProcess:
    env, script = installed
    # movi_a, not bench: a recipe that reads kubric's attributes (kb.Scene) failed; bench,
    # importing submodules only, ran even in a shadowed worker
    return subprocess.run([sys.executable, str(script), "generate", "movi_a", "--out", "scenes",
                           "--scenes", "2", "--workers", "2", "--retries", "0", "--no-progress",
                           *TINY], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


def test_an_empty_folder_named_kubric_does_not_shadow_the_workers(tmp_path, installed):
    run = tmp_path / "run"
    (run / "kubric").mkdir(parents=True)
    assert shadowed(run, installed[0]) == "None"  # a namespace package: the trap is set
    proc = generate_in(run, installed)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "2 generated" in proc.stdout
    assert all(is_complete(run / "scenes" / f"scene_{s:08d}") for s in range(2))


def test_a_clone_beside_the_output_does_not_shadow_the_workers(tmp_path, installed):
    run = tmp_path / "work"
    clone = run / "kubric"
    for folder in ("kubric/recipes", "docs", "tests"):
        (clone / folder).mkdir(parents=True)
    (clone / "pyproject.toml").write_text('[project]\nname = "kubric"\n')
    (clone / "README.md").write_text("# Kubric\n")
    (clone / "kubric" / "__init__.py").write_text("raise ImportError('the clone, not installed')\n")
    assert shadowed(run, installed[0]) == "None"
    proc = generate_in(run, installed)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert all(is_complete(run / "scenes" / f"scene_{s:08d}") for s in range(2))
    log = (run / "scenes" / "logs" / "scene_00000000.log").read_text()
    assert "AttributeError" not in log and "done: " in log


def test_a_module_recipe_found_in_the_current_folder_still_runs(tmp_path, installed):
    """The workers no longer see the current folder; a ``module:Class`` recipe that
    `python -m kubric` imported from there is still found (generate hands the workers its
    folder)."""
    run = tmp_path / "mine"
    run.mkdir()
    (run / "my_recipes.py").write_text((ROOT / "tests" / "fake_recipes.py").read_text())
    proc = subprocess.run([sys.executable, "-m", "kubric", "generate", "my_recipes:Fake",
                           "--out", "scenes", "--scenes", "1", "--retries", "0", "--no-progress"],
                          cwd=run, env=installed[0], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert is_complete(run / "scenes" / "scene_00000000")
