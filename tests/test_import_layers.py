"""The import structure docs/architecture.md promises: no import cycles between kubric modules,
each layer imports only the layers its row of the page's table names (no upward import, not even
inside a function), and that table is :data:`ALLOWED`, row for row."""

import ast
import collections
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"
ABOVE = "all of the above"
#: layer → the kubric layers it may import, lowest layer first ("all of the above": every
#: earlier layer). A layer is a package (``kubric.X``), a top-level module, ``datasets.exports``
#: or ``datasets.exports.hub``. Entry points (kubric, __main__, cli, docgen, demo, workers, safeimport)
#: are not layers: nothing below imports them.
ALLOWED = {
    "errors": set(),
    "faults": set(),
    "extras": {"errors"},
    "core": {"errors"},
    "io": {"core", "errors"},
    "annotations": {"core", "io", "errors"},
    "assets": {"core", "io", "errors"},
    "asset_tools": {"core", "io", "errors", "assets"},
    "randomness": {"core", "errors", "assets"},  # upstream's samplers; CLEVR facts in assets.clevr
    "file_io": {"core", "io", "errors", "annotations", "randomness"},
    "post_processing": {"core", "io", "errors", "annotations", "randomness"},
    "utils": {"core", "io", "errors", "annotations", "randomness"},
    "renderer": {"core", "io", "errors", "assets", "annotations"},
    "simulator": {"core", "io", "errors", "assets"},
    "datasets.exports": {"core", "io", "errors", "faults", "annotations", "assets", "asset_tools"},
    "pipeline": ABOVE,
    "recipes": ABOVE,
    "datasets": {"core", "io", "errors", "faults", "extras", "pipeline"},
    "viewer": {"core", "io", "errors", "extras", "annotations", "pipeline"},
    "datasets.exports.hub": {"core", "io", "errors", "asset_tools", "datasets",
                             "datasets.exports"},
}


def allowed(layer: str) -> set:
    value = ALLOWED[layer]
    return set(list(ALLOWED)[:list(ALLOWED).index(layer)]) if value == ABOVE else value


def _modules() -> dict[str, pathlib.Path]:
    out = {}
    for path in (ROOT / "kubric").rglob("*.py"):
        name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
        out[name.removesuffix(".__init__")] = path
    return out


def _imports(path: pathlib.Path):
    """(target module, line, inside a function) of every kubric import of a file."""
    tree = ast.parse(path.read_text())
    local = {id(n) for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
             for n in ast.walk(f)}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("kubric"):
            names = [f"{node.module}.{a.name}" for a in node.names]
            for target in names:
                yield target, node.module, node.lineno, id(node) in local
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("kubric"):
                    yield a.name, a.name, node.lineno, id(node) in local


def _package(module: str) -> str:
    """The layer of a module: ``kubric.X...`` → X (``datasets.exports`` for the exports)."""
    parts = module.split(".")
    if parts[1:4] == ["datasets", "exports", "hub"]:
        return "datasets.exports.hub"
    if parts[1:3] == ["datasets", "exports"]:
        return "datasets.exports"
    return parts[1] if len(parts) > 1 else ""


def test_no_import_cycles():
    modules = _modules()
    graph = collections.defaultdict(set)
    for name, path in modules.items():
        for target, parent, _, _ in _imports(path):
            resolved = target if target in modules else parent
            if resolved != name and resolved != "kubric" and name != "kubric":
                graph[name].add(resolved)
    state: dict[str, int] = {}
    cycles = []

    def visit(node, stack):
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert not cycles, f"import cycles: {cycles[:3]}"


def test_each_layer_imports_only_what_its_row_allows():
    modules = _modules()
    wrong = []
    for name, path in modules.items():
        source = _package(name)
        if source not in ALLOWED:
            continue
        for target_name, parent, line, _ in _imports(path):
            # `from kubric import assets` names a layer in the target, `from kubric.io import x`
            # in the parent; `from kubric import __version__` names the package itself
            target = _package(target_name if parent == "kubric" else parent)
            if parent == "kubric" and target_name not in modules:
                continue
            if target in (source, "") or target in allowed(source):
                continue
            wrong.append(f"{path.relative_to(ROOT)}:{line}: {source} imports {parent}")
    assert not wrong, "\n".join(wrong)


def test_the_check_sees_imports_inside_functions_and_from_kubric(tmp_path):
    """The scan above finds `from kubric import X` and imports inside functions (its silence
    means something)."""
    path = tmp_path / "m.py"
    path.write_text("from kubric import assets\ndef f():\n    from kubric.asset_tools import x\n")
    assert [(t, p, line, inside) for t, p, line, inside in _imports(path)] == [
        ("kubric.assets", "kubric", 1, False), ("kubric.asset_tools.x", "kubric.asset_tools", 3,
                                                 True)]
    assert "asset_tools" not in allowed("assets") and "randomness" not in allowed("assets")


def doc_table() -> dict:
    """{layer: set of layers or ABOVE} from the page's table "Layers and what they may import"."""
    text = DOC.read_text().split("## Layers and what they may import", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in text.splitlines() if line.startswith("| `kubric")]
    out = {}
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        names = re.findall(r"`kubric\.([\w.]+)`", cells[0])
        imports = cells[-1]
        value = ABOVE if imports == ABOVE else (
            set() if imports == "—" else {v.strip() for v in imports.split(",")})
        for layer in names:
            out[layer] = value
    return out


def test_the_architecture_page_shows_this_table():
    table = doc_table()
    assert list(table) == list(ALLOWED), "the page's rows, in order, are ALLOWED's layers"
    for layer, value in ALLOWED.items():
        assert table[layer] == value, (layer, table[layer], value)


def test_the_exports_load_without_the_packer_or_the_pipeline():
    """kubric.datasets resolves its names lazily, so a recipe importing an export (nerf, lasr)
    does not load the packer or the pipeline through the package's __init__."""
    import subprocess
    import sys

    code = ("import sys, kubric.datasets.exports.nerf, kubric.datasets.exports.lasr, "
            "kubric.datasets.exports.tapvid; print(sorted(m for m in sys.modules if "
            "m.startswith(('kubric.pipeline', 'kubric.recipes', 'kubric.datasets.packer', "
            "'kubric.datasets.source'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]"
    from kubric.datasets import load, pack  # the names still resolve
    assert callable(load) and callable(pack)
