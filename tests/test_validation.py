"""Leave-one-out bookkeeping (coverage, its binomial probability, errors), on hand-made folds."""

from __future__ import annotations

from math import comb, log

import numpy as np
import pytest

from bayeshopf.validation import HeldOut, HeldOutFold, LeaveOneOut


def _fold(measured: float, lo: float, hi: float, fold_mu: float) -> HeldOutFold:
    p = HeldOut(median=0.5 * (lo + hi), lo=lo, hi=hi, p_exists=1.0,
                mu_fold=(fold_mu, fold_mu - 0.1, fold_mu + 0.1), mu0=(17.0, 16.9, 17.1),
                base_log_median=log(0.5 * (lo + hi)),
                base_log_var=((log(hi) - log(lo)) / 3.29) ** 2, away_sd=0.5)
    return HeldOutFold(name="r", mu=15.0, branch="stable", measured=measured, measured_sd=0.0,
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


def test_maximum_likelihood_is_refused_with_the_reason():
    from bayeshopf.data.synthetic import demo_system
    from bayeshopf.errors import FitError
    from bayeshopf.validation import leave_one_out

    rs, _ = demo_system(seed=0, fast=True)
    with pytest.raises(FitError, match="legacy core"):
        leave_one_out(rs, methods=("bayes", "ml"), progress=False)
    with pytest.raises(FitError, match="no recording named"):
        leave_one_out(rs, folds=["nope"], progress=False)


@pytest.fixture(scope="module")
def one_fold():
    """One fold of :func:`leave_one_out` on the fast demo set (fast settings, both methods).

    The rig's seven-fold study at default settings is the slow test in
    test_wind_tunnel_validation; here one interior stable orbit is held out.
    """
    from bayeshopf.data.synthetic import demo_system
    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.validation import leave_one_out

    rs, truth = demo_system(seed=0, fast=True)
    loo = leave_one_out(rs, "subcritical", seed=0, settings=CollapsedSettings.fast(),
                        folds=["stable_mu16.70"], keep_fits=True, progress=False)
    return rs, truth, loo


def test_leave_one_out_refits_without_the_held_out_recording_and_predicts_it(one_fold):
    import json

    import numpy as np

    rs, truth, loo = one_fold
    name = "stable_mu16.70"
    assert loo.methods == ("bayes", "map") and len(loo.folds) == 1
    (fold,) = loo.folds
    assert (fold.name, fold.mu, fold.branch) == (name, 16.7, "stable")
    assert name not in fold.fit.features.names             # refitted without it
    assert fold.fit.features.n_recordings == len(rs) - 1
    # ... in a frame built without it (the centre and scale of the other orbits)
    from bayeshopf.features.harmonics import extract_harmonics

    full = extract_harmonics(rs).frame
    assert not np.allclose(fold.fit.features.frame.L, full.L, rtol=1e-6, atol=0)
    for m in loo.methods:
        p = fold.predictions[m]
        assert p.lo <= p.median <= p.hi and p.p_exists == 1.0
    # an interior orbit of a planted system: the Bayesian band holds it, and the truth
    assert fold.inside("bayes"), (fold.predictions["bayes"], fold.measured)
    bayes = fold.predictions["bayes"]
    assert bayes.lo <= float(truth.amplitude(16.7, "stable")) <= bayes.hi
    assert fold.relative_error("bayes") < 0.05
    assert bayes.mu_fold[1] < truth.mu_fold + 0.1 and bayes.mu_fold[2] > truth.mu_fold - 0.1
    # the plug-in predicts about the same amplitude as the posterior, and its fold has no width
    plug = fold.predictions["map"]
    assert fold.relative_error("map") < 0.05
    assert abs(plug.median - bayes.median) < 0.03 * bayes.median
    assert plug.mu_fold[1] == plug.mu_fold[0] == plug.mu_fold[2]
    assert abs(plug.mu_fold[0] - truth.mu_fold) < 0.3, plug.mu_fold
    # the band without the model error away from the data: an interior μ has c > 0, and
    # the residual is small against that band
    assert 0 < bayes.away_sd < 1 and 0 < bayes.base_log_var < 0.01
    assert abs(fold.log_residual("bayes")) < 3 * np.sqrt(bayes.base_log_var) + 0.05
    rows = json.loads(json.dumps(loo.table()))
    assert rows[0]["file"] == name and {"bayes", "map"} <= set(rows[0])
    assert all(np.isfinite(rows[0][m]["median"]) for m in loo.methods)
    # the fold's scale away from the recordings is its refit's own (by its σ_rel)
    assert fold.extrapolation_scale == fold.fit.extrapolation_scale == \
        rows[0]["extrapolation_scale"]


def test_plug_in_map_is_the_conditional_mean_and_fits_the_training_orbits(one_fold):
    r"""``β̂ = (ΦᵀD⁻¹Φ + V⁻¹)⁻¹ΦᵀD⁻¹y`` at the MAP's θ̂, computed here without Woodbury."""
    import jax.numpy as jnp
    import numpy as np

    from bayeshopf.model import collapsed as cm
    from bayeshopf.validation import map_coefficients, map_theta, plug_in_coefficients

    _, _, loo = one_fold
    post = loo.folds[0].fit
    theta = map_theta(post)
    beta = map_coefficients(post, theta)
    f, spec = post.features, post.spec
    th = {k: jnp.asarray(v[0]) for k, v in theta.items()}
    sign = jnp.asarray(np.where(f.unstable, -1.0, 1.0))
    control = None if spec.control_scale is None else jnp.asarray(f.control)
    Phis, sd, ds = cm.linear_system(spec, th, jnp.asarray(f.mu), sign, jnp.asarray(f.coeffs),
                                    jnp.asarray(f.coeffs_se), control)
    v = np.asarray(sd) ** 2
    for c in range(2):
        Phi, d = np.asarray(Phis[c]), np.asarray(ds[c])
        y = f.coeffs[:, c].reshape(-1)
        direct = np.linalg.solve(Phi.T @ (Phi / d[:, None]) + np.diag(1 / v), Phi.T @ (y / d))
        assert beta[:, c] == pytest.approx(direct, rel=1e-5, abs=1e-8 * np.abs(direct).max())
    # the plug-in orbit at each training recording is close to its measured orbit
    for i in range(f.n_recordings):
        branch = "unstable" if f.unstable[i] else "stable"
        c = plug_in_coefficients(post, [f.mu[i]], branch)[0]
        err = np.sqrt(np.sum((c - f.coeffs[i]) ** 2) / np.sum(f.coeffs[i][:, 1:] ** 2))
        assert err < 0.05, (f.names[i], err)


def test_plot_leave_one_out(one_fold):
    import numpy as np

    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.plotting.validation import plot_leave_one_out

    rs, _, loo = one_fold
    fig = plot_leave_one_out(loo, extract_harmonics(rs), mu_units="m/s", n_cols=2)
    ax = fig.axes[0]
    gids = {ln.get_gid() for ln in ax.lines}
    assert {"stable-median", "unstable-median", "map-stable", "map-unstable"} <= gids
    assert "MAP plug-in" in [t.get_text() for t in fig.legends[0].get_texts()]
    # the Bayesian folds only (as `fit --leave-one-out` keeps them): no MAP curve, no key
    from dataclasses import replace

    (f,) = loo.folds
    bayes = LeaveOneOut(folds=(replace(f, predictions={"bayes": f.predictions["bayes"]}),),
                        methods=("bayes",))
    fig = plot_leave_one_out(bayes, extract_harmonics(rs), mu_units="m/s", n_cols=2)
    gids = {ln.get_gid() for ln in fig.axes[0].lines}
    assert "stable-median" in gids and not {"map-stable", "map-unstable"} & gids
    assert "MAP plug-in" not in [t.get_text() for t in fig.legends[0].get_texts()]
    # in mm, as `fit --leave-one-out` draws the rig: every amplitude × 1000, the label [mm]
    m = plot_leave_one_out(bayes, extract_harmonics(rs), mu_units="m/s", n_cols=2)
    mm = plot_leave_one_out(bayes, extract_harmonics(rs), mu_units="m/s", n_cols=2,
                            length_unit="mm")
    a_m, a_mm = m.axes[0], mm.axes[0]
    assert "[mm]" in a_mm.get_ylabel() and "[m]" in a_m.get_ylabel()
    assert a_mm.get_ylim()[1] == pytest.approx(1e3 * a_m.get_ylim()[1])
    star = [ln for ln in a_mm.lines if ln.get_marker() == "*"][0]
    assert star.get_ydata()[0] == pytest.approx(1e3 * f.measured)
    med = {ln.get_gid(): ln.get_ydata() for ln in a_m.lines}["stable-median"]
    med_mm = {ln.get_gid(): ln.get_ydata() for ln in a_mm.lines}["stable-median"]
    np.testing.assert_allclose(np.asarray(med_mm, float), 1e3 * np.asarray(med, float))


@pytest.mark.parametrize("k, flagged", [(7, False), (5, False), (4, True), (3, True)])
def test_check_flags_a_coverage_improbable_for_calibrated_bands(k, flagged):
    """``check`` fails below P = 0.05: with 7 folds at 4 of 7 (P = 0.026), not at 5 (0.150)."""
    import json

    from bayeshopf.validation import COVERAGE_ALPHA

    loo = _study(k)
    c = loo.check("bayes")
    assert c["ok"] is (not flagged) and c["alpha"] == COVERAGE_ALPHA == 0.05
    assert (c["inside_ci90"], c["n_folds"]) == (k, 7)
    assert c["coverage_p"] == pytest.approx(_binomial_cdf(k, 7, 0.9), rel=1e-12)
    if flagged:
        assert c["warning"].startswith(f"leave-one-out: {k}/7 held-out amplitudes inside")
        assert f"P = {_binomial_cdf(k, 7, 0.9):.2g}" in c["warning"]
        # how much too narrow: the misses (log residual log 2 at c = 0.5) choose a scale
        # far above the prior's
        assert c["held_out_scale"] > 0.5 and c["prior_scale"] == "0.1"
        assert c["prior_scales"] == [0.1] * 7
        assert f"scale of {c['held_out_scale']:.2g} away from the recordings; the prior's " \
               "is 0.1" in c["warning"]
    else:
        assert c["warning"] is None
    rep = json.loads(json.dumps(loo.report("bayes")))
    assert rep["check"] == c and rep["summary"]["coverage"] == k
    assert [r["bayes"]["inside"] for r in rep["folds"]] == [True] * k + [False] * (7 - k)


def test_check_names_the_scales_each_refit_chose():
    """Refits that chose different scales (by their own relative model error) are all named."""
    from dataclasses import replace

    loo = _study(3)
    mixed = LeaveOneOut(folds=tuple(replace(f, extrapolation_scale=0.7 if i % 2 else 0.1)
                                    for i, f in enumerate(loo.folds)), methods=("bayes",))
    c = mixed.check("bayes")
    assert mixed.extrapolation_scales == (0.1, 0.7)
    assert c["prior_scale"] == "0.1–0.7" and c["prior_scales"] == [0.1, 0.7] * 3 + [0.1]
    assert "the prior's is 0.1–0.7)" in c["warning"]


@pytest.mark.parametrize("s0", [0.0, 0.25])
def test_held_out_scale_recovers_a_planted_scale(s0):
    """``held_out_scale`` maximises ``Π N(r; 0, v + s²c²)``: it recovers the scale the
    residuals were drawn with, and agrees with a brute-force grid of scipy's normal density."""
    import numpy as np
    from scipy.stats import norm

    rng = np.random.default_rng(11)
    n = 400
    v = rng.uniform(0.001, 0.01, n)
    c = rng.uniform(0.2, 1.0, n)
    r = rng.normal(0.0, np.sqrt(v + s0**2 * c**2))
    folds = []
    for ri, vi, ci in zip(r, v, c, strict=True):
        p = HeldOut(median=1.0, lo=0.9, hi=1.1, p_exists=1.0, mu_fold=(14.0,) * 3,
                    mu0=(17.0,) * 3, base_log_median=0.0, base_log_var=vi, away_sd=ci)
        folds.append(HeldOutFold(name="r", mu=15.0, branch="stable", measured=float(np.exp(ri)),
                          measured_sd=0.0, predictions={"bayes": p}))
    s_hat = LeaveOneOut(folds=tuple(folds), methods=("bayes",)).held_out_scale()
    grid = np.linspace(0.0, 1.0, 10001)
    ll = [norm.logpdf(r, 0.0, np.sqrt(v + g**2 * c**2)).sum() for g in grid]
    assert s_hat == pytest.approx(grid[int(np.argmax(ll))], abs=2e-4)
    assert abs(s_hat - s0) < 0.03, s_hat


def test_held_out_scale_skips_folds_without_a_band():
    import numpy as np

    loo = _study(5)
    none = HeldOut(median=np.nan, lo=np.nan, hi=np.nan, p_exists=0.0, mu_fold=(14.0,) * 3,
                   mu0=(17.0,) * 3)
    gone = HeldOutFold(name="x", mu=15.0, branch="unstable", measured=1.0, measured_sd=0.0,
                predictions={"bayes": none})
    assert LeaveOneOut(folds=loo.folds + (gone,), methods=("bayes",)).held_out_scale() == \
        pytest.approx(loo.held_out_scale(), rel=1e-9)
    assert np.isnan(LeaveOneOut(folds=(gone,), methods=("bayes",)).held_out_scale())


def test_log_density_is_the_predictive_density_at_the_measured_amplitude():
    """Draws from N(1, 0.05²) with the branch in 80% of them: log(0.8) + log N(A; 1, 0.05²)."""
    from dataclasses import replace

    from scipy.stats import norm

    rng = np.random.default_rng(0)
    draws = rng.normal(1.0, 0.05, 20000)
    f = _fold(1.03, 0.9, 1.1, 14.6)
    held = replace(f.predictions["bayes"], p_exists=0.8, draws=draws)
    f = replace(f, predictions={"bayes": held})
    want = np.log(0.8) + norm(1.0, 0.05).logpdf(1.03)
    assert f.log_density("bayes") == pytest.approx(want, abs=0.02)
    loo = LeaveOneOut(folds=(f, f), methods=("bayes",))
    assert loo.summary()["bayes"]["log_predictive_density"] == pytest.approx(2 * want, abs=0.04)
    no_draws = replace(f, predictions={"bayes": replace(held, draws=None)})
    assert no_draws.log_density("bayes") == -np.inf
