r"""Extra model error away from the recordings, for a fit without the discrepancy.

Predictions only (the fit does not see it), and a user's override
(``CollapsedSettings.extrapolation_scale``). A new recording at μ on branch
``b`` may have its orbit about its centre scaled by ``e^{δ_b(μ)}``, with ``δ_b``
a squared-exponential Gaussian process in μ conditioned on ``δ_b = 0`` at that
branch's training recordings,

.. math::  δ_b(μ) \sim N\big(0, s_e^2\,c_b(μ)^2\big),\quad
           c_b(μ)^2 = 1 - k_*^T K^{-1} k_*,\quad
           k(μ, μ') = e^{-(μ-μ')^2 / 2ℓ^2},

``s_e ~ HalfNormal(S)``, ``ℓ =`` :data:`EXTRAPOLATION_LENGTH` ``· Δμ``, with ``S``
the setting ``extrapolation_scale``; unset, a fit with the discrepancy takes
none (its own process widens the bands away from the recordings) and a fit
without it :data:`EXTRAPOLATION_SCALE`.
"""

from __future__ import annotations

import numpy as np

#: Half-normal scale of the extra model error away from the recordings, ``s_e`` (log
#: orbit size), of a fit without the model discrepancy (module docstring).
EXTRAPOLATION_SCALE = 0.1
#: Its correlation length as a fraction of the recordings' μ span Δμ.
EXTRAPOLATION_LENGTH = 1.0 / 3.0


def extrapolation_sd(mu, mu_data, length: float) -> np.ndarray:
    r"""``c(μ) = √(1 − k_*ᵀ K⁻¹ k_*)``: a unit Gaussian process's sd at μ given zero at ``mu_data``.

    Squared-exponential kernel ``k(μ, μ') = exp(−(μ − μ')²/2ℓ²)``; 0 at every
    point of ``mu_data``, towards 1 far from them, 1 everywhere when ``mu_data``
    is empty (module docstring, "Model error away from the recordings").

    Args:
        mu: Where, shape ``(n_mu,)``.
        mu_data: The branch's training μ (repeats allowed), shape ``(m,)``.
        length: Correlation length ``ℓ`` in units of μ.
    """
    mu = np.atleast_1d(np.asarray(mu, dtype=float))
    x = np.unique(np.asarray(mu_data, dtype=float))
    if x.size == 0:
        return np.ones_like(mu)
    K = np.exp(-0.5 * ((x[:, None] - x[None]) / length) ** 2)
    ks = np.exp(-0.5 * ((x[:, None] - mu[None]) / length) ** 2)          # (m, n_mu)
    explained = np.sum(ks * np.linalg.solve(K + 1e-10 * np.eye(x.size), ks), axis=0)
    return np.sqrt(np.clip(1.0 - explained, 0.0, 1.0))

