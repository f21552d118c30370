"""Data sets drawn from the collapsed model's prior, against the prior and marginal they follow."""

import jax
import numpy as np
import pytest
from scipy import stats

from bayeshopf._x64 import ensure_x64
from bayeshopf.errors import FitError
from bayeshopf.features.frame import PlanarFrame
from bayeshopf.model import collapsed as cm
from bayeshopf.model import frequency as fm
from bayeshopf.model.prior_predictive import draw_data

ensure_x64()

K = 2
MU = np.array([15.0, 15.5, 16.0, 16.5, 17.0, 15.2, 15.8, 16.5])
SIGN = np.array([1, 1, 1, 1, 1, -1, -1, -1], float)
N_DRAWS = 150


def _spec(discrepancy=True):
    q = ((0.0, 1.0, 0.2, 1.0, 0.2), (0.0, 0.6, 0.1, 0.6, 0.1)) if discrepancy else None
    return cm.CollapsedSpec("subcritical", PlanarFrame(np.zeros(2), np.eye(2)), K, 16.0, 2.0,
                            15.0, 16.5, 1.0, cm.hidden_layer(6), omega_centre=15.0,
                            discrepancy_scale=q)


@pytest.fixture(scope="module")
def draws():
    spec = _spec()
    rng = np.random.default_rng(1)
    se = rng.uniform(0.005, 0.03, (MU.size, 2, 2 * K + 1))
    omega_se = rng.uniform(0.001, 0.01, MU.size)
    keys = jax.random.split(jax.random.PRNGKey(7), N_DRAWS)
    return spec, se, omega_se, [draw_data(spec, MU, SIGN, se, k, omega_se=omega_se) for k in keys]


def test_the_normal_form_follows_its_prior(draws):
    # the gaps' prior written out: μ_SN = μ_min − g_f, μ0 = max(μ_SN, μ_u,max) + g_h,
    # g ~ HalfNormal(Δμ); compared with an independent numpy sample (two-sample KS)
    spec, _, _, ds = draws
    rng = np.random.default_rng(3)
    g_f, g_h = np.abs(rng.normal(0, spec.mu_span, (2, 20000)))
    fold = spec.mu_min - g_f
    mu0 = np.maximum(fold, spec.mu_unstable_max) + g_h
    assert stats.ks_2samp([d.theta["mu_fold"] for d in ds], fold).pvalue > 1e-3
    assert stats.ks_2samp([d.theta["mu0"] for d in ds], mu0).pvalue > 1e-3


def test_the_model_errors_follow_their_priors(draws):
    # σ_rel is sampled as S|z| with the discrepancy (a smooth geometry for NUTS near
    # 0): its draws must still be HalfNormal(S), as η's are HalfNormal(ETA_PRIOR)
    from bayeshopf.model import discrepancy as dm

    _, _, _, ds = draws
    for name, scale in (("sigma_rel", cm.SIGMA_REL_PRIOR), ("eta", dm.ETA_PRIOR)):
        x = np.array([float(d.theta[name]) for d in ds])
        assert stats.kstest(x, stats.halfnorm(scale=scale).cdf).pvalue > 1e-3, name


def test_coefficients_follow_the_collapsed_marginal(draws):
    # each axis's coefficients, flattened as the likelihood flattens them, have
    # the Mahalanobis distance of a Gaussian under the covariance Φ V Φᵀ + D the
    # collapsed likelihood integrates: χ² with n (2K+1) degrees of freedom
    spec, se, _, ds = draws
    n = MU.size * (2 * K + 1)
    m2 = []
    for d in ds:
        theta = {k: np.asarray(v) for k, v in d.theta.items()}
        Phis, sd, dd = cm.linear_system(spec, theta, MU, SIGN, d.coeffs, se)
        for c in range(2):
            Phi, s, v = np.asarray(Phis[c]), np.asarray(sd), np.asarray(dd[c])
            cov = (Phi * s**2) @ Phi.T + np.diag(v)
            y = d.coeffs[:, c].reshape(-1)
            m2.append(y @ np.linalg.solve(cov, y))
    assert stats.kstest(m2, stats.chi2(n).cdf).pvalue > 1e-3


def test_frequencies_follow_their_marginal(draws):
    spec, _, omega_se, ds = draws
    m2 = []
    for d in ds:
        X = np.asarray(fm.frequency_design(spec, MU, SIGN, d.theta))
        s = np.asarray(fm.frequency_prior_sd(spec))
        cov = (X * s**2) @ X.T + np.diag(omega_se**2 + float(d.theta["sigma_omega"]) ** 2)
        e = d.omega - spec.omega_centre
        m2.append(e @ np.linalg.solve(cov, e))
    assert stats.kstest(m2, stats.chi2(MU.size).cdf).pvalue > 1e-3


def test_a_model_without_the_discrepancy_has_no_prior_predictive():
    with pytest.raises(FitError, match="spec: a model with the discrepancy expected"):
        draw_data(_spec(discrepancy=False), MU, SIGN, np.ones((MU.size, 2, 2 * K + 1)),
                  jax.random.PRNGKey(0))


def test_a_design_of_the_wrong_shape_is_refused():
    with pytest.raises(FitError, match="coeffs_se"):
        draw_data(_spec(), MU, SIGN, np.ones((MU.size, 2, 3)), jax.random.PRNGKey(0))
