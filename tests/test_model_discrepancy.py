"""The model discrepancy (bayeshopf.model.discrepancy) against dense Gaussian references.

The references are written here from the module's equations, with NumPy and
SciPy's dense multivariate normal: the covariance of Δ element by element, the
collapsed marginal ``N(0, ΦVΦᵀ + K + D)``, and the Gaussian-process conditional.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import multivariate_normal

from bayeshopf._x64 import ensure_x64
from bayeshopf.model import collapsed as cm
from bayeshopf.model import discrepancy as dm

ensure_x64()

K_HARM = 2
M = 2 * K_HARM + 1


def _dense_cov(g, x, eta, ell, sigma_rel):
    """Cov(Δ_(i,k), Δ_(j,l)) element by element, from the module docstring."""
    n = g.shape[0]
    h = np.array([0, 1, 2, 1, 2])
    C = np.zeros((n * M, n * M))
    for i in range(n):
        for j in range(n):
            k = eta**2 * np.exp(-0.5 * np.sum((x[i] - x[j]) ** 2) / ell**2)
            for a in range(M):
                smooth = k if h[a] == 1 else 0.0
                C[i * M + a, j * M + a] = g[i, a] * g[j, a] * (smooth + sigma_rel**2 * (i == j))
    return C


def _problem(seed=0, n=5, J=6):
    rng = np.random.default_rng(seed)
    g = np.abs(rng.normal(1.0, 0.3, (n, M)))
    g[:, 0] = 0.0
    x = rng.uniform(0, 2, (n, 2))
    Phi = rng.standard_normal((n * M, J))
    sd = rng.uniform(0.3, 2.0, J)
    se2 = rng.uniform(0.01, 0.05, (n, M))
    return rng, g, x, Phi, sd, se2


def test_coefficient_scale_is_the_rms_harmonic_size():
    c = np.zeros((3, 2, M))
    c[:, 0, 1] = [3.0, 4.0, 0.0]          # a1 of w1
    c[:, 0, K_HARM + 1] = [4.0, 3.0, 0.0]  # b1 of w1: |h1| = 5, 5, 0
    q = dm.coefficient_scale(c)
    assert q[0, 0] == 0.0
    want = np.sqrt(np.mean(np.array([25.0, 25.0, 0.0]) / 2))
    assert q[0, 1] == pytest.approx(want) and q[0, K_HARM + 1] == pytest.approx(want)
    assert q[1].max() == 0.0


def test_latent_columns_give_the_dense_marginal():
    rng, g, x, Phi, sd, se2 = _problem()
    eta, ell, sigma_rel = 0.3, 0.7, 0.05
    y = rng.standard_normal(Phi.shape[0])
    C = np.asarray(dm.latent_columns(jnp.asarray(g), jnp.asarray(x), eta, ell))
    d = np.asarray(dm.independent_variance(g, se2, sigma_rel)).reshape(-1)
    sd_all = np.concatenate([sd, np.ones(C.shape[1])])
    got = float(cm.log_marginal(jnp.asarray(np.hstack([Phi, C])), jnp.asarray(y),
                                jnp.asarray(d), jnp.asarray(sd_all)))
    cov = (Phi * sd**2) @ Phi.T + _dense_cov(g, x, eta, ell, sigma_rel) + np.diag(se2.reshape(-1))
    want = multivariate_normal(np.zeros(y.size), cov).logpdf(y)
    # the jitter of the unit kernel's factor is 1e-10 of its diagonal
    assert got == pytest.approx(want, abs=1e-6)


def test_conditional_is_the_noise_free_gaussian_process_conditional():
    rng, g, x, *_ = _problem(seed=1)
    eta, ell = 0.4, 0.9
    z = rng.standard_normal((g.shape[0] * 2,))          # two smooth coefficients (a1, b1)
    x_new = rng.uniform(0, 2, (3, 2))
    g_new = np.abs(rng.normal(1.0, 0.3, (3, M)))
    mean, var = (np.asarray(a) for a in dm.conditional(jnp.asarray(z), jnp.asarray(g_new),
                                                      jnp.asarray(x), jnp.asarray(x_new), eta, ell))
    # f at the training points, per smooth coefficient, as the latent columns make it
    Kxx = np.exp(-0.5 * np.sum((x[:, None] - x[None]) ** 2, -1) / ell**2)
    L = np.linalg.cholesky(Kxx + dm.JITTER * np.eye(len(x)))
    f = L @ z.reshape(-1, 2)                              # (n, 2): a1, b1
    ks = np.exp(-0.5 * np.sum((x[:, None] - x_new[None]) ** 2, -1) / ell**2)
    w = np.linalg.solve(Kxx + dm.JITTER * np.eye(len(x)), ks)   # (n, 3)
    for j, col in enumerate((1, K_HARM + 1)):
        assert mean[:, col] == pytest.approx(eta * g_new[:, col] * (w.T @ f[:, j]), abs=1e-8)
        v = eta**2 * g_new[:, col] ** 2 * (1 - np.sum(ks * w, axis=0))
        assert var[:, col] == pytest.approx(v, abs=1e-8)
    others = [c for c in range(M) if c not in (1, K_HARM + 1)]
    assert np.all(mean[:, others] == 0) and np.all(var[:, others] == 0)


def test_conditional_at_a_training_point_returns_its_value():
    """At a training orbit the discrepancy is known given z: variance 0, mean η g f."""
    rng, g, x, *_ = _problem(seed=2)
    z = rng.standard_normal((g.shape[0] * 2,))
    mean, var = (np.asarray(a) for a in dm.conditional(jnp.asarray(z), jnp.asarray(g[:2]),
                                                      jnp.asarray(x), jnp.asarray(x[:2]), 0.2, 0.8))
    C = np.asarray(dm.latent_columns(jnp.asarray(g), jnp.asarray(x), 0.2, 0.8))
    delta = (C @ z).reshape(g.shape[0], M)
    assert mean == pytest.approx(delta[:2], abs=1e-6)
    assert np.max(var) < 1e-6 * 0.2**2 * np.max(g) ** 2


def test_far_from_the_recordings_the_variance_returns_to_the_prior():
    rng, g, x, *_ = _problem(seed=3)
    z = rng.standard_normal((g.shape[0] * 2,))
    far = np.array([[50.0, 50.0]])
    g_new = np.ones((1, M))
    mean, var = (np.asarray(a) for a in dm.conditional(jnp.asarray(z), jnp.asarray(g_new),
                                                      jnp.asarray(x), jnp.asarray(far), 0.3, 0.5))
    assert var[0, 1] == pytest.approx(0.09, rel=1e-9) and abs(mean[0, 1]) < 1e-12


@pytest.mark.parametrize("floor", [0.0, 0.5])
def test_scales_follow_the_harmonic_power_of_the_radius(floor):
    """``g = q √((s^{2h} + κ m_h)/((1+κ) m_h))``, ``m_h`` the training mean of ``s^{2h}``:
    ``q s^h / √m_h`` without a floor; the training recordings' mean square is ``q²``."""
    q = np.tile(np.array([0.0, 2.0, 0.5, 2.0, 0.5]), (2, 1))
    s_ref = np.array([0.5, 1.0, 1.5])
    s = np.array([0.2, 2.0])
    g = np.asarray(dm.scales(jnp.asarray(q), jnp.asarray(s), jnp.asarray(s_ref), floor))
    for k, h in enumerate([0, 1, 2, 1, 2]):
        m = np.mean(s_ref ** (2 * h))
        want = q[0, k] * np.sqrt((s ** (2 * h) + floor * m) / ((1 + floor) * m))
        assert g[:, 0, k] == pytest.approx(want, rel=1e-12)
    g_ref = np.asarray(dm.scales(jnp.asarray(q), jnp.asarray(s_ref), jnp.asarray(s_ref), floor))
    assert np.mean(g_ref[:, 0, 1:] ** 2, axis=0) == pytest.approx(q[0, 1:] ** 2, rel=1e-12)
