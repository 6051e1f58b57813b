"""The asset runtime (``kubric.assets``) works without the offline build tools
(``kubric.asset_tools``): imports go one way, and ``import kubric`` stays light."""

import ast
import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import kubric

PACKAGE = pathlib.Path(kubric.__file__).parent
RUNTIME = sorted(p.stem for p in (PACKAGE / "assets").glob("*.py") if p.stem != "__init__")
TOOLS = sorted(p.stem for p in (PACKAGE / "asset_tools").glob("*.py") if p.stem != "__init__")
HEAVY = ("bpy", "pybullet", "trimesh", "torch", "tensorflow", "jax", "dask", "grain")
#: the runtime's lazy imports of build tools: none (the first-use builds are
#: kubric.asset_tools.ensure_*, the GLB writer is kubric.assets.glb)
ON_DEMAND: set = set()


def _run(code: str) -> dict:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def _loaded(prefix: str) -> str:
    return (f"sorted(m for m in sys.modules if m == {prefix!r} or m.startswith({prefix!r} + '.'))")


def test_the_split_holds_the_expected_modules():
    assert {"asset_source", "archive", "download", "utils", "clevr", "articulated"} <= set(RUNTIME)
    assert {"converter", "physics", "writer", "kubasic", "shapes", "hdri", "gso", "shapenet",
            "polyhaven", "pybullet_collection", "cli"} <= set(TOOLS)
    assert not set(RUNTIME) & set(TOOLS)


def test_runtime_modules_import_without_build_tools():
    mods = ", ".join(f"kubric.assets.{m}" for m in RUNTIME)
    got = _run(f"import json, sys\nimport kubric.assets, {mods}\n"
               f"print(json.dumps({{'tools': {_loaded('kubric.asset_tools')}, "
               f"'heavy': sorted(set({HEAVY!r}) & set(sys.modules))}}))")
    assert got == {"tools": [], "heavy": []}


def test_import_kubric_loads_neither_assets_nor_heavy_packages():
    got = _run("import json, sys\nimport kubric as kb\n"
               f"print(json.dumps({{'assets': {_loaded('kubric.assets')}, "
               f"'tools': {_loaded('kubric.asset_tools')}, "
               f"'heavy': sorted(set({HEAVY!r}) & set(sys.modules))}}))")
    assert got == {"assets": [], "tools": [], "heavy": []}


def test_build_tools_import_light():
    mods = ", ".join(f"kubric.asset_tools.{m}" for m in TOOLS)
    got = _run(f"import json, sys\nimport {mods}\n"
               f"print(json.dumps(sorted(set({HEAVY!r}) & set(sys.modules))))")
    assert got == []


def _tool_imports(tree):
    """(enclosing top-level function or None, line) of every import of kubric.asset_tools."""
    found = []

    def visit(node, func):
        for child in ast.iter_child_nodes(node):
            inner = func
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)) and func is None:
                inner = child.name
            names = []
            if isinstance(child, ast.Import):
                names = [a.name for a in child.names]
            elif isinstance(child, ast.ImportFrom) and child.module:
                names = [child.module] + [f"{child.module}.{a.name}" for a in child.names]
            if any(n == "kubric.asset_tools" or n.startswith("kubric.asset_tools.")
                   for n in names):
                found.append((func, child.lineno))
            visit(child, inner)

    visit(tree, None)
    return found


@pytest.mark.parametrize("module", ["__init__", *RUNTIME])
def test_runtime_imports_build_tools_only_lazily_for_on_demand_builds(module):
    tree = ast.parse((PACKAGE / "assets" / f"{module}.py").read_text())
    for func, line in _tool_imports(tree):
        assert func is not None, f"kubric/assets/{module}.py:{line} imports build tools at import"
        assert (module, func) in ON_DEMAND, (
            f"kubric/assets/{module}.py:{line}: {func}() imports kubric.asset_tools; only the "
            f"on-demand builds {sorted(ON_DEMAND)} may")


def test_the_import_scan_sees_imports():
    """The scan above finds module-level and nested imports (so its silence means something)."""
    tree = ast.parse("import kubric.asset_tools.writer\n"
                     "def f():\n    if 1:\n        from kubric.asset_tools import physics\n"
                     "from kubric import asset_tools\n")
    assert _tool_imports(tree) == [(None, 1), ("f", 4), (None, 5)]


def test_a_worker_opens_and_extracts_a_built_source_with_the_runtime_only(tmp_path):
    from kubric.asset_tools import ensure_kubasic

    source_dir = ensure_kubasic().manifest_path.parent  # built (if needed) here, with the build tools
    scratch = tmp_path / "cache"
    got = _run("import json, os, sys\n"
               f"os.environ['KUBRIC_CACHE_DIR'] = {str(scratch)!r}\n"
               "from kubric.assets import AssetSource\n"
               f"src = AssetSource({str(source_dir)!r})\n"
               "cube = src.create('cube', scale=0.7)\n"
               "files = [cube.render_filename, cube.simulation_filename]\n"
               f"print(json.dumps({{'tools': {_loaded('kubric.asset_tools')}, "
               "'exist': [os.path.isfile(f) for f in files], "
               "'under_cache': [f.startswith(" + repr(str(scratch)) + ") for f in files], "
               "'bounds': [list(map(float, b)) for b in cube.bounds]}))")
    assert got["tools"] == []
    assert got["exist"] == [True, True] and got["under_cache"] == [True, True]
    assert np.allclose(got["bounds"], [[-0.5] * 3, [0.5] * 3], atol=1e-6)  # KuBasic: unit cube
