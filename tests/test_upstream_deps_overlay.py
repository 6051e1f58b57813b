"""``tools/run_upstream_tests.py --install-deps DIR`` leaves the environment's numpy alone
(issue #33: ``pip install --target DIR traitlets pyquaternion`` also put numpy 2.x into DIR, which
shadowed the environment's numpy 1.26, and ``import bpy`` failed there).

First the commands the tool builds, with pip replaced by a stand-in that writes the package
metadata pip would; then a real install from the package index into a temporary folder, used by
a real run of the tool and by ``import bpy``.
"""

import importlib.util
import os
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "tools" / "run_upstream_tests.py"


@pytest.fixture(scope="module")
def tool():
    spec = importlib.util.spec_from_file_location("run_upstream_tests", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def fake_pip(requires: dict, calls: list):
    """A stand-in for ``subprocess.run(pip install --target DIR --no-deps PKGS)``: writes a
    dist-info folder per package with its ``Requires-Dist`` lines from ``requires``."""
    def run(cmd, check):
        calls.append(cmd)
        target = Path(cmd[cmd.index("--target") + 1])
        for arg in cmd[cmd.index("--target") + 2:]:
            name = Requirement(arg).name
            info = target / f"{name}-1.0.dist-info"
            info.mkdir(parents=True)
            lines = ["Metadata-Version: 2.1", f"Name: {name}", "Version: 1.0",
                     *(f"Requires-Dist: {r}" for r in requires.get(name, ()))]
            (info / "METADATA").write_text("\n".join(lines) + "\n")
    return run


def test_only_missing_packages_with_no_deps_never_numpy(tool, tmp_path):
    assert metadata.version("hypothesis") and metadata.version("numpy")  # the env has both
    calls = []
    requires = {"pyquaternion": ["numpy>=1.13"], "traitlets": [],
                "not-in-env-a": ["not-in-env-b ; python_version >= '3'",
                                 "numpy ; extra == 'never'"], "not-in-env-b": []}
    packages = ("traitlets", "pyquaternion", "hypothesis", "not-in-env-a")
    installed = tool.install_deps(tmp_path / "deps", packages, run=fake_pip(requires, calls))
    assert installed == ["not-in-env-a", "pyquaternion", "traitlets", "not-in-env-b"]
    assert [c[c.index("--target") + 2:] for c in calls] == [
        ["not-in-env-a", "pyquaternion", "traitlets"], ["not-in-env-b"]]
    for cmd in calls:
        assert cmd[:4] == [sys.executable, "-m", "pip", "install"]
        assert "--no-deps" in cmd and cmd[cmd.index("--target") + 1] == str(tmp_path / "deps")
        assert not any(arg.startswith(("numpy", "hypothesis")) for arg in cmd)


def test_a_requirement_the_env_cannot_meet_stops_with_one_line(tool, tmp_path):
    requires = {"pyquaternion": ["numpy>=99"]}
    with pytest.raises(SystemExit, match=r"pyquaternion needs numpy>=99, but this environment "
                                         rf"has numpy {np.__version__}; not installing a second"):
        tool.install_deps(tmp_path / "deps", ("pyquaternion",), run=fake_pip(requires, []))


@pytest.mark.slow
@pytest.mark.blender
def test_real_install_keeps_the_envs_numpy_and_bpy_imports(tmp_path):
    """pip from the package index: traitlets and pyquaternion land in DIR, numpy does not; the
    tool's own run (a stand-in upstream test importing them) and ``import bpy`` see the env's
    numpy."""
    tests = tmp_path / "test"
    tests.mkdir()
    (tests / "test_imports.py").write_text(
        "import numpy, pyquaternion, traitlets\n\n"
        f"def test_envs_numpy():\n    assert numpy.__version__ == {np.__version__!r}\n"
        f"    assert numpy.__file__ == {np.__file__!r}\n")
    deps = tmp_path / "deps"
    proc = subprocess.run([sys.executable, str(SCRIPT), str(tests), "--install-deps", str(deps)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.splitlines()[-1] == "upstream tests: 1 of 1 passed", proc.stdout
    names = {d.metadata["Name"].lower() for d in metadata.distributions(path=[str(deps)])}
    assert {"traitlets", "pyquaternion"} <= names and "numpy" not in names
    assert not (deps / "numpy").exists()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(deps), str(ROOT)]))
    out = subprocess.run([sys.executable, "-c", "import bpy, numpy, pyquaternion; "
                          "print(numpy.__version__, bpy.app.version_string)"], env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[0] == np.__version__
