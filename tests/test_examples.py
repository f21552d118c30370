"""The quick-start example script and notebook run end to end (in their fast mode).

Every example and notebook reaches the package through ``import bayeshopf as bh``.
"""

from __future__ import annotations

import ast
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from notebook_runs import built_sources, execute_fast, stored

from bayeshopf.plotting import FIGURE_NAMES

REPO = Path(__file__).resolve().parent.parent
QUICKSTART = REPO / "examples" / "quickstart.py"
NOTEBOOK = REPO / "notebooks" / "01_quickstart.ipynb"
#: Generous: a cold JAX compilation cache on a slow machine.
TIMEOUT_S = 1200

TRUTH = {"mu0": 18.0, "a2": 3.4, "mu_fold": 15.11}
NUMBER = r"(-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)"
INTERVAL_LINE = re.compile(
    rf"^(mu0|a2|mu_fold)\s+{NUMBER}\s+\[\s*{NUMBER},\s*{NUMBER}\]\s+{NUMBER}\s+(yes|NO)\s*$",
    re.MULTILINE,
)


def _fast_env() -> dict:
    env = dict(os.environ)
    env["BAYESHOPF_FAST"] = "1"
    env["MPLBACKEND"] = "Agg"
    return env


@pytest.mark.notebooks
def test_quickstart_script_runs_and_writes_figures(tmp_path):
    out = tmp_path / "figures"
    proc = subprocess.run(
        [sys.executable, str(QUICKSTART), str(out)],
        cwd=tmp_path, env=_fast_env(), capture_output=True, text=True, timeout=TIMEOUT_S,
    )
    assert proc.returncode == 0, f"stdout:\n{proc.stdout[-3000:]}\nstderr:\n{proc.stderr[-3000:]}"

    for name in FIGURE_NAMES:
        path = out / name
        assert path.is_file(), f"{name} not written; found {sorted(os.listdir(out))}"
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    rows = {m[0]: [float(x) for x in m[1:5]] for m in INTERVAL_LINE.findall(proc.stdout)}
    assert set(rows) == set(TRUTH), proc.stdout
    for name, (median, lo, hi, true) in rows.items():
        assert all(math.isfinite(v) for v in (median, lo, hi)), (name, proc.stdout)
        assert lo <= median <= hi, (name, proc.stdout)
        assert true == pytest.approx(TRUTH[name], abs=0.01)
        # fast settings are less converged; the estimate must still be close
        assert median == pytest.approx(TRUTH[name], rel=0.05), (name, proc.stdout)

    assert "fast settings" in proc.stdout
    assert "amplitude at airspeed = 17" in proc.stdout
    for branch in ("stable", "unstable"):
        assert re.search(rf"^\s+{branch}\s+{NUMBER}\s+90% \[", proc.stdout, re.MULTILINE), (
            branch, proc.stdout)


@pytest.mark.notebooks
def test_quickstart_notebook_executes_in_fast_mode(tmp_path, monkeypatch):
    run = execute_fast(NOTEBOOK, tmp_path, monkeypatch, timeout=TIMEOUT_S)
    assert not run.errors, run.errors
    assert "fast mode: True" in run.text
    assert run.n_images >= 5


@pytest.mark.notebooks
def test_stored_notebook_has_outputs_of_a_full_run():
    run = stored(NOTEBOOK)
    assert 'FAST = os.environ.get("BAYESHOPF_FAST", "0") == "1"' in run.code[0].source
    assert not run.errors
    assert all(c.get("execution_count") for c in run.code), "stored notebook not fully executed"
    assert run.n_images >= 5
    assert "fast mode: False" in run.text, "stored outputs must come from a default-settings run"


@pytest.mark.notebooks
@pytest.mark.parametrize("number, name", [("01", "01_quickstart"),
                                          ("02", "02_numerical_examples"),
                                          ("03", "03_wind_tunnel"),
                                          ("04", "04_missing_physics"),
                                          ("05", "05_experimental_design")])
