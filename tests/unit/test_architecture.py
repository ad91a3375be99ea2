"""The package's import map keeps the pipeline's layers (``docs/architecture.md``).

Every ``import`` of an ``fdem`` module, at module level or inside a function, read with
``ast``: a module imports only from its own layer or a lower one, and the import graph has no
circle. The facade (``fdem/__init__.py``) and the command line sit on top.
"""
from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "fdem"

LAYERS = {  # subpackage (or top-level module) -> floor
    "io": 0, "reference": 0,
    "geometry": 1,
    "mesh": 2,
    "kernels": 3,
    "physics": 4,
    "solve": 5, "blocks": 5,
    "results": 6,
    "workflow": 7,
    "cases": 8, "scene": 8,
    "cli": 9, "__main__": 9, "": 9,
}


def module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path) -> set[str]:
    """Absolute ``fdem...`` names imported by a file (relative imports resolved)."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.split(".")[0] == "fdem"}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] == "fdem":
                found |= {f"{mod}.{a.name}" for a in node.names} | {mod}
    return found


def graph() -> dict[str, set[str]]:
    files = {module_name(p): p for p in PACKAGE.rglob("*.py")}

    def resolve(name: str) -> str | None:
        while name and name not in files:
            name = name.rpartition(".")[0]
        return name or None

    edges = {}
    for mod, path in files.items():
        targets = {resolve(t) for t in imports_of(path)}
        edges[mod] = {t for t in targets if t and t != mod and t != "fdem" and not mod.startswith(t + ".")}
    return edges


def layer(module: str) -> int:
    parts = module.split(".")
    return LAYERS[parts[1] if len(parts) > 1 else ""]


def test_every_module_has_a_layer():
    unknown = sorted(m for m in graph() if (m.split(".") + [""])[1] not in LAYERS)
    assert not unknown, f"modules outside the layers of docs/architecture.md: {unknown}"


def test_no_import_goes_up_a_layer():
    upward = sorted(f"{m} (floor {layer(m)}) imports {t} (floor {layer(t)})"
                    for m, ts in graph().items() for t in ts if layer(t) > layer(m))
    assert not upward, "imports from a higher layer:\n" + "\n".join(upward)


def test_no_import_circle():
    edges = graph()
    index, low, stack, on, circles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                circles.append(sorted(group))

    for v in edges:
        if v not in index:
            visit(v)
    assert not circles, f"import circles: {circles}"


def test_every_module_declares_its_public_names():
    missing = sorted(module_name(p) for p in PACKAGE.rglob("*.py")
                     if p.name != "__init__.py" and "__all__" not in p.read_text())
    assert not missing, f"modules without __all__: {missing}"
