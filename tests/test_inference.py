"""MAP, SVI and the NUTS check against parameters planted in synthetic recordings."""

from __future__ import annotations

import numpy as np
import pytest

from bayeshopf.data.synthetic import demo_system
from bayeshopf.inference.nuts import nuts_check
from bayeshopf.model.hybrid import params_from_sites
from bayeshopf.pipeline import FitSettings, fit


@pytest.fixture(scope="module")
def planted():
    return demo_system(seed=11, fast=True)


@pytest.fixture(scope="module")
def result(planted):
    """Default settings but two MAP starts instead of four (stacking needs more than one)."""
    rs, _ = planted
    return fit(rs, "subcritical", seed=0, settings=FitSettings(n_starts=2), progress=False)


@pytest.mark.slow  # legacy core (--core legacy)
def test_map_recovers_mu0_a2(result, planted):
    _, truth = planted
    p = result.map.params
    assert abs(float(p["mu0"]) - truth.mu0) < 0.05
    assert abs(float(p["a2"]) - truth.a2) < 0.05
    assert abs(float(p["mu_fold"]) - truth.mu_fold) < 0.05


@pytest.mark.slow  # legacy core (--core legacy)
def test_map_recovers_linear_map(result, planted):
    """T_L in physical units, up to the normal form's phase (a rotation of u).

    The model's linear part maps u to the frame, ``z = c + L (T_L u + …)``, so
    its physical 2×2 block is ``L T_L``; any rotation of u fits equally well,
    so the rotation-invariant Gram matrix ``M Mᵀ`` is compared.
    """
    _, truth = planted
    p = params_from_sites(result.map.params, result.spec)
    mu_c = result.spec.mu_centre
    M = result.spec.frame.L @ (np.asarray(p.T_L)[:, :2]
                               + result.spec.mu_tilde(mu_c) * np.asarray(p.T_L1))
    G, G_true = M @ M.T, truth.T_L @ truth.T_L.T
    np.testing.assert_allclose(np.sqrt(np.abs(G)), np.sqrt(np.abs(G_true)),
                               rtol=0.1, atol=0.05 * np.sqrt(np.abs(G_true)).max())


@pytest.mark.slow  # legacy core (--core legacy)
def test_svi_intervals_cover_planted_values(result, planted):
    _, truth = planted
    for name, value in (("mu0", truth.mu0), ("a2", truth.a2), ("mu_fold", truth.mu_fold)):
        iv = result.interval(name)
        assert iv.contains(value), f"{name}: {iv} misses {value}"
        assert iv.width < 0.1 * abs(value), f"{name}: interval {iv} uninformative"


@pytest.mark.slow  # legacy core (--core legacy)
def test_posterior_predictive_covers_training_amplitudes(result):
    ppc = result.ppc()
    assert ppc.covered.all(), list(zip(ppc.measured, ppc.predictive, strict=False))
    assert ppc.coeff_coverage > 0.8


@pytest.mark.slow  # legacy core (--core legacy)
def test_curve_band_covers_true_diagram(result, planted):
    _, truth = planted
    d = result.diagram()
    for band, branch in ((d.stable, "stable"), (d.unstable, "unstable")):
        true = truth.amplitude(band.mu, branch)
        ok = np.isfinite(true) & np.isfinite(band.quantiles[0])
        inside = (band.quantiles[0][ok] <= true[ok]) & (true[ok] <= band.quantiles[-1][ok])
        assert inside.mean() > 0.85, f"{branch}: truth inside the 90% band at {inside.mean():.0%}"
    assert d.mu0.contains(truth.mu0) and d.mu_fold.contains(truth.mu_fold)


@pytest.mark.slow  # legacy core (--core legacy)
def test_reproducible_from_seed(planted):
    """Two fits from one seed give identical draws and losses (short runs: only the equality
    of every random choice is checked here, not convergence)."""
    rs, _ = planted
    short = FitSettings(adam_steps=60, lbfgs_steps=20, svi_steps=60, n_draws=50, n_starts=2)
    a = fit(rs, "subcritical", seed=5, settings=short, progress=False)
    b = fit(rs, "subcritical", seed=5, settings=short, progress=False)
    np.testing.assert_array_equal(a.samples["mu0"], b.samples["mu0"])
    np.testing.assert_array_equal(a.map.losses, b.map.losses)


def test_supercritical_refuses_unstable_recordings(planted):
    from bayeshopf.errors import FitError

    rs, _ = planted
    with pytest.raises(FitError, match="unstable"):
        fit(rs, "supercritical", settings=FitSettings.fast(), progress=False)


