"""pyproject.toml declares what bayeshopf imports, and nothing it does not use."""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from importlib import metadata
from pathlib import Path

REPO = Path(__file__).parents[1]

#: Declared without an import: runtime backends found by name.
USED_WITHOUT_IMPORT = {
    "jaxlib": "jax's compiled backend",
    "h5netcdf": "the engine ArviZ/xarray write and read posterior.nc with",
    "flatbuffers": "jax.export's serialization (inference.cache.compiled_call)",
}


def _declared() -> set[str]:
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    return {re.split(r"[<>=!~\[; ]", d, maxsplit=1)[0].lower() for d in project["dependencies"]}


def _imported_distributions() -> set[str]:
    top = set()
    for path in (REPO / "bayeshopf").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                top |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                top.add(node.module.split(".")[0])
    third_party = top - set(sys.stdlib_module_names) - {"bayeshopf"}
    dists = metadata.packages_distributions()
    missing = sorted(m for m in third_party if m not in dists)
    assert not missing, f"imported but not installed: {missing}"
    return {d.lower() for m in third_party for d in dists[m]}


def test_every_import_is_declared_and_every_declaration_used() -> None:
    declared, imported = _declared(), _imported_distributions()
    assert imported - declared == set(), "imported by bayeshopf/ but not in dependencies"
    assert declared - imported == set(USED_WITHOUT_IMPORT), "declared but never imported"


def test_plain_install_has_no_test_tools() -> None:
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    plain = " ".join(project["dependencies"])
    for tool in ("pytest", "ruff", "nbformat", "nbclient", "ipykernel"):
        assert tool not in plain
    assert "equinox" not in plain and "optimistix" not in plain
