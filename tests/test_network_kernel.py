"""The map's network at infinite width (bayeshopf.model.network_kernel) against direct references.

The references are written here, apart from the module: a Monte Carlo of the
erf network's hidden units (SciPy's erf) for the kernel; the kernel evaluated
at every pair of phase points and projected by brute force for the harmonic
covariances; SciPy's dense multivariate normal and the dense Gaussian-process
conditional for the collapsed marginal and the predictions.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.special import erf
from scipy.stats import multivariate_normal

from bayeshopf._x64 import ensure_x64
from bayeshopf.errors import FitError
from bayeshopf.features.frame import PlanarFrame
from bayeshopf.inference.settings import CollapsedSettings
from bayeshopf.model import collapsed as cm
from bayeshopf.model import discrepancy as dm
from bayeshopf.model import network_kernel as nk

ensure_x64()

K_HARM = 3
M = 2 * K_HARM + 1
MU = (15.2, 15.9, 16.7, 15.6, 16.4)
SIGN = (1.0, 1.0, 1.0, -1.0, -1.0)
THETA = {"mu0": 17.0, "mu_fold": 15.0, "w_unfold": 0.2, "a2": 2.0 * np.sqrt(2.0),
         "tau_mu": 0.3, "tau_shape": 0.4}


def _spec() -> cm.CollapsedSpec:
    return cm.CollapsedSpec("subcritical", PlanarFrame(np.zeros(2), np.eye(2)), K_HARM, 16.0,
                            1.5, 15.2, 16.4, 1.3, cm.hidden_layer(0), nn_training=(MU, SIGN))


def _theta() -> dict:
    t = dict(THETA)
    beta = -cm.unfolding(t["mu_fold"], t["mu0"], t["w_unfold"], t["mu_fold"])
    t["a2"] = 2.0 * np.sqrt(float(beta))
    return t


def _points(spec, theta, mu, sign, n_phi=cm.N_PHI):
    """Each orbit's network inputs ``(n, N, 3)``, written from the model's definition."""
    r = np.asarray(cm.radius(spec, jnp.asarray(mu), jnp.asarray(sign), theta))
    s = r / np.sqrt(theta["a2"])
    phi = 2 * np.pi * np.arange(n_phi) / n_phi
    m = (np.asarray(mu) - spec.mu_centre) / spec.mu_span
    return np.stack([s[:, None] * np.cos(phi), s[:, None] * np.sin(phi),
                     np.broadcast_to(m[:, None], (len(s), n_phi))], axis=-1)


def _brute_cov(xa, xb):
    """``P k(X_a, X_b) Pᵀ`` over every pair of phase points, ``(n_a M, n_b M)``, recording-major."""
    P = cm.projection(K_HARM)
    k = np.asarray(nk.kernel(xa.reshape(-1, 3), xb.reshape(-1, 3)))
    k = k.reshape(xa.shape[0], xa.shape[1], xb.shape[0], xb.shape[1])
    return np.einsum("kn,anbm,lm->akbl", P, k, P).reshape(xa.shape[0] * M, xb.shape[0] * M)


def _to_coefficient_major(n):
    """Permutation of recording-major ``(i, k)`` indices to coefficient-major ``(k, i)``."""
    return np.array([i * M + k for k in range(M) for i in range(n)])


def _training_cov(X):
    """The training orbits' brute-force covariance, coefficient-major, with the module's jitter.

    Returns the covariance ``(n M, n M)`` and the permutation from recording-major.
    """
    n = X.shape[0]
    perm = _to_coefficient_major(n)
    Kc = _brute_cov(X, X)[np.ix_(perm, perm)]
    for k in range(M):
        blk = slice(k * n, (k + 1) * n)
        Kc[blk, blk] += nk.JITTER * np.mean(np.diag(Kc[blk, blk])) * np.eye(n)
    return Kc, perm


def test_kernel_is_the_erf_networks_covariance():
    rng = np.random.default_rng(5)
    x = rng.normal(0.0, 0.8, (6, 3))
    H = 400_000
    W, b = rng.standard_normal((3, H)), rng.standard_normal(H)
    F = erf(np.sqrt(np.pi) / 2 * (x @ W + b))
    mc = F @ F.T / H
    # the Monte Carlo error of a mean of H products of two numbers in [-1, 1]
    assert np.abs(np.asarray(nk.kernel(x, x)) - mc).max() < 4.0 / np.sqrt(H)


def _kernel_with_weight_variances(xa, xb, var):
    """Williams's erf kernel for weights ``w ~ N(0, diag(var))`` and a unit bias, written here."""
    c = np.pi / 2
    inner = 1.0 + (xa * var) @ xb.T
    na = 1.0 + np.sum(xa * xa * var, axis=-1)
    nb = 1.0 + np.sum(xb * xb * var, axis=-1)
    return 2 / np.pi * np.arcsin(c * inner / np.sqrt((1 + c * na)[:, None] * (1 + c * nb)[None]))


