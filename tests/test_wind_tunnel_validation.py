"""The wind-tunnel recordings: leave-one-out refits, criticality from the data, the example.

Leave-one-out refits all 7 folds at default settings (Bayesian, MAP-only and
maximum-likelihood fits), about 10 minutes on 2 cores: those tests are marked
``slow`` and run with ``pytest -m slow``; the stored notebook 03 holds the
outputs of the same study.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bayeshopf.validation import leave_one_out

REPO = Path(__file__).resolve().parent.parent
CBC_DIR = (REPO / ".." / "shared" / "data" / "flutter_cbc").resolve()
PAPER_FOLD = 14.66


@pytest.fixture(scope="module")
def recordings(cbc_recordings):
    return cbc_recordings


@pytest.fixture(scope="module")
def loo(recordings):
    return leave_one_out(recordings, "subcritical", seed=0, progress=False)


@pytest.mark.slow
def test_bayesian_bands_cover_held_out_recordings_better_than_point_fits(loo):
    """Measured (seed 0, defaults): Bayesian 5/7, MAP plug-in 4/7, maximum likelihood 0/7.

    The two Bayesian misses are extrapolations at the data's edges (the largest
    stable μ, and the unstable LCO nearest the Hopf point). With seven folds,
    5/7 is not evidence that the bands are too narrow (P(X ≤ 5) = 0.150 for
    calibrated 90% bands), while 0/7 of the maximum-likelihood bands is.
    """
    cov = {m: loo.coverage(m) for m in loo.methods}
    assert cov["bayes"] >= 5, cov
    assert cov["bayes"] > cov["ml"] and cov["bayes"] >= cov["map"], cov
    assert loo.coverage_p("bayes") > 0.05 > loo.coverage_p("ml")
    # every held-out stable LCO inside the data range is covered
    for f in loo.folds:
        if f.branch == "stable" and f.mu < 17.3:
            assert f.inside("bayes"), (f.name, f.predictions["bayes"], f.measured)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="issue 4 asks for 6/7 held out inside; measured 5/7 "
                   "(misses: stable 17.3 and unstable 16.5 m/s, the data's edges)")
def test_held_out_coverage_reaches_six_of_seven(loo):
    assert loo.coverage("bayes") >= 6


@pytest.mark.slow
def test_fold_moves_less_across_folds_than_with_maximum_likelihood(loo):
    s = loo.summary()
    assert s["bayes"]["mu_fold_sd"] < s["ml"]["mu_fold_sd"], s
    # the paper's fold, 14.66 m/s, lies in the Bayesian fold interval of 5 of the
    # 7 folds (measured): without the lowest-μ stable recording the fold moves
    # to 14.50 [14.26, 14.64] m/s, and without the unstable 16.5 m/s one to
    # 14.47 [14.30, 14.58]
    inside = [f.predictions["bayes"].mu_fold[1] <= PAPER_FOLD <= f.predictions["bayes"].mu_fold[2]
              for f in loo.folds]
    assert sum(inside) >= 5, [f.predictions["bayes"].mu_fold for f in loo.folds]
    # and every fold's interval overlaps the one of the fit to all 7 (14.53 to 14.74)
    assert all(f.predictions["bayes"].mu_fold[2] >= 14.53 and f.predictions["bayes"].mu_fold[1]
               <= 14.74 for f in loo.folds), [f.predictions["bayes"].mu_fold for f in loo.folds]


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="the paper's fold lies in 5 of the 7 fold intervals, "
                   "not 6: without the stable 14.9 or the unstable 16.5 m/s recording the "
                   "interval ends below 14.66 m/s (14.64 and 14.58)")
def test_paper_fold_lies_in_six_of_seven_fold_intervals(loo):
    inside = [f.predictions["bayes"].mu_fold[1] <= PAPER_FOLD <= f.predictions["bayes"].mu_fold[2]
              for f in loo.folds]
    assert sum(inside) >= 6, [f.predictions["bayes"].mu_fold for f in loo.folds]


@pytest.mark.slow
def test_loo_table_is_json_ready(loo):
    rows = json.loads(json.dumps(loo.table()))
    assert len(rows) == 7
    assert {"bayes", "map", "ml"} <= set(rows[0])
    assert all(np.isfinite(r["bayes"]["median"]) for r in rows)


@pytest.fixture(scope="module")
def auto(cbc_auto):
    """``fit_auto(recordings, seed=0)`` at default settings (conftest: made once, shared with
    test_wind_tunnel)."""
    return cbc_auto


def test_two_orbits_at_one_airspeed_without_any_model(recordings):
    """The model-free part of the criticality verdict, on the collapsed core's features."""
    from bayeshopf.diagnostics.comparison import coexisting_orbits
    from bayeshopf.features.harmonics import extract_harmonics

    pairs = {round(p["mu"], 1): p for p in coexisting_orbits(extract_harmonics(recordings))}
    assert sorted(pairs) == pytest.approx([14.9, 16.5])     # 15.6 and 15.7 m/s are not one μ
    assert set(pairs[16.5]["recordings"]) == {"CBC_stable_v16_5.mat", "CBC_unstable_v16_5.mat"}
    # K = 4 harmonics of the mean orbit (the legacy R(θ) features read 64.2 and 19.5 mm)
    assert pairs[16.5]["amplitudes"] == pytest.approx((0.0637, 0.0194), abs=2e-4)
    assert min(p["separation"] for p in pairs.values()) > 10


