"""Leave-one-out bookkeeping (coverage, its binomial probability, errors), on hand-made folds."""

from __future__ import annotations

from math import comb

import pytest

from bayeshopf.validation import Fold, HeldOut, LeaveOneOut


def _fold(measured: float, lo: float, hi: float, fold_mu: float) -> Fold:
    p = HeldOut(median=0.5 * (lo + hi), lo=lo, hi=hi, p_exists=1.0,
                mu_fold=(fold_mu, fold_mu - 0.1, fold_mu + 0.1), mu0=(17.0, 16.9, 17.1))
    return Fold(name="r", mu=15.0, branch="stable", measured=measured, measured_sd=0.0,
                predictions={"bayes": p})


def _study(n_inside: int, n: int = 7) -> LeaveOneOut:
    folds = [_fold(1.0, 0.9, 1.1, 14.6 + 0.01 * i) for i in range(n_inside)]
    folds += [_fold(2.0, 0.9, 1.1, 14.6) for _ in range(n - n_inside)]
    return LeaveOneOut(folds=tuple(folds), methods=("bayes",))


def _binomial_cdf(k: int, n: int, p: float) -> float:
    return sum(comb(n, j) * p**j * (1 - p) ** (n - j) for j in range(k + 1))


@pytest.mark.parametrize("k", [7, 6, 5, 3])
def test_coverage_and_its_binomial_probability(k):
    loo = _study(k)
    assert loo.coverage("bayes") == k
    assert loo.coverage_p("bayes") == pytest.approx(_binomial_cdf(k, 7, 0.9), rel=1e-12)
    s = loo.summary()["bayes"]
    assert s["coverage"] == k and s["n_folds"] == 7
    assert s["coverage_p"] == pytest.approx(loo.coverage_p("bayes"))


def test_five_of_seven_is_not_evidence_of_narrow_bands_but_three_is():
    # 5/7: P = 0.150 under calibrated 90% bands; 3/7: P = 0.003
    assert _study(5).coverage_p("bayes") == pytest.approx(0.1497, abs=1e-4)
    assert _study(3).coverage_p("bayes") < 0.01
    assert _study(7).coverage_p("bayes") == pytest.approx(1.0)


def test_band_edges_count_as_inside_and_errors_are_relative():
    f = _fold(1.1, 0.9, 1.1, 14.6)
    assert f.inside("bayes")
    assert f.relative_error("bayes") == pytest.approx(0.1 / 1.1)
    s = _study(6).summary()["bayes"]
    assert s["max_relative_error"] == pytest.approx(0.5)  # (2.0 − 1.0)/2.0
    assert s["mu_fold_range"] == pytest.approx([14.6, 14.65])


def test_leave_one_out_refits_without_the_held_out_recording_and_predicts_it():
    """One fold of :func:`leave_one_out` on the fast demo set (fast settings, all three methods).

    The rig's seven-fold study at default settings is the slow test in
    test_wind_tunnel_validation; here one interior stable orbit is held out.
    """
    import json

    import numpy as np

    from bayeshopf.data.synthetic import demo_system
    from bayeshopf.pipeline import FitSettings
    from bayeshopf.validation import leave_one_out

    rs, truth = demo_system(seed=0, fast=True)
    name = "stable_mu16.70"
    loo = leave_one_out(rs, "subcritical", seed=0, settings=FitSettings.fast(), folds=[name],
                        keep_fits=True, progress=False)
    assert loo.methods == ("bayes", "map", "ml") and len(loo.folds) == 1
    (fold,) = loo.folds
    assert (fold.name, fold.mu, fold.branch) == (name, 16.7, "stable")
    for m in loo.methods:                 # every fit was made without the held-out recording
        assert name not in fold.fits[m].features.names
        assert fold.fits[m].features.mu.size == len(rs) - 1
        p = fold.predictions[m]
        assert p.lo <= p.median <= p.hi and p.p_exists == 1.0
    # an interior orbit of a planted system: the Bayesian band holds it, and the truth
    assert fold.inside("bayes"), (fold.predictions["bayes"], fold.measured)
    bayes = fold.predictions["bayes"]
    assert bayes.lo <= float(truth.amplitude(16.7, "stable")) <= bayes.hi
    assert fold.relative_error("bayes") < 0.05
    # (fast settings give a fold interval only ~0.002 m/s wide: its median is checked)
    assert abs(bayes.mu_fold[0] - truth.mu_fold) < 0.05, bayes.mu_fold
    # the point fits' folds have no width
    assert fold.predictions["ml"].mu_fold[1] == fold.predictions["ml"].mu_fold[2]
    rows = json.loads(json.dumps(loo.table()))
    assert rows[0]["file"] == name and {"bayes", "map", "ml"} <= set(rows[0])
    assert all(np.isfinite(rows[0][m]["median"]) for m in loo.methods)