def test_learned_mu_scale_is_the_kernel_of_a_wider_weight_on_mu():
    nu = 2.7
    var = np.array([1.0, 1.0, nu**2])
    rng = np.random.default_rng(8)
    x = rng.normal(0.0, 0.6, (5, 3))
    H = 400_000
    W = rng.standard_normal((3, H)) * np.sqrt(var)[:, None]
    F = erf(np.sqrt(np.pi) / 2 * (x @ W + rng.standard_normal(H)))
    assert np.abs(_kernel_with_weight_variances(x, x, var) - F @ F.T / H).max() < 4.0 / np.sqrt(H)
    # the training factor of a spec with the learned scale is that kernel's projection
    spec = dataclasses.replace(_spec(), nn_mu_scale=None)
    theta = dict(_theta(), nu_mu=nu)
    X = _points(spec, theta, MU, SIGN)
    P = cm.projection(K_HARM)
    k = _kernel_with_weight_variances(X.reshape(-1, 3), X.reshape(-1, 3), var)
    k = k.reshape(X.shape[0], X.shape[1], X.shape[0], X.shape[1])
    dense = np.einsum("kn,anbm,lm->akbl", P, k, P)            # (n, M, n, M)
    L = np.asarray(nk.training_factor(spec, theta, cm.N_PHI)[0])
    h = dm.harmonic_index(K_HARM)
    for kk in range(M):
        C = L[h[kk]] @ L[h[kk]].T
        want = dense[:, kk, :, kk]
        want = want + nk.JITTER * np.mean(np.diag(want)) * np.eye(len(MU))
        np.testing.assert_allclose(C, want, rtol=1e-9, atol=1e-12 * np.abs(want).max())
    # a fixed scale is the same kernel
    fixed = np.asarray(nk.training_factor(dataclasses.replace(_spec(), nn_mu_scale=nu),
                                          _theta(), cm.N_PHI)[0])
    np.testing.assert_allclose(fixed, L, rtol=1e-12, atol=1e-15)
    # and it is not the unit scale's
    L1 = np.asarray(nk.training_factor(_spec(), theta, cm.N_PHI)[0])
    assert np.abs(L1[1] @ L1[1].T - L[1] @ L[1].T).max() > 1e-3 * np.abs(L[1]).max() ** 2


def test_harmonic_kernel_is_the_brute_force_projection():
    spec, theta = _spec(), _theta()
    X = _points(spec, theta, MU, SIGN)
    dense = _brute_cov(X, X)
    s = X[:, 0, 0]                   # φ = 0: (s, 0, μ̃)
    m = X[:, 0, 2]
    C = np.asarray(nk.harmonic_kernel(jnp.asarray(s), jnp.asarray(m), jnp.asarray(s),
                                      jnp.asarray(m), K_HARM, cm.N_PHI))
    h = dm.harmonic_index(K_HARM)
    want = np.zeros_like(dense)
    for k in range(M):                # diagonal in the coefficients, C_h per harmonic
        idx = np.arange(len(MU)) * M + k
        want[np.ix_(idx, idx)] = C[h[k]]
    scale = np.abs(dense).max()
    assert np.abs(dense - want).max() < 1e-12 * scale


def test_latent_columns_give_the_marginal_of_the_dense_gaussian():
    spec, theta = _spec(), _theta()
    rng = np.random.default_rng(1)
    n = len(MU)
    mu, sign = jnp.asarray(MU), jnp.asarray(SIGN)
    Phi = np.asarray(cm.design(spec, mu, sign, theta, training=True)).reshape(n * M, -1)
    sd = np.asarray(cm.prior_sd(spec, theta["tau_mu"], theta["tau_shape"]))
    n_mono = len(cm.MONOMIALS) * len(cm.MU_POWERS)
    d = rng.uniform(1e-4, 4e-4, n * M)
    y = rng.standard_normal(n * M) * 0.3
    # the network's block from the brute-force kernel (with the module's jitter)
    X = _points(spec, theta, MU, SIGN)
    Kc, perm = _training_cov(X)
    inv = np.argsort(perm)
    net = (spec.orbit_scale * theta["tau_shape"]) ** 2 * Kc[np.ix_(inv, inv)]
    mono = Phi[:, :n_mono] * sd[:n_mono]
    cov = mono @ mono.T + net + np.diag(d)
    want = multivariate_normal(np.zeros(n * M), cov).logpdf(y)
    got = float(cm.log_marginal(jnp.asarray(Phi), jnp.asarray(y), jnp.asarray(d), jnp.asarray(sd)))
    assert got == pytest.approx(want, rel=1e-8)
    # the columns at the training orbits computed as at new ones are the factor's
    general = np.asarray(cm.design(spec, mu, sign, theta)).reshape(n * M, -1)
    assert np.abs(general - Phi).max() < 1e-6 * np.abs(Phi).max()


