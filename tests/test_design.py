"""``bayeshopf.design`` and ``bayeshopf next``: expected shrinkage of the fold, Hopf and diagram."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from notebook_runs import execute_fast, stored

from bayeshopf.cli.main import main
from bayeshopf.design import _expected_var_ratio, next_measurements, parse_candidates
from bayeshopf.errors import FitError


def test_expected_variance_ratio_matches_the_conjugate_gaussian():
    """Prior x ~ N(0, 1), y = x + N(0, s²): the posterior variance is s²/(1+s²) for every y.

    The importance weights N(y_m; x_s, s²) over prior draws must give that ratio
    (an independent closed form), and uniform weights must give 1.
    """
    rng = np.random.default_rng(3)
    x = rng.standard_normal(4000)
    for s in (0.5, 1.0, 2.0):
        y = x[:800] + s * rng.standard_normal(800)            # outcomes from the predictive
        logw = -0.5 * ((y[:, None] - x[None]) / s) ** 2
        w = np.exp(logw - logw.max(axis=1, keepdims=True))
        w /= w.sum(axis=1, keepdims=True)
        ratio = float(_expected_var_ratio(x[:, None], w)[0])
        assert ratio == pytest.approx(s**2 / (1 + s**2), abs=0.03)
    flat = np.full((5, x.size), 1.0 / x.size)
    assert float(_expected_var_ratio(x[:, None], flat)[0]) == pytest.approx(1.0, abs=1e-9)


def test_candidate_grid_text():
    assert parse_candidates("14:15:0.25") == pytest.approx([14, 14.25, 14.5, 14.75, 15])
    for bad in ("14:15", "15:14:0.1", "14:15:0", "a:b:c"):
        with pytest.raises(ValueError):
            parse_candidates(bad)


@pytest.fixture(scope="module")
def demo(fast_demo_fit):
    return fast_demo_fit[0]


def test_design_ranks_and_skips(demo):
    mu_fold = float(np.median(demo.samples["mu_fold"]))
    below = np.linspace(mu_fold - 3.0, mu_fold - 1.0, 5)       # no LCO on either branch
    inside = np.linspace(mu_fold + 0.3, float(np.median(demo.samples["mu0"])) - 0.3, 9)
    r = next_measurements(demo, target="fold", candidates=np.r_[below, inside], n=3)
    rows = {(c.mu, c.branch): c for c in r.candidates}
    for m in below:
        for b in ("stable", "unstable"):
            c = rows[(float(m), b)]
            assert c.skipped and "exists in" in c.skipped and c.p_exists < 0.9
            assert np.isnan(c.gain)
    assert len(r.recommended) == 3
    gains = [c.gain for c in r.recommended]
    assert gains == sorted(gains, reverse=True)
    assert all(not c.skipped and c.mu > mu_fold for c in r.recommended)
    best = max(c.gain for c in r.candidates if not c.skipped)
    assert r.recommended[0].gain == best
    for c in r.candidates:
        if not c.skipped:
            assert c.width_after == pytest.approx(c.width_now - c.gain)
            assert c.amplitude[1] < c.amplitude[0] < c.amplitude[2]
    df = r.to_dataframe()
    assert len(df) == 2 * 14 and df["rank"].notna().sum() == 3
    only_below = next_measurements(demo, target="hopf", candidates=below)
    assert only_below.recommended == () and all(c.skipped for c in only_below.candidates)


def test_design_diagram_target_and_errors(demo):
    r = next_measurements(demo, target="diagram", candidates=[16.0, 17.0], branch="stable", n=1)
    assert {c.branch for c in r.candidates} == {"stable"} and r.width_now > 0
    with pytest.raises(FitError, match="target"):
        next_measurements(demo, target="flutter")
    with pytest.raises(FitError, match="branch"):
        next_measurements(demo, branch="both-ways")


def test_design_on_a_fit_without_unstable_recordings(demo):
    """Stable recordings only, fitted supercritical: no fold to target, no unstable branch."""
    from dataclasses import replace

    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.posterior import fit_hybrid

    f = demo.features
    stable = f.subset([i for i in range(f.n_recordings) if not f.unstable[i]])
    settings = replace(CollapsedSettings.fast(), num_warmup=150, num_samples=150)
    fit = fit_hybrid(stable, "supercritical", seed=0, settings=settings, progress=False)
    with pytest.raises(FitError, match="fold"):
        next_measurements(fit, target="fold")
    r = next_measurements(fit, target="hopf", n=2)
    assert {c.branch for c in r.candidates} == {"stable"}
    assert len(r.recommended) == 2


def test_cli_next(demo, tmp_path, capsys):
    from bayeshopf.report import save_hybrid

    out = tmp_path / "fit"
    save_hybrid(demo, out)
    assert main(["next", str(out), "--target", "hopf", "--n", "2"]) == 0
    text = capsys.readouterr().out
    assert "Hopf point" in text and text.count("stable") >= 1
    assert (out / "figures" / "next_hopf.png").stat().st_size > 0
    assert main(["next", str(out), "--candidates", "15:14:1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--candidates" in err[0] and "MU_MIN <= MU_MAX" in err[0]
    assert main(["next", str(tmp_path / "nothing")]) == 2


@pytest.mark.slow  # one simulated campaign: 9 NUTS refits (about 5 minutes on one core)
def test_a_designed_campaign_beats_the_sweep_and_stays_calibrated():
    """benchmarks/bench_design.py's campaign on a seed outside the benchmark's (110).

    After 4 added recordings the design's 90% fold interval is narrower than the
    uniform sweep's and still holds the true fold; the Hopf interval holds the
    true Hopf point. (Over seeds 100–109 the benchmark reports the same per seed;
    this is the check that the code path still does it.)
    """
    import sys

    sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
    from bench_design import campaign

    res = campaign(110, steps=4, strategies=("design", "sweep"))
    design, sweep = res["strategies"]["design"][-1], res["strategies"]["sweep"][-1]
    assert design["mu_fold"]["inside"] and design["mu0"]["inside"], design
    assert design["mu_fold"]["width"] < sweep["mu_fold"]["width"], (design, sweep)


NOTEBOOK = Path(__file__).parents[1] / "notebooks" / "05_experimental_design.ipynb"


@pytest.mark.slow  # about 85 s: two fits at fast settings
@pytest.mark.notebooks
def test_campaign_notebook_executes_in_fast_mode(tmp_path, monkeypatch):
    run = execute_fast(NOTEBOOK, tmp_path, monkeypatch, timeout=1200)
    assert not run.errors
    assert "fast mode: True" in run.text and "5 recordings: fold" in run.text
    assert run.n_images >= 2


@pytest.mark.notebooks
def test_stored_campaign_notebook_has_outputs_of_a_full_run():
    """The stored notebook ran at default settings: 4 steps, a figure each, no error."""
    run = stored(NOTEBOOK)
    assert all(c.get("execution_count") for c in run.code), "stored notebook not fully executed"
    assert not run.errors
    assert "fast mode: False" in run.text
    assert sum(f"step {k}: where to measure next" in run.text for k in range(1, 5)) == 4
    assert run.n_images >= 5
