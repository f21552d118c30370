r"""The map's random-feature network against its infinite-width limit.

The network's columns of ``Φ`` are ``P tanh(W_1ᵀ x + b_1)`` with one fixed draw
``(W_1, b_1) ~ N(0, 1)`` (:func:`~bayeshopf.model.spec.hidden_layer`) and
output weights of prior sd ``ρ τ_s / √H`` (:func:`~bayeshopf.model.collapsed.prior_sd`),
so their prior covariance of the coefficients is a Monte Carlo average over
``H`` units,

.. math::  Φ_{nn} V Φ_{nn}^T = \frac{(ρ τ_s)^2}{H} \sum_h P f_h f_h^T P^T,\qquad
           f_h(x) = \tanh(w_h^T x + b_h),

which tends as ``H → ∞`` to ``(ρ τ_s)^2 P K P^T`` with the arc-tanh network's
kernel ``K(x, x') = E[\tanh(z) \tanh(z')]``, ``(z, z')`` bivariate normal with
variances ``1 + |x|², 1 + |x'|²`` and covariance ``1 + xᵀx'`` (Neal 1996,
*Bayesian Learning for Neural Networks*, ch. 2; Williams 1998, *Computing with
infinite networks*). The reference here is that expectation by two-dimensional
Gauss–Hermite quadrature (numpy), with the inputs
``x = (s cos φ, s sin φ, μ̃)`` computed from the normal form's closed-form radius,
not from the package. The error of one draw is a mean of ``H`` independent
terms, so its root mean square over draws falls like ``1/√H``.
"""

import numpy as np
import pytest

from bayeshopf.features.frame import PlanarFrame
from bayeshopf.model import collapsed as cm

MU0, MU_FOLD, MU_CENTRE, MU_SPAN = 17.0, 14.5, 16.0, 2.0
A2 = 2.0 * np.sqrt(MU0 - MU_FOLD)            # the fold at MU_FOLD: (μ_SN − μ0) = −a2²/4
MU = np.array([15.0, 16.0, 16.5, 17.5, 15.5, 16.5])
SIGN = np.array([1, 1, 1, 1, -1, -1])
RHO, TAU_SHAPE = 0.7, 0.3
N_SEEDS = 200


def _spec(nn_hidden, n_harmonics=3):
    return cm.CollapsedSpec("subcritical", PlanarFrame(np.zeros(2), np.eye(2)), n_harmonics,
                            MU_CENTRE, MU_SPAN, MU_FOLD + 0.5, 16.5, RHO, nn_hidden,
                            unfolding="linear")


def _theta():
    return {"mu0": MU0, "mu_fold": MU_FOLD, "a2": A2}


def _inputs(n_phi=cm.N_PHI):
    """``x = (s cos φ, s sin φ, μ̃)`` at each recording and phase, ``(n_rec n_phi, 3)``."""
    # ṙ = (μ − μ0) r + a2 r³ − r⁵: r² = (a2 ± √(a2² + 4(μ − μ0)))/2, + stable; r_ref = √a2
    s = np.sqrt((A2 + SIGN * np.sqrt(A2**2 + 4 * (MU - MU0))) / 2) / np.sqrt(A2)
    phi = 2 * np.pi * np.arange(n_phi) / n_phi
    m = (MU - MU_CENTRE) / MU_SPAN
    return np.stack([(s[:, None] * np.cos(phi)).ravel(), (s[:, None] * np.sin(phi)).ravel(),
                     np.repeat(m, n_phi)], axis=-1)


def tanh_kernel(x, n_nodes=64):
    """``E[tanh(wᵀx + b) tanh(wᵀx' + b)]`` over ``(w, b) ~ N(0, I)``, by Gauss–Hermite."""
    t, wt = np.polynomial.hermite_e.hermegauss(n_nodes)      # weight exp(−t²/2)
    wt = wt / np.sqrt(2 * np.pi)
    var = 1.0 + np.sum(x * x, axis=1)
    cov = 1.0 + x @ x.T
    K = np.empty_like(cov)
    for i in range(x.shape[0]):
        s1 = np.sqrt(var[i])
        a = cov[i] / s1                                       # z' = a t1 + c t2
        c = np.sqrt(np.clip(var - a**2, 0.0, None))
        f1 = np.tanh(s1 * t)                                  # (n1,)
        f2 = np.tanh(a[:, None, None] * t[:, None] + c[:, None, None] * t[None, :])
        K[i] = np.einsum("a,b,a,jab->j", wt, wt, f1, f2)
    return K


def _blockwise(K, P, n_rec):
    """``P K_ij Pᵀ`` for every pair of recordings, as one ``(n_rec(2K+1))²`` matrix."""
    n_phi = P.shape[1]
    K4 = K.reshape(n_rec, n_phi, n_rec, n_phi)
    return np.einsum("kn,injm,lm->ikjl", P, K4, P).reshape(n_rec * P.shape[0], -1)


@pytest.fixture(scope="module")
def limit():
    """``(ρ τ_s)² P K Pᵀ`` by quadrature."""
    P = cm.projection(3)
    return (RHO * TAU_SHAPE) ** 2 * _blockwise(tanh_kernel(_inputs()), P, MU.size)


def _network_covariances(width, n_seeds):
    """``Φ_nn V Φ_nnᵀ`` of the package's network for ``nn_seed`` 0..n_seeds−1, ``(n_seeds, m, m)``.

    The network's columns of :func:`~bayeshopf.model.collapsed.design` are one per
    unit, so the draws of all seeds go through one call, then are split by seed.
    """
    layers = [cm.hidden_layer(width, s) for s in range(n_seeds)]
    big = _spec((np.concatenate([W for W, _ in layers], axis=1),
                 np.concatenate([b for _, b in layers])))
    n_mono = len(cm.MONOMIALS) * len(cm.MU_POWERS)
    Phi = np.asarray(cm.design(big, MU, SIGN, _theta()))[..., n_mono:]
    Phi = Phi.reshape(-1, n_seeds, width)                     # (n(2K+1), seed, unit)
    sd = np.asarray(cm.prior_sd(_spec(layers[0]), 0.1, TAU_SHAPE))[n_mono:]
    assert sd.shape == (width,)
    return np.einsum("isu,u,jsu->sij", Phi, sd**2, Phi)


def test_quadrature_reference_is_converged():
    # the reference itself: twice the nodes change it by less than 1e-4 of its
    # size, far below the smallest difference asserted below (a few 1e-3)
    x = _inputs(n_phi=8)
    np.testing.assert_allclose(tanh_kernel(x, 64), tanh_kernel(x, 128), atol=5e-5)


def test_network_prior_covariance_tends_to_its_infinite_width_limit(limit):
    norm = np.linalg.norm(limit)
    err, bias = {}, {}
    for width in (16, 256):
        C = _network_covariances(width, N_SEEDS)
        err[width] = np.sqrt(np.mean(np.linalg.norm(C - limit, axis=(1, 2)) ** 2)) / norm
        bias[width] = np.linalg.norm(C.mean(axis=0) - limit) / norm
        # unbiased: the mean over seeds (N_SEEDS · H units) is the limit within its
        # Monte Carlo error, the error of one seed over √N_SEEDS
        assert bias[width] < 3 * err[width] / np.sqrt(N_SEEDS), (width, bias[width], err[width])
    # the seed-to-seed spread falls like 1/√H: a factor √(256/16) = 4 (1/H would be 16,
    # a spread that does not fall 1); over 200 seeds the ratio's own scatter is ±0.3
    assert 3.5 < err[16] / err[256] < 4.5, err
    assert err[256] < 0.15, err
