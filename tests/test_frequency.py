"""The frequency part of the collapsed model, Ω(r, μ), against closed forms."""

import jax
import numpy as np
import pytest

from bayeshopf.model import collapsed as cm
from bayeshopf.model import normal_form


def _spec(omega_centre=15.0):
    return cm.CollapsedSpec(
        criticality="subcritical", frame=None, n_harmonics=2, mu_centre=16.0, mu_span=2.0,
        mu_min=15.0, mu_unstable_max=16.5, orbit_scale=1.0, nn_hidden=cm.hidden_layer(4),
        omega_centre=omega_centre)


def test_frequency_basis_is_the_normal_form_expansion():
    """χ(r̃², μ̃) = [1, μ̃, r̃², r̃⁴]: ω0 + ω1 μ̃ + b1 r̃² + b2 r̃⁴."""
    x = np.asarray(cm.frequency_basis(np.array([0.5, 2.0]), np.array([-0.25, 0.5])))
    np.testing.assert_allclose(x, [[1, -0.25, 0.5, 0.25], [1, 0.5, 2.0, 4.0]])


def test_frequency_draws_have_the_bayesian_regression_moments():
    """draw_frequency's draws of γ: mean and covariance of the conjugate linear regression."""
    spec = _spec()
    theta = {"mu0": 17.0, "mu_fold": 14.8, "a2": 2.0 * np.sqrt(17.0 - 14.8),
             "sigma_omega": 0.05}
    mu = np.array([15.2, 15.8, 16.4, 17.0, 15.4, 16.2])
    sign = np.array([1, 1, 1, 1, -1, -1.0])
    r2 = np.asarray(normal_form.lco_radius(mu, theta["mu0"], theta["a2"], sign)) ** 2 / theta["a2"]
    X = np.stack([np.ones_like(r2), (mu - 16.0) / 2.0, r2, r2**2], axis=1)
    rng = np.random.default_rng(0)
    se = np.full(mu.size, 0.02)
    omega = 15.0 + X @ np.array([0.1, 0.3, -0.2, 0.05]) + 0.05 * rng.standard_normal(mu.size)
    # closed form: γ | ω ~ N(S Xᵀ D⁻¹ (ω − ω̄), S), S = (Xᵀ D⁻¹ X + V⁻¹)⁻¹
    D = se**2 + theta["sigma_omega"] ** 2
    V = (cm.FREQUENCY_SCALE * 15.0) ** 2
    S = np.linalg.inv(X.T @ (X / D[:, None]) + np.eye(4) / V)
    mean = S @ X.T @ ((omega - 15.0) / D)
    keys = jax.random.split(jax.random.PRNGKey(1), 4000)
    draws = np.asarray(jax.jit(jax.vmap(
        lambda k: cm.draw_frequency(spec, theta, mu, sign, omega, se, k)))(keys))
    sd = np.sqrt(np.diag(S))
    assert np.all(np.abs(draws.mean(0) - mean) < 4 * sd / np.sqrt(4000)), (draws.mean(0), mean)
    np.testing.assert_allclose(np.cov(draws.T), S, atol=0.1 * np.max(np.diag(S)))


def test_frequency_is_nan_where_the_branch_does_not_exist():
    spec = _spec()
    theta = {"mu0": 17.0, "mu_fold": 14.8, "a2": 2.0 * np.sqrt(2.2)}
    f = np.asarray(cm.frequency(spec, theta, np.zeros(4), np.array([14.0, 16.0, 18.0]), -1.0))
    assert np.isnan(f[0]) and np.isnan(f[2]) and f[1] == pytest.approx(15.0)
