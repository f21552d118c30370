"""The package's shape: imports go one way, modules stay small, the research log stays out."""

from __future__ import annotations

import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "bayeshopf"
#: Most lines a module may have.
MAX_LINES = 600
#: Layers from the bottom: a module may import its own layer and those below, never above.
LAYERS = ("data", "features", "model", "inference")
#: Modules below every layer (errors, settings of the runtime, atomic writes).
BASE = ("errors", "_x64", "_xla", "_atomic", "_version", "_preload", "_lazy")


def _modules() -> dict[str, Path]:
    out = {}
    for p in PACKAGE.rglob("*.py"):
        parts = p.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = p
    return out


def _imports(mods: dict[str, Path]) -> dict[str, set[str]]:
    """Each module's imports of other bayeshopf modules, function-local ones included."""
    edges = {}
    for name, path in mods.items():
        deps = set()
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    pkg = name.split(".") if is_pkg else name.split(".")[:-1]
                    pkg = pkg[: len(pkg) - (node.level - 1)]
                    base = ".".join(pkg + ([base] if base else []))
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base
                           for a in node.names]
            for t in targets:
                while t not in mods and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t.startswith("bayeshopf.") and t != name and t in mods:
                    deps.add(t)
        edges[name] = deps
    return edges


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one member (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in edges:
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles_between_modules_or_subpackages():
    edges = _imports(_modules())
    assert _cycles(edges) == []
    top = {}
    for a, deps in edges.items():
        for b in deps:
            pa, pb = a.split(".")[:2], b.split(".")[:2]
            if pa != pb and len(pa) == 2 and len(pb) == 2:
                top.setdefault(".".join(pa), set()).add(".".join(pb))
    mutual = sorted((a, b) for a in top for b in top[a] if a < b and a in top.get(b, ()))
    assert mutual == []


def test_lower_layers_import_nothing_above_them():
    edges = _imports(_modules())
    upward = []
    for a, deps in edges.items():
        la = (a.split(".") + [""])[1]
        if la not in LAYERS:
            continue
        for b in deps:
            lb = (b.split(".") + [""])[1]
            if lb not in LAYERS[: LAYERS.index(la) + 1] and lb not in BASE:
                upward.append(f"{a} -> {b}")
    assert upward == []


def test_no_module_does_several_things_by_size():
    long = {str(p.relative_to(PACKAGE.parent)): n for p in PACKAGE.rglob("*.py")
            if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert long == {}


def test_no_research_log_in_the_code():
    pattern = re.compile(r"Stop [0-9]|\bstop [0-9]+\b|[0-9a-f]{7,40}\b commit|commit [0-9a-f]{7}|"
                         r"docs/inference_core")
    hits = [f"{p.relative_to(PACKAGE.parent)}:{i}" for p in PACKAGE.rglob("*.py")
            for i, line in enumerate(p.read_text().splitlines(), 1) if pattern.search(line)]
    assert hits == []
