r"""Model discrepancy: a Gaussian process over the diagram on the orbits' harmonics.

The normal form plus map is never exactly the rig. Following Kennedy & O'Hagan
(2001), the recorded coefficients are the model's plus a discrepancy plus noise,

.. math::  y_{i,c,k} = (Φ_i β_c)_k + Δ_{c,k}(x_i) + ε_{i,c,k},

with ``Δ`` a zero-mean Gaussian process, independent between the frame axes
``c`` and the coefficients ``k`` (``a_0, a_1..a_K, b_1..b_K``), and

.. math::

    \operatorname{Cov}\big(Δ_{c,k}(i), Δ_{c,k}(j)\big) = g_{c,k,i}\, g_{c,k,j}
        \big[η^2 [h_k = 1]\, e^{-|x_i - x_j|^2 / 2ℓ^2} + σ_{rel}^2 [i = j]\big].

* **Where in the diagram**: ``x_i = (μ̃_i, s_i^2 / \overline{s^2})``, with
  ``s_i = r_i / r_ref`` the normal form's radius at recording ``i`` and
  ``\overline{s^2}`` its mean over the training recordings. ``r²`` runs
  continuously from the Hopf point over the unstable branch, through the fold,
  up the stable branch, so orbits that are nearly the same orbit (both sides of
  the fold) share their discrepancy, while a stable and an unstable orbit at
  one μ need not.
* **How large**: ``g_{c,k,i} = q_{c,h} s_i^h / (\overline{s^{2h}})^{1/2}`` for a
  coefficient of harmonic ``h ≥ 1`` (with a floor ``κ``:
  ``q_{c,h} ((s_i^{2h} + κ\overline{s^{2h}}) / ((1 + κ)\overline{s^{2h}}))^{1/2}``,
  :func:`scales`), ``q_{c,h}`` the RMS size of that harmonic's
  coefficients in the training recordings (a data constant, like the orbit
  scale ρ), and ``g = 0`` for ``a_0`` (the centre has its own shift terms in the
  map). Harmonic ``h`` of a weakly nonlinear orbit grows as ``r^h``, so ``η`` is
  a *relative* error of each harmonic, smooth along the branch, and ``σ_rel`` a
  relative error of each recording alone. Both scale with the model's radius,
  never with the observed coefficient, so the likelihood is a density in ``y``.
* **Priors** (stated, informative; discrepancy and the normal form's parameters
  trade off, Brynjarsdóttir & O'Hagan 2014): ``η ~ HalfNormal(`` :data:`ETA_PRIOR` ``)``,
  ``ℓ ~ LogNormal`` (:data:`LENGTH_PRIOR`, in units of ``x``), ``σ_rel ~
  HalfNormal(`` :data:`~bayeshopf.model.collapsed.SIGMA_REL_PRIOR` ``)``.

The smooth part is carried by the fundamental (:data:`SMOOTH_HARMONIC`: the
orbit's size and phase, which place the Hopf point and the fold) and is a
Gaussian process over the diagram's plane, ``x_i = (μ̃_i, s_i^2/\overline{s^2})``;
the independent part ``σ_rel`` is on every harmonic.

``Δ`` is linear and Gaussian, so it is integrated out exactly with the map:
its smooth part is ``C z`` with ``z ~ N(0, I)``, one latent per training
recording and smooth coefficient (:func:`latent_columns`), a few more linear
columns of the design, and its independent part joins the diagonal noise
(:func:`independent_variance`). Given a draw of ``θ``, ``β`` and ``z``, the
discrepancy at new orbits is the Gaussian-process conditional
(:func:`conditional`): the bands of a new measurement widen away from the
recordings, and by as much as the recordings disagree with the model, without a
rule.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

#: Half-normal scale of ``η``, the smooth relative discrepancy of each harmonic.
ETA_PRIOR = 0.05
#: Log-normal prior of ``ℓ`` (median, log-sd), in units of ``x = s²/mean(s²)``.
LENGTH_PRIOR = (0.5, 0.5)
#: The harmonic whose discrepancy is smooth over the diagram (the fundamental: the
#: orbit's size and phase, which place the Hopf point and the fold); every
#: harmonic has the independent relative part ``σ_rel``.
SMOOTH_HARMONIC = 1
#: ``κ``, the default floor of the scales relative to their training mean,
#: ``g ∝ √((s^{2h} + κ\,\overline{s^{2h}}) / ((1 + κ)\,\overline{s^{2h}}))``; 0 makes the
#: discrepancy purely relative (it vanishes with the orbit at the Hopf point).
FLOOR = 0.0
#: Jitter added to the unit kernel's diagonal (a Cholesky factor where two
#: recordings lie at one point of the diagram).
JITTER = 1e-10


def harmonic_index(n_harmonics: int) -> np.ndarray:
    """The harmonic of each coefficient ``[a_0, a_1..a_K, b_1..b_K]``: ``[0, 1..K, 1..K]``."""
    k = np.arange(1, n_harmonics + 1)
    return np.concatenate([[0], k, k])


def coefficient_scale(coeffs) -> np.ndarray:
    """``q_{c,h}`` per frame axis and coefficient, ``(2, 2K+1)``; 0 for ``a_0``.

    The RMS over recordings of ``√((a_h² + b_h²)/2)``: the typical size of one
    coefficient of harmonic ``h``. ``coeffs``: ``(n_rec, 2, 2K+1)``.
    """
    c = np.asarray(coeffs, dtype=float)
    K = (c.shape[-1] - 1) // 2
    mag = np.sqrt(np.mean(0.5 * (c[..., 1:K + 1] ** 2 + c[..., K + 1:] ** 2), axis=0))  # (2, K)
    return np.concatenate([np.zeros((2, 1)), mag, mag], axis=-1)


def scales(q, s, s_ref, floor: float = 0.0):
    """``g_{c,k,i}`` at radii ``s`` (n,), normalised by training radii ``s_ref``, ``(n, 2, 2K+1)``.

    ``floor`` is ``κ`` (:data:`FLOOR`); ``nan`` in ``s`` (no orbit) gives ``nan``.
    """
    q = jnp.asarray(q)
    h = harmonic_index((q.shape[-1] - 1) // 2)
    m = jnp.mean(s_ref[:, None] ** (2 * h[None]), axis=0)                     # (2K+1,)
    rel = jnp.sqrt((s[:, None] ** (2 * h[None]) + floor * m) / ((1 + floor) * m))
    return rel[:, None, :] * q[None]


def coordinate(mu_tilde, s, s_ref):
    """``x = (μ̃, s² / mean(s_ref²))``, ``(n, 2)``: where each orbit lies in the diagram."""
    return jnp.stack([mu_tilde, s**2 / jnp.mean(s_ref**2)], axis=-1)


def kernel(x_a, x_b, eta, ell):
    """``η² exp(−|x_a − x_b|² / 2ℓ²)``, shape ``(n_a, n_b)``, for ``x`` ``(n, 2)``."""
    d2 = jnp.sum((x_a[:, None, :] - x_b[None, :, :]) ** 2, axis=-1)
    return eta**2 * jnp.exp(-0.5 * d2 / ell**2)


def smooth_mask(n_coeffs: int) -> np.ndarray:
    """Which of the ``2K+1`` coefficients carry the smooth part (:data:`SMOOTH_HARMONIC`)."""
    return harmonic_index((n_coeffs - 1) // 2) == SMOOTH_HARMONIC


def unit_factor(x, ell):
    """``L``, the Cholesky factor of the unit kernel ``exp(−|x_i − x_j|²/2ℓ²)`` (+ jitter)."""
    k = kernel(x, x, 1.0, ell)
    return jnp.linalg.cholesky(k + JITTER * jnp.eye(x.shape[0]))


def latent_columns(g, x, eta, ell):
    r"""The smooth discrepancy as linear columns of one frame axis, ``(n M, n S)``.

    With ``f = L z``, ``z ~ N(0, I)`` per smooth coefficient (``S`` of them),
    ``Δ_k(i) = η g_{i,k} f_k(i)`` has the covariance of the module docstring; so
    ``Δ = C z`` with ``C[(i,k), (m,j)] = η g_{i,k} L_{im} [k = j	ext{-th smooth}]``,
    and ``z`` joins the map's coefficients, integrated out (and drawn) with them.

    Args:
        g: Scales ``(n, M)`` of the training recordings.
        x: Their coordinates ``(n, 2)``.
        eta: The discrepancy's scale.
        ell: Its length.
    """
    L = unit_factor(x, ell)                                            # (n, n)
    n, m = g.shape
    sel = np.flatnonzero(smooth_mask(m))                               # (S,)
    E = np.zeros((m, sel.size))
    E[sel, np.arange(sel.size)] = 1.0
    C = eta * g[:, :, None, None] * L[:, None, :, None] * E[None, :, None, :]  # (n, M, n, S)
    return C.reshape(n * m, n * sel.size)


def independent_variance(g, se2, sigma_rel):
    """``se² + σ_c² + (σ_rel g)²``: the diagonal noise of each coefficient, as ``g``."""
    return se2 + (sigma_rel * g) ** 2


def conditional(z, g_new, x, x_new, eta, ell):
    """Mean and variance of the smooth ``Δ`` at new orbits given the latent ``z``.

    The noise-free Gaussian-process conditional ``f_* | f = L z``: mean
    ``k_*ᵀ L⁻ᵀ z``, variance ``1 − |L⁻¹ k_*|²`` per unit scale, times
    ``η g_*`` (a new recording's own relative error ``σ_rel g_*`` is added with
    its noise, :func:`independent_variance`).

    Args:
        z: The latent draws of one frame axis, ``(n S,)`` (recording-major).
        g_new: The new orbits' scales ``(n_new, M)``.
        x: The training coordinates ``(n, 2)``.
        x_new: The new orbits' ``(n_new, 2)``.
        eta: The discrepancy's scale.
        ell: Its length.

    Returns:
        ``(mean, var)``, each ``(n_new, M)``; zero for the coefficients without
        the smooth part.
    """
    L = unit_factor(x, ell)
    ks = kernel(x, x_new, 1.0, ell)                                    # (n, n_new)
    V = jax.scipy.linalg.solve_triangular(L, ks, lower=True)           # (n, n_new)
    m = g_new.shape[-1]
    mask = smooth_mask(m)
    S = int(mask.sum())
    f_mean = V.T @ z.reshape(-1, S)                                    # (n_new, S)
    f_var = jnp.maximum(1.0 - jnp.sum(V * V, axis=0), 0.0)             # (n_new,)
    sel = np.flatnonzero(mask)
    mean = jnp.zeros(g_new.shape).at[:, sel].set(eta * g_new[:, sel] * f_mean)
    var = jnp.zeros(g_new.shape).at[:, sel].set((eta * g_new[:, sel]) ** 2 * f_var[:, None])
    return mean, var