def test_new_orbits_take_the_dense_gaussian_process_conditional():
    spec, theta = _spec(), _theta()
    n = len(MU)
    new_mu, new_sign = np.array([15.4, 16.1, 16.9]), np.array([1.0, -1.0, 1.0])
    X = _points(spec, theta, MU, SIGN)
    Xs = _points(spec, theta, new_mu, new_sign)
    Kcm, perm = _training_cov(X)
    Ks = _brute_cov(X, Xs)[perm]                                  # (n M, n_new M)
    Kss = _brute_cov(Xs, Xs)
    L = np.linalg.cholesky(Kcm)
    z = np.random.default_rng(3).standard_normal(n * M)
    mean = Ks.T @ np.linalg.solve(Kcm, L @ z)                     # E[f* | f = L z]
    var = np.diag(Kss - Ks.T @ np.linalg.solve(Kcm, Ks))
    cols = np.asarray(nk.columns(spec, theta, jnp.asarray(new_mu), jnp.asarray(new_sign),
                                 cm.N_PHI))                       # (n_new, M, n M)
    got_var = np.asarray(nk.conditional_var(spec, theta, jnp.asarray(new_mu),
                                            jnp.asarray(new_sign), cm.N_PHI))
    np.testing.assert_allclose((cols @ z).reshape(-1), mean, atol=1e-7 * np.abs(mean).max())
    np.testing.assert_allclose(got_var.reshape(-1), var, atol=1e-7 * var.max())
    # zero at a training orbit (but for the jitter), more where the orbit is farther
    at = np.asarray(nk.conditional_var(spec, theta, jnp.asarray(MU), jnp.asarray(SIGN),
                                       cm.N_PHI))
    assert at.max() < 10 * nk.JITTER * np.diag(Kss).max()
    far = np.asarray(nk.conditional_var(spec, theta, jnp.asarray([16.9, 19.0]),
                                        jnp.asarray([1.0, 1.0]), cm.N_PHI))
    assert far[1, 1] > far[0, 1] > 0


def test_orbit_is_the_fourier_series_of_the_predicted_coefficients():
    spec, theta = _spec(), _theta()
    rng = np.random.default_rng(4)
    beta = rng.standard_normal((spec.n_basis, 2))
    phi = 2 * np.pi * np.arange(cm.N_PHI) / cm.N_PHI
    for mu, sign in ((15.9, 1.0), (16.2, -1.0)):
        w = np.asarray(cm.orbit(spec, theta, jnp.asarray(beta), mu, sign, jnp.asarray(phi)))
        c = np.asarray(cm.design(spec, jnp.asarray([mu]), jnp.asarray([sign]), theta))[0] @ beta
        np.testing.assert_allclose(cm.projection(K_HARM) @ w, c, atol=1e-10)


def test_spec_round_trips_and_settings_refuse_bad_widths():
    spec = _spec()
    back = cm.CollapsedSpec.from_dict(spec.to_dict())
    assert back.nn_training == spec.nn_training and back.n_map == spec.n_map
    assert back.n_network == len(MU) * M
    assert cm.basis_names(back)[len(cm.MONOMIALS) * len(cm.MU_POWERS)] == "nn_a0_rec0"
    assert dataclasses.replace(spec, nn_training=None, nn_hidden=cm.hidden_layer(4)).n_network == 4
    for bad in (0, -3, True, 2.5):
        with pytest.raises(FitError, match="nn_width"):
            CollapsedSettings(nn_width=bad)
    assert CollapsedSettings(nn_width=None).nn_width is None
    with pytest.raises(FitError, match="nn_mu_scale.*infinite width"):
        CollapsedSettings(nn_width=16, nn_mu_scale=None)
    for bad in (0.0, -1.0, True, float("inf")):
        with pytest.raises(FitError, match="nn_mu_scale: a positive number"):
            CollapsedSettings(nn_width=None, nn_mu_scale=bad)
    for v in (None, 3.0):
        back = cm.CollapsedSpec.from_dict(dataclasses.replace(spec, nn_mu_scale=v).to_dict())
        assert back.nn_mu_scale == v
