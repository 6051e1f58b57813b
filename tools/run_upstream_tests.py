"""Run upstream Kubric's own unit tests against this package and count how many pass.

Usage::

    python tools/run_upstream_tests.py PATH [--extra-path DIR] [-k EXPR] [--show-passed]

``PATH`` is the ``test/`` folder of a checkout of https://github.com/google-research/kubric that
you supply (or the checkout itself); nothing is downloaded. The test files are copied to a
temporary directory and run there with this interpreter's pytest, isolated from this repository's
pytest configuration and fixtures, so they see the package exactly as a user's script would.

Upstream's tests import ``traitlets``, ``pyquaternion`` and ``hypothesis`` (and ``tensorflow`` for
its old dataset tests). These are not dependencies of this package: ``--install-deps DIR`` installs
into DIR those of them this environment lacks, and puts DIR on the tests' path. It never installs a
package the environment already has (above all numpy: a plain ``pip install --target DIR
pyquaternion`` also puts the newest numpy into DIR, which then shadows the environment's, and
``import bpy`` fails there): pip runs with ``--no-deps``, then every requirement of what landed in
DIR must be met by DIR or the environment — a missing one is installed the same way, one the
environment has in a version that does not fit stops with one line. ``--extra-path DIR`` adds a
folder you filled yourself.

A module that cannot be imported counts all of its tests as failed; their number is read from the
module's source (``test_*`` functions and methods, times the length of literal
``pytest.mark.parametrize`` lists). The last line printed is ``upstream tests: N of M passed``.
"""

from __future__ import annotations

import argparse
import ast
import os
import re
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path


def _parametrize_count(decorator: ast.expr) -> int:
    """Number of cases of a literal ``@pytest.mark.parametrize(names, [...])``, else 1."""
    if not (isinstance(decorator, ast.Call) and isinstance(decorator.func, ast.Attribute)
            and decorator.func.attr == "parametrize" and len(decorator.args) >= 2):
        return 1
    values = decorator.args[1]
    return len(values.elts) if isinstance(values, (ast.List, ast.Tuple)) else 1


def _tests_in_function(node: ast.AST) -> int:
    count = 1
    for decorator in node.decorator_list:
        count *= _parametrize_count(decorator)
    return count


def count_tests_in_source(source: str) -> int:
    """How many test items pytest would collect from a module, read from its source."""
    total = 0
    for node in ast.parse(source).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and \
                node.name.startswith("test"):
            total += _tests_in_function(node)
        elif isinstance(node, ast.ClassDef) and node.name.startswith("Test") or \
                isinstance(node, ast.ClassDef) and any(
                    isinstance(b, ast.Attribute) and b.attr.endswith("TestCase")
                    for b in node.bases):
            total += sum(_tests_in_function(item) for item in node.body
                         if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef))
                         and item.name.startswith("test"))
    return total


def _find_test_dir(path: Path) -> Path:
    if (path / "test").is_dir() and not list(path.glob("test_*.py")):
        path = path / "test"
    if not path.is_dir() or not list(path.glob("test_*.py")):
        raise SystemExit(f"run_upstream_tests: {str(path)!r} holds no test_*.py files; pass "
                         "upstream Kubric's test/ folder (or a checkout containing it)")
    return path


def _outcomes(junit: Path) -> tuple[dict[str, str], dict[str, str]]:
    """{test id: outcome} for collected tests, {module file: message} for modules not imported."""
    outcomes, broken = {}, {}
    for case in ET.parse(junit).getroot().iter("testcase"):
        classname, name = case.get("classname", ""), case.get("name", "")
        kinds = {child.tag for child in case}
        if not name and "error" in kinds or (name and classname == "" and "error" in kinds):
            error = case.find("error")
            lines = [ln[1:].strip() for ln in (error.text or "").splitlines()
                     if ln.startswith("E ")]
            broken[name or classname] = lines[-1] if lines else error.get("message", "")
            continue
        if "skipped" in kinds:
            outcome = "skipped"
        elif "failure" in kinds:
            outcome = "failed"
        elif "error" in kinds:
            outcome = "error"
        else:
            outcome = "passed"
        outcomes[f"{classname}::{name}"] = outcome
    return outcomes, broken


#: what upstream's unit tests import beyond this package's own dependencies
UPSTREAM_TEST_DEPS = ("traitlets", "pyquaternion", "hypothesis")


