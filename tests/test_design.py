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
    from bayeshopf.fit_folder import save_hybrid

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


# --- issue 52 item 5: only what exists, gains with their Monte Carlo error, resolution, labels


def test_expected_width_standard_error_matches_the_spread_over_outcome_sets():
    """The reported MC error of the expected width against an independent estimate.

    Conjugate Gaussian as above, prior draws held fixed: the sd of the expected
    width over 300 independent sets of 60 outcomes is the Monte Carlo error the
    reported standard error (of one set) must estimate.
    """
    from bayeshopf.design import _expected_width

    rng = np.random.default_rng(11)
    x = rng.standard_normal(600)
    s, m = 0.7, 60
    afters, ses = [], []
    for _ in range(300):
        pick = rng.integers(0, x.size, m)
        y = x[pick] + s * rng.standard_normal(m)
        logw = -0.5 * ((y[:, None] - x[None]) / s) ** 2
        w = np.exp(logw - logw.max(axis=1, keepdims=True))
        w /= w.sum(axis=1, keepdims=True)
        a, se = _expected_width(x[:, None], np.array([1.0]), w)
        afters.append(a)
        ses.append(se)
    spread = float(np.std(afters, ddof=1))
    assert spread > 0
    assert 0.7 < float(np.mean(ses)) / spread < 1.4
    # the width itself: sqrt(s²/(1+s²)) of the current width (closed form)
    assert float(np.mean(afters)) == pytest.approx(np.sqrt(s**2 / (1 + s**2)), abs=0.05)


def _median_amplitude(fit, mu, branch):
    a = fit.amplitude(np.atleast_1d(mu), branch)
    return np.array([np.nanmedian(c) if np.isfinite(c).any() else np.nan for c in a.T]), \
        np.isfinite(a).mean(axis=0)


def test_design_never_recommends_a_rare_or_small_orbit(demo):
    """``min_p_exists`` and ``min_amplitude`` against the fit's own amplitude draws."""
    mu_fold = float(np.median(demo.samples["mu_fold"]))
    mu0 = float(np.median(demo.samples["mu0"]))
    grid = np.linspace(mu_fold - 0.3, mu0 + 0.3, 17)
    med, p = {}, {}
    for b in ("stable", "unstable"):
        med[b], p[b] = _median_amplitude(demo, grid, b)
    finite = np.concatenate([med["stable"][p["stable"] >= 0.95],
                             med["unstable"][p["unstable"] >= 0.95]])
    # a threshold between two predicted amplitudes, well away from both
    vals = np.sort(finite)
    gaps = np.diff(vals) / vals[1:]
    k = int(np.argmax(np.where((np.arange(gaps.size) > 1) & (np.arange(gaps.size)
                                                               < gaps.size - 2), gaps, 0)))
    a_min = float(0.5 * (vals[k] + vals[k + 1]))
    r = next_measurements(demo, target="fold", candidates=grid, n=6, min_p_exists=0.95,
                          min_amplitude=a_min)
    assert r.min_p_exists == 0.95 and r.min_amplitude == a_min
    rows = {(c.mu, c.branch): c for c in r.candidates}
    n_small = n_rare = 0
    for b in ("stable", "unstable"):
        for j, m in enumerate(grid):
            c = rows[(float(m), b)]
            if p[b][j] < 0.95:
                n_rare += 1
                assert c.skipped and "exists in" in c.skipped, c
            elif med[b][j] < a_min:
                n_small += 1
                assert c.skipped and "below the minimum" in c.skipped, c
            else:
                assert not c.skipped, c
    assert n_small > 0 and n_rare > 0
    assert r.recommended and all(not c.skipped for c in r.recommended)
    assert all(np.interp(c.mu, grid, med[c.branch]) >= a_min for c in r.recommended)
    with pytest.raises(FitError, match="min_amplitude"):
        next_measurements(demo, candidates=grid, min_amplitude=-1.0)


def test_design_gains_carry_their_mc_error_and_are_never_negative(demo):
    mu0 = float(np.median(demo.samples["mu0"]))
    grid = np.linspace(mu0 - 2.0, mu0 - 0.1, 12)
    r = next_measurements(demo, target="hopf", candidates=grid, n=3)
    done = [c for c in r.candidates if not c.skipped]
    assert done
    for c in done:
        assert c.gain >= 0 and c.width_after <= c.width_now
        assert np.isfinite(c.gain_mcse) and c.gain_mcse > 0
        assert (c.note.startswith("no gain")) == (not c.gain > 2 * c.gain_mcse), c
    js = r.to_json()
    assert all("gain_mcse" in row and row["gain"] >= 0 for row in js["candidates"]
               if row["gain"] is not None)