def test_stored_notebook_is_a_full_run_of_its_build_script(number: str, name: str):
    """A stored notebook holds exactly the cells its ``_src`` script writes now, all executed.

    An edit to a build script without a new run fails here: the stored outputs
    would no longer be those of the code shown.
    """
    path = REPO / "notebooks" / f"{name}.ipynb"
    script = REPO / "notebooks" / "_src" / f"build_{number}.py"
    run = stored(path)
    nbformat = pytest.importorskip("nbformat")
    cells = [(c.cell_type, c.source) for c in nbformat.read(path, as_version=4).cells]
    assert cells == built_sources(script), f"{path.name} differs from what {script.name} writes"
    assert all(c.get("execution_count") for c in run.code), "stored notebook not fully executed"
    assert not run.errors
    assert "fast mode: False" in run.text or "fast mode" not in "".join(
        c.source for c in run.code), "stored outputs must come from a default-settings run"


# ------------------------------------------------------------ one way into the package

EXAMPLES = sorted((REPO / "examples").glob("*.py"))
BUILD_SCRIPTS = sorted((REPO / "notebooks" / "_src").glob("build_*.py"))


def _code_of(path: Path) -> str:
    """An example's source, or the code cells a notebook build script writes (magics left out)."""
    if path.parent.name == "examples":
        return path.read_text()
    cells = [src for kind, src in built_sources(path) if kind == "code"]
    return "\n".join(ln for src in cells for ln in src.splitlines() if not ln.startswith("%"))


def bayeshopf_imports(code: str) -> list[str]:
    """The statements of ``code`` that import bayeshopf otherwise than as ``bh``.

    Allowed: ``import bayeshopf as bh``, and ``import bayeshopf.<module>`` that
    only loads a module so that ``bh.<package>.<module>`` reaches it; then the
    name ``bayeshopf`` itself must not be used.
    """
    tree = ast.parse(code)
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "bayeshopf":
            bad.append(f"line {node.lineno}: from {node.module} import ...")
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] != "bayeshopf":
                    continue
                if a.name == "bayeshopf" and a.asname == "bh":
                    continue
                if a.name != "bayeshopf" and a.asname is None:
                    continue
                bad.append(f"line {node.lineno}: import {a.name}"
                           + (f" as {a.asname}" if a.asname else ""))
        elif isinstance(node, ast.Name) and node.id == "bayeshopf":
            bad.append(f"line {node.lineno}: uses the name bayeshopf (bh expected)")
    if not any(isinstance(n, ast.Import) and any(a.name == "bayeshopf" and a.asname == "bh"
                                                  for a in n.names) for n in ast.walk(tree)):
        bad.append("no 'import bayeshopf as bh'")
    return bad


def test_import_rule_catches_the_old_imports():
    assert bayeshopf_imports("import bayeshopf as bh\nbh.fit(1)\n") == []
    assert bayeshopf_imports("import bayeshopf as bh\nimport bayeshopf.plotting.truth\n"
                             "bh.plotting.truth.plot_diagram_vs_truth(1, 2)\n") == []
    assert bayeshopf_imports("import bayeshopf as bh\n"
                             "from bayeshopf.posterior import fit_hybrid\n") == [
        "line 2: from bayeshopf.posterior import ..."]
    assert bayeshopf_imports("import bayeshopf\nbayeshopf.fit(1)\n") == [
        "line 1: import bayeshopf", "line 2: uses the name bayeshopf (bh expected)",
        "no 'import bayeshopf as bh'"]
    assert bayeshopf_imports("import bayeshopf as bh\nimport bayeshopf.plotting as bp\n") == [
        "line 2: import bayeshopf.plotting as bp"]


@pytest.mark.parametrize("path", EXAMPLES + BUILD_SCRIPTS, ids=lambda p: p.name)
def test_examples_and_notebooks_import_bayeshopf_as_bh(path: Path):
    if path.parent.name != "examples":
        pytest.importorskip("nbformat")
    assert bayeshopf_imports(_code_of(path)) == []
    assert "configure_xla_cpu" not in _code_of(path)   # bh.fit sets JAX's CPU flags itself