def _canonical(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _env_version(name: str) -> str | None:
    """The version of distribution ``name`` installed in this environment, or None."""
    from importlib import metadata
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def install_command(target: Path, packages) -> list[str]:
    """The pip command that installs ``packages`` into ``target`` and nothing else (no deps)."""
    return [sys.executable, "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
            "--no-deps", "--target", str(target), *packages]


def unmet_requirements(target: Path) -> list[str]:
    """Requirements of the distributions in ``target`` that neither ``target`` nor this
    environment has; ``SystemExit`` (one line) for one the environment has in a version that does
    not satisfy it (installing it into ``target`` would shadow the environment's)."""
    from importlib import metadata

    from packaging.requirements import Requirement
    local = {_canonical(d.metadata["Name"]): d.version
             for d in metadata.distributions(path=[str(target)])}
    unmet = []
    for dist in metadata.distributions(path=[str(target)]):
        for text in dist.requires or ():
            req = Requirement(text)
            if req.marker is not None and not req.marker.evaluate({"extra": ""}):
                continue
            name = _canonical(req.name)
            env = None if name in local else _env_version(req.name)
            have = local.get(name, env)
            if have is None:
                unmet.append(f"{req.name}{req.specifier}")  # its marker holds here
            elif env is not None and not req.specifier.contains(have, prereleases=True):
                raise SystemExit(f"run_upstream_tests: {dist.metadata['Name']} needs {req}, but "
                                 f"this environment has {req.name} {have}; not installing a "
                                 f"second copy into {str(target)!r}")
    return sorted(set(unmet))


def install_deps(target: Path, packages=UPSTREAM_TEST_DEPS, run=subprocess.run) -> list[str]:
    """Install into ``target`` the ``packages`` this environment lacks and, in turn, their
    requirements that neither has (module doc). Returns what was installed."""
    from importlib import metadata
    target.mkdir(parents=True, exist_ok=True)
    wanted = sorted({p for p in packages if _env_version(p) is None})
    installed: list[str] = []
    for _ in range(10):
        if not wanted:
            break
        run(install_command(target, wanted), check=True)
        installed += wanted
        wanted = unmet_requirements(target)
    shadowing = sorted(_canonical(d.metadata["Name"])
                       for d in metadata.distributions(path=[str(target)])
                       if _env_version(d.metadata["Name"]) is not None)
    if wanted or shadowing:
        raise SystemExit(f"run_upstream_tests: {str(target)!r}: still unmet {wanted}, or "
                         f"shadowing this environment's {shadowing}")
    return installed


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("path", type=Path, help="upstream Kubric's test/ folder (or checkout)")
    parser.add_argument("--extra-path", action="append", default=[],
                        help="folder added to PYTHONPATH (e.g. holding traitlets, pyquaternion)")
    parser.add_argument("--install-deps", type=Path, metavar="DIR", default=None,
                        help="install the upstream tests' imports this environment lacks into "
                             "DIR (never numpy or anything else it has) and add DIR to the path")
    parser.add_argument("-k", dest="keyword", default=None, help="pytest -k expression")
    parser.add_argument("--show-passed", action="store_true", help="list passed tests too")
    args = parser.parse_args(argv)
    source = _find_test_dir(args.path.resolve())
    if args.install_deps is not None:
        install_deps(args.install_deps.resolve())
        args.extra_path.append(args.install_deps)

    with tempfile.TemporaryDirectory(prefix="kubric_upstream_tests_") as tmp:
        work = Path(tmp) / "test"
        shutil.copytree(source, work, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        (Path(tmp) / "pytest.ini").write_text("[pytest]\n")
        junit = Path(tmp) / "report.xml"
        cmd = [sys.executable, "-m", "pytest", str(work), "-q", "-p", "no:cacheprovider",
               "-c", str(Path(tmp) / "pytest.ini"), "--rootdir", tmp,
               "--continue-on-collection-errors", f"--junitxml={junit}", "--tb=no"]
        if args.keyword:
            cmd += ["-k", args.keyword]
        env = dict(os.environ)
        extra = [str(Path(p).resolve()) for p in args.extra_path]
        env["PYTHONPATH"] = os.pathsep.join(extra + [env.get("PYTHONPATH", "")]).strip(os.pathsep)
        subprocess.run(cmd, cwd=tmp, env=env, stdout=subprocess.DEVNULL, check=False)
        if not junit.exists():
            raise SystemExit("run_upstream_tests: pytest wrote no report (is pytest installed in "
                             f"{sys.executable}?)")
        outcomes, broken = _outcomes(junit)

    not_collected = {}
    for module, message in sorted(broken.items()):
        file = source / (module.split(".")[-1] + ".py") if not module.endswith(".py") \
            else source / Path(module).name
        n = count_tests_in_source(file.read_text()) if file.is_file() else 0
        not_collected[file.name] = (n, message or "import failed")

    counts = Counter(outcomes.values())
    for test_id, outcome in sorted(outcomes.items()):
        if outcome != "passed" or args.show_passed:
            print(f"{outcome:8s} {test_id}")
    for name, (n, message) in not_collected.items():
        print(f"{'import':8s} {name}: {n} tests not collected ({message})")
    total = sum(counts.values()) + sum(n for n, _ in not_collected.values())
    print(f"collected {sum(counts.values())}: " + ", ".join(
        f"{counts[k]} {k}" for k in ("passed", "failed", "error", "skipped") if counts[k]))
    print(f"upstream tests: {counts['passed']} of {total} passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