@pytest.mark.slow  # legacy fit_auto at default settings
def test_criticality_from_the_data_is_subcritical(auto):
    """Two orbits at 14.9 and at 16.5 m/s decide it: a supercritical Hopf has one LCO per μ."""
    result, evidence = auto
    assert evidence["preferred"] == "subcritical" and result.criticality == "subcritical"
    assert evidence["decided_by"] == "coexisting orbits"
    # 15.6 and 15.7 m/s are not one airspeed
    pairs = {p["mu"]: p for p in evidence["coexisting"]}
    assert sorted(pairs) == pytest.approx([14.9, 16.5])
    assert set(pairs[16.5]["recordings"]) == {"CBC_stable_v16_5.mat", "CBC_unstable_v16_5.mat"}
    assert pairs[16.5]["amplitudes"] == pytest.approx((0.0642, 0.0195), abs=5e-4)
    assert min(p["separation"] for p in pairs.values()) > 10
    assert "two distinct orbits" in evidence["statement"]
    assert "subcritical" in evidence["statement"]


@pytest.mark.slow  # legacy fit_auto at default settings
@pytest.mark.xfail(strict=True, reason=(
    "issue 4: PSIS-LOO prefers the subcritical model by only 15.8 ± 8.8 in ELPD (1.8 SE; "
    "Pareto k 1.51 and 2.08), and exact refits where k > 0.7 bring it to 0.3 ± 7.7 "
    "(benchmarks/criticality.md): the supercritical model takes the orbits that share an "
    "airspeed (14.9 and 16.5 m/s) for scatter (README, Limits)"))
def test_criticality_elpd_alone_is_clear(auto):
    _, evidence = auto
    assert evidence["elpd_preferred"] == "subcritical"
    assert evidence["elpd_diff"] > 2.0 * evidence["dse"], evidence["statement"]


@pytest.mark.slow  # the same calls as notebook 03 in its fast mode (below)
@pytest.mark.notebooks
def test_wind_tunnel_example_runs_in_fast_mode(tmp_path, recordings):
    env = {**os.environ, "BAYESHOPF_FAST": "1", "MPLBACKEND": "Agg"}
    proc = subprocess.run(
        [sys.executable, str(REPO / "examples" / "wind_tunnel.py"), str(CBC_DIR), str(tmp_path)],
        env=env, capture_output=True, text=True, timeout=1800,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "prefers the subcritical model" in proc.stdout
    summary = json.loads((tmp_path / "wind_tunnel.json").read_text())
    assert set(summary["leave_one_out"]["summary"]) == {"bayes", "map", "ml"}
    for name in ("bifurcation.png", "leave_one_out.png", "actuator.png"):
        assert (tmp_path / "figures" / name).read_bytes()[:4] == b"\x89PNG"


NOTEBOOK = REPO / "notebooks" / "03_wind_tunnel.ipynb"


@pytest.mark.slow  # its calls run by default on smaller problems: fit_auto (above, default
# settings), leave_one_out (test_validation, one fold of the demo set), fit_channel
# (test_channels) and fit_speed (test_speed)
@pytest.mark.notebooks
def test_wind_tunnel_notebook_executes_in_fast_mode(tmp_path, monkeypatch, recordings):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    copy = tmp_path / NOTEBOOK.name  # never execute (or overwrite) the stored notebook
    copy.write_bytes(NOTEBOOK.read_bytes())
    nb = nbformat.read(copy, as_version=4)
    monkeypatch.setenv("BAYESHOPF_FAST", "1")
    monkeypatch.setenv("BAYESHOPF_FLUTTER_CBC", str(CBC_DIR))
    monkeypatch.delenv("MPLBACKEND", raising=False)
    nbclient.NotebookClient(nb, timeout=1800, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.output_type == "error"]
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    assert "fast mode: True" in text and "prefers the subcritical model" in text
    assert sum("image/png" in o.get("data", {}) for o in outputs) >= 4


@pytest.mark.notebooks
def test_stored_wind_tunnel_notebook_has_outputs_of_a_full_run():
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert all(c.get("execution_count") for c in code), "stored notebook not fully executed"
    outputs = [o for c in code for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.output_type == "error"]
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    assert "fast mode: False" in text
    assert sum("image/png" in o.get("data", {}) for o in outputs) >= 4