def test_design_resolution_merges_and_flags(demo):
    from bayeshopf.design import BELOW_RESOLUTION

    mu_fold = float(np.median(demo.samples["mu_fold"]))
    mu0 = float(np.median(demo.samples["mu0"]))
    grid = np.arange(mu_fold + 0.1, mu0, 0.05)
    res = 0.4
    r = next_measurements(demo, target="fold", candidates=grid, n=4, resolution=res)
    rec = r.recommended
    assert rec and r.resolution == res
    for i, a in enumerate(rec):
        for b in rec[i + 1:]:
            assert a.branch != b.branch or abs(a.mu - b.mu) > res
    # every candidate not kept but within the resolution of a better kept one is merged
    for c in r.candidates:
        if c.skipped or c in rec:
            continue
        better = [k for k in rec if k.branch == c.branch and abs(k.mu - c.mu) <= res
                  and k.gain >= c.gain]
        if better:
            assert "merged into" in c.note, c
        if not c.note.startswith("no gain") and c.gain < res:
            assert BELOW_RESOLUTION in c.note, c
    # a resolution wider than the grid keeps one candidate per branch
    wide = next_measurements(demo, target="fold", candidates=grid, n=4, resolution=100.0)
    assert len(wide.recommended) <= 2
    assert len({c.branch for c in wide.recommended}) == len(wide.recommended)


def test_design_labels_from_the_fit_and_rank_order(demo):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bayeshopf.plotting.design import plot_design

    name = demo.spec.frame.names[0]
    r = next_measurements(demo, target="diagram", candidates=[16.0, 16.5, 17.0], n=2)
    assert r.amplitude_label == f"peak-to-peak of {name}"
    fig = plot_design(r, demo)
    ax_d, ax_g = fig.axes[0], fig.axes[1]
    assert f"peak-to-peak of {name}" in ax_g.get_ylabel()
    assert f"peak-to-peak of {name}" in ax_d.get_ylabel()
    if name != "z1":
        assert "z1" not in ax_g.get_ylabel() + ax_d.get_ylabel()
    plt.close(fig)
    df = r.to_dataframe()
    n = len(r.recommended)
    assert list(df["rank"][:n]) == list(range(1, n + 1)) and df["rank"][n:].isna().all()


def test_cli_next_skips_merges_and_reports_mc_error(demo, tmp_path, capsys):
    import json

    from bayeshopf.fit_folder import save_hybrid

    out = tmp_path / "fit"
    save_hybrid(demo, out)
    assert main(["next", str(out), "--target", "fold", "--min-p-exists", "0.99",
                 "--min-amplitude", "1e9", "--json", "--no-figure"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["recommended"] == [] and doc["min_amplitude"] == 1e9
    assert all(c["skipped"] for c in doc["candidates"])
    assert main(["next", str(out), "--target", "hopf", "--resolution", "0.5", "--json",
                 "--no-figure"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["resolution"] == 0.5 and doc["recommended"]
    for row in doc["recommended"]:
        assert row["gain"] >= 0 and row["gain_mcse"] > 0 and "note" in row
    assert main(["next", str(out), "--target", "hopf", "--no-figure"]) == 0
    assert "MC se" in capsys.readouterr().out
    assert main(["next", str(out), "--min-p-exists", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--min-p-exists" in err[0]


def test_benchmark_has_the_experimenters_descent():
    """bench_design.py's descent: one Δμ below the lowest recording, branches alternating."""
    import subprocess
    import sys

    sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
    from bench_design import START, STRATEGIES, descent_point

    assert "descent" in STRATEGIES
    low = min(m for m, _ in START)
    assert descent_point(low, 0.3, 0) == pytest.approx((low - 0.3, "unstable"))
    assert descent_point(low - 0.3, 0.3, 1)[1] == "stable"
    r = subprocess.run([sys.executable, str(Path(__file__).parents[1] / "benchmarks"
                                            / "bench_design.py"), "--help"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "--smoke" in r.stdout and "--delta-mu" in r.stdout