@pytest.mark.slow  # legacy core (--core legacy)
def test_every_start_is_recorded_and_stacked(result):
    """Default fits run several MAP starts; the posterior is their stacked mixture."""
    starts = result.starts
    assert len(starts) == result.settings.n_starts > 1
    w = np.array([s.weight for s in starts])
    assert np.all(w >= 0) and np.isclose(w.sum(), 1.0)
    # the reported MAP is the start with the lowest negative log joint
    assert float(result.map.losses[-1]) == min(s.map_loss for s in starts)
    assert result.samples["mu0"].shape == (result.settings.n_draws,)
    for s in starts:
        assert np.isfinite(s.lpd) and set(s.map_values) == {"mu0", "a2", "mu_fold"}


@pytest.mark.slow  # legacy core (--core legacy)
def test_supercritical_gauge_fits_a_planted_quintic_system():
    """Data from the quintic gauge (a2 = −3.4, a4 = −1) fitted in the gauge a2 = −1, a4 = −κ.

    The two are the same family with κ = 1/a2² (r scaled by √|a2|, which the
    map absorbs). κ itself trades against the map's change with μ (L1, L2),
    so only μ0 and the fit to the data are checked: with the fast settings
    μ0 = 18.0042 [18.0032, 18.0052] (too narrow an interval to hold 18.0) and
    κ = 0.122 against 1/3.4² = 0.0865.
    """
    from bayeshopf.data.synthetic import hopf_recordings

    rs = hopf_recordings(criticality="supercritical", mu0=18.0, a2=-3.4,
                         stable_mu=(18.3, 18.8, 19.5, 20.3, 21.2, 22.0), seed=3, nonlinear=0.0)
    res = fit(rs, "supercritical", seed=0, settings=FitSettings.fast(), progress=False)
    assert res.interval("mu_fold") is None
    a2 = res.interval("a2")
    assert a2.lo == a2.hi == -1.0
    assert abs(res.interval("mu0").median - 18.0) < 0.01, res.interval("mu0")
    assert res.interval("a4").hi < 0
    assert res.ppc().covered.all()


# --- NUTS chains from the MAP point (bayeshopf.inference.nuts) ---


@pytest.fixture(scope="module")
def check(result):
    return nuts_check(result, num_chains=2, num_warmup=100, num_samples=100, seed=0)


@pytest.mark.slow  # legacy core (--core legacy)
def test_chains_hold_the_planted_normal_form(check, planted):
    """Each chain's 90% intervals of μ0, a2 and the fold hold the planted values."""
    _, truth = planted
    for name, value in (("mu0", truth.mu0), ("a2", truth.a2), ("mu_fold", truth.mu_fold)):
        for c, iv in enumerate(check.per_chain[name]):
            assert iv.lo - 0.02 <= value <= iv.hi + 0.02, f"chain {c} {name}: {iv} vs {value}"


@pytest.mark.slow  # legacy core (--core legacy)
def test_chains_agree_with_svi_where_the_data_identify_the_model(check, result):
    """On well-identified data the chains' μ0 lies inside SVI's band and vice versa."""
    svi = result.interval("mu0")
    pooled = check.pooled["mu0"]
    assert svi.lo < pooled.median < svi.hi, (svi, pooled)
    assert pooled.lo < svi.median < pooled.hi, (svi, pooled)
    lo, hi = check.spread("mu0")
    assert hi - lo < svi.width, (lo, hi, svi)


@pytest.mark.slow  # legacy core (--core legacy)
def test_report_has_rhat_per_latent_site_and_draws_per_chain(check):
    assert {"gap_fold", "gap_hopf", "sigma", "nn_scale", "nn_W0"} <= set(check.rhat)
    assert "mu0" not in check.rhat  # deterministic, not sampled
    assert check.samples["mu0"].shape == (2, 100)
    assert len(check.divergences) == 2
    assert check.mixed == (check.max_rhat < 1.05)
    assert np.isfinite(check.max_rhat)


@pytest.mark.slow  # legacy core (--core legacy)
def test_one_chain_is_refused(result):
    with pytest.raises(ValueError, match="at least 2"):
        nuts_check(result, num_chains=1)


@pytest.mark.slow  # legacy core (--core legacy)
def test_held_out_log_likelihood_of_a_training_recording_is_the_fits_own(result):
    """The held-out density (prediction recomputed at μ_i) against the model's own coeffs_hat."""
    from bayeshopf.diagnostics.comparison import held_out_log_likelihood, pointwise_log_likelihood
    from bayeshopf.model.hybrid import branch_signs

    own = pointwise_log_likelihood(result.samples, result.features)
    signs = branch_signs(result.features.unstable)
    for i in range(result.features.n_recordings):
        ll = held_out_log_likelihood(result.samples, result.spec, result.features, i, signs[i])
        np.testing.assert_allclose(ll, own[:, i], rtol=1e-8, atol=1e-8)
    # on the wrong branch the density collapses
    wrong = held_out_log_likelihood(result.samples, result.spec, result.features, 0, -signs[0])
    assert np.all(wrong < own[:, 0] - 10)
