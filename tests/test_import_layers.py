"""The import structure docs/architecture.md promises: no import cycles between kubric modules,
and each low layer imports only from the layers below it — except the lazy imports listed here,
each inside a function and with its reason."""

import ast
import collections
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]
#: package → the kubric packages (or top-level modules) it may import
ALLOWED = {
    "errors": set(),
    "randomness": {"core", "errors", "assets"},  # upstream's samplers; CLEVR facts in assets.clevr
    "core": {"errors"},
    "io": {"core", "errors"},
    "annotations": {"core", "io", "errors"},
    "assets": {"core", "io", "errors", "randomness"},
    "renderer": {"core", "io", "errors", "assets", "annotations"},
    "simulator": {"core", "io", "errors", "assets"},
}
#: (importing package, imported package): why an upward import is allowed, inside a function only
LAZY_UPWARD = {
    ("assets", "asset_tools"): "kubric.assets.ensure_* build the generated sources on first use",
}


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
    parts = module.split(".")
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


def test_low_layers_import_only_below_them():
    wrong = []
    for name, path in _modules().items():
        source = _package(name)
        if source not in ALLOWED:
            continue
        for _, parent, line, inside_function in _imports(path):
            target = _package(parent if parent != "kubric" else name)
            if target in (source, "") or target in ALLOWED[source]:
                continue
            if inside_function and (source, target) in LAZY_UPWARD:
                continue
            wrong.append(f"{path.relative_to(ROOT)}:{line}: {source} imports {parent}")
    assert not wrong, "\n".join(wrong)
