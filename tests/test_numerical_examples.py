"""The paper's Section 4 reproduced blind: Van der Pol and the 3-DOF aerofoil.

One default-settings fit of each simulated experiment
(:mod:`bayeshopf.simulators.truth`) on the collapsed core
(:func:`bayeshopf.posterior.fit_hybrid`), started from data-driven values, never
from the truth. The 3-DOF fit's intervals must hold the simulator's Hopf point
and fold, and the held-out orbits must lie in the 90% predictive bands; the Van
der Pol fit's μ0 interval must hold 0. (a2 is not checked: under the default
curved unfolding it is not the linear unfolding's 2√(μ0 − μ_SN).) The two
default-settings fits take minutes: those tests are marked ``slow``
(``pytest -m slow``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from notebook_runs import execute_fast

from bayeshopf.features.frame import PlanarFrame
from bayeshopf.features.harmonics import extract_harmonics
from bayeshopf.inference.collapsed import CollapsedSettings
from bayeshopf.posterior import fit_hybrid
from bayeshopf.simulators.truth import (
    amplitude_truth,
    flutter_experiment,
    held_out_check,
    vanderpol_experiment,
)

#: The simulator's values (continuation), to 4 decimals.
FLUTTER_MU0, FLUTTER_FOLD = 18.2747, 14.9362


@pytest.fixture(scope="module")
def flutter():
    rs, truth = flutter_experiment(seed=0)
    return rs, truth, fit_hybrid(rs, "subcritical", seed=0, settings=CollapsedSettings(),
                                 progress=False)


@pytest.fixture(scope="module")
def vanderpol():
    rs, truth = vanderpol_experiment(seed=0)
    return rs, truth, fit_hybrid(rs, "supercritical", seed=0, settings=CollapsedSettings(),
                                 progress=False)


def test_flutter_truth_is_the_papers():
    _, truth = flutter_experiment(seed=0, fast=True)
    assert truth.mu0 == pytest.approx(FLUTTER_MU0, abs=1e-3)
    assert truth.mu_fold == pytest.approx(FLUTTER_FOLD, abs=1e-3)
    assert truth.a2 == pytest.approx(3.654, abs=2e-3)  # the paper's 3.65
    assert truth.criticality == "subcritical"
    # offsets are drawn from the seed, small next to the orbits
    assert abs(truth.offsets["h"]) < 5e-3 and abs(truth.offsets["alpha"]) < 0.025


def test_amplitude_truth_matches_newton_corrected_orbits():
    _, truth = flutter_experiment(seed=0, fast=True)
    amp = amplitude_truth(truth.diagram)
    for mu, branch in truth.held_out + truth.plan:
        exact = truth.exact_amplitude(mu, branch)
        assert float(amp(mu, branch)) == pytest.approx(exact, rel=1e-4), (mu, branch)
    # square-root ends: zero at the Hopf point, nan past the ends of a branch
    assert float(amp(truth.mu0, "unstable")) == pytest.approx(0.0, abs=1e-9)
    assert np.isnan(amp(truth.mu_fold - 0.01, "stable"))
    assert np.isnan(amp(truth.mu0 + 0.01, "unstable"))
    assert np.all(np.isfinite(amp(np.array([15.0, 19.0]), "stable")))


def test_harmonic_features_of_orbits_that_miss_the_mean_centre():
    """The 18 m/s unstable orbit does not encircle the mean of the orbit means.

    The collapsed core's time-Fourier features need no centre inside the orbits:
    the frame keeps the mean centre and every recording's peak-to-peak (4
    harmonics, 1% noise) is the simulator's within 1%.
    """
    rs, truth = flutter_experiment(seed=0, fast=True)
    orbits = [r.planar(rs.planar) for r in rs]
    mean = PlanarFrame.from_orbits(orbits).centre
    feats = extract_harmonics(rs, n_harmonics=4)
    np.testing.assert_allclose(feats.frame.centre, mean)
    # the smallest orbit lies entirely on one side of that centre in pitch
    small = min(orbits, key=lambda o: np.ptp(o[:, 1]))
    assert small[:, 1].min() > mean[1] or small[:, 1].max() < mean[1]
    exact = np.array([truth.exact_amplitude(r.mu, r.branch) for r in rs])
    np.testing.assert_allclose(feats.amplitude, exact, rtol=0.01)
    assert np.all(np.isfinite(feats.coeffs)) and np.all(feats.coeffs_se > 0)


@pytest.mark.slow
def test_flutter_blind_fit_intervals_hold_the_truth(flutter):
    """μ0's 90% interval and the fold's 95% interval hold the simulator's values.

    The fold's 95%, not 90%: over seeds 100–119 its 90% interval held the truth
    in 18/20, the misses by less than 4e-4 m/s, and seed 0's sits at the edge
    (docs/inference_core.md).
    """
    _, truth, result = flutter
    assert result.spec.unfolding == "curved"
    for name, mass in (("mu0", 0.9), ("mu_fold", 0.95)):
        true = getattr(truth, name)
        iv = result.interval(name, mass)
        assert iv.lo <= true <= iv.hi, (name, iv, true)
        # informative, not merely right: narrower than a hundredth of the bistable range
        assert iv.hi - iv.lo < 0.01 * (truth.mu0 - truth.mu_fold), (name, iv)
    # the fit's own checks: the map fits every training orbit to within 5% of its size
    assert all(e["ok"] for e in result.diagnostics["fit"]["orbit_error"])


@pytest.mark.slow
def test_flutter_held_out_orbits_inside_predictive_bands(flutter):
    _, truth, result = flutter
    rows = held_out_check(result, truth)
    assert len(rows) == len(truth.held_out) >= 6
    for r in rows:
        assert r["p_exists"] > 0.9, r
        assert r["inside"], r


@pytest.mark.slow
def test_vanderpol_blind_fit_mu0_interval_holds_zero(vanderpol):
    """The paper's Section 4.1, blind: the 90% interval of μ0 holds 0.

    Seed 0, default settings: 0.0002 [−0.0001, 0.0006] (docs/inference_core.md).
    """
    _, truth, result = vanderpol
    assert result.criticality == "supercritical"
    iv = result.interval("mu0")
    assert iv.lo <= truth.mu0 <= iv.hi, iv
    assert iv.hi - iv.lo < 0.1, iv


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="K = 4 harmonics overstate the relaxation-shaped orbits' "
                   "peak-to-peak by up to 1.9%: 1/5 held out inside (docs/limits.md)")
def test_vanderpol_held_out_orbits_inside_predictive_bands(vanderpol):
    _, truth, result = vanderpol
    rows = held_out_check(result, truth)
    assert len(rows) == len(truth.held_out) == 5
    for r in rows:
        assert r["p_exists"] > 0.9 and r["inside"], r


# ---------------------------------------------------------------- demo, example, notebook 02

REPO = Path(__file__).resolve().parent.parent
NOTEBOOK = REPO / "notebooks" / "02_numerical_examples.ipynb"
EXAMPLE = REPO / "examples" / "numerical_examples.py"


def test_demo_fits_the_simulated_aerofoil(tmp_path, capsys):
    """``bayeshopf demo --fast``: the 3-DOF recordings, fitted, with the simulator's truth."""
    from bayeshopf.cli.main import main

    out = tmp_path / "demo"
    assert main(["demo", "--fast", "--quiet", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "3-DOF aeroelastic aerofoil" in text
    summary = json.loads((out / "summary.json").read_text())
    assert summary["truth"]["mu0"] == pytest.approx(FLUTTER_MU0, abs=1e-3)
    assert summary["truth"]["mu_fold"] == pytest.approx(FLUTTER_FOLD, abs=1e-3)
    # even the fast fit lands within a few tenths of a m/s of the Hopf point and the fold
    for q, true in (("mu0", FLUTTER_MU0), ("mu_fold", FLUTTER_FOLD)):
        assert abs(summary[q]["median"] - true) < 0.3, summary[q]
    assert (out / "figures").is_dir() and any((out / "figures").glob("*.png"))


@pytest.mark.notebooks
def test_numerical_examples_script_runs_in_fast_mode(tmp_path):
    env = {**os.environ, "BAYESHOPF_FAST": "1", "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, str(EXAMPLE), str(tmp_path), "--system", "vanderpol"],
                          env=env, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "held-out:" in proc.stdout and "mu0" in proc.stdout
    assert len(list(tmp_path.glob("vanderpol_*.png"))) == 3


@pytest.mark.slow  # two fast fits and six figures in a fresh kernel: the script test above
# runs the same steps on the Van der Pol example, demo --fast fits the 3-DOF recordings
@pytest.mark.notebooks
def test_numerical_examples_notebook_executes_in_fast_mode(tmp_path, monkeypatch):
    (tmp_path / "notebooks").mkdir()          # run where a notebook sits, as in the repository
    run = execute_fast(NOTEBOOK, tmp_path / "notebooks", monkeypatch)
    assert not run.errors
    assert "fast mode: True" in run.text
    assert run.n_images >= 6
