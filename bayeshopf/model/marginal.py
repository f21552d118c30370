r"""The collapsed Gaussian: the marginal of a linear model with its coefficients integrated out.

For ``y ~ N(Φ β, D)`` with ``β ~ N(0, V)``, ``V = diag(sd²)``, ``D = diag(d)``
and ``Φ' = Φ V^{1/2}``,

.. math::

    \log p(y) = -\tfrac12\Big[y^T D^{-1} y - b^T A^{-1} b
        + \log|D| + \log|A| + n\log 2π\Big],\quad
    A = I + Φ'^T D^{-1} Φ',\ b = Φ'^T D^{-1} y,

and ``β | y ~ N(V^{1/2} A^{-1} b, V^{1/2} A^{-1} V^{1/2})`` (Woodbury). One
Cholesky factor of the J × J matrix ``A`` gives the value
(:func:`log_marginal`), its derivatives, a draw of ``β``
(:func:`conditional_draw`) and each block's leave-one-out density
(:func:`block_log_predictive`). Where there are more columns than data
(``J > n``: the network at infinite width, with the discrepancy's latents) the
value and its derivatives come instead from the n × n matrix
``Σ̃ = D^{-1/2} Σ D^{-1/2} = I + P Pᵀ``, ``P = D^{-1/2} Φ'``, whose eigenvalues
other than 1 are those of ``A``: the same conditioning at a smaller size.
:mod:`bayeshopf.model.collapsed` uses it for the map and
:mod:`bayeshopf.model.frequency` for the phase speed.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def _factored(Phi, y, d, sd):
    """The collapsed Gaussian's log density and the pieces of its Woodbury form.

    Returns:
        ``(log N(y | 0, Σ), L, z, D⁻¹Φ', D⁻¹)`` with ``Φ' = Φ V^{1/2}``, ``A = I + Φ'ᵀD⁻¹Φ'
        = L Lᵀ`` and ``z = L⁻¹b``, ``b = Φ'ᵀD⁻¹y`` (module docstring).
    """
    Ps = Phi * sd                                   # Φ'
    Dinv = 1.0 / d
    PD = Dinv[:, None] * Ps                         # D⁻¹Φ'
    L = jnp.linalg.cholesky(jnp.eye(Phi.shape[-1]) + Ps.T @ PD)
    z = jax.scipy.linalg.solve_triangular(L, PD.T @ y, lower=True)
    return _gaussian(jnp.sum(Dinv * y * y) - z @ z, L, d), L, z, PD, Dinv


def _factored_dual(Phi, y, d, sd):
    """The collapsed Gaussian's log density through ``Σ̃ = I + P Pᵀ``, ``P = D^{-1/2}Φ'``.

    Returns:
        ``(log N(y | 0, Σ), L, u, P, r)`` with ``Σ̃ = L Lᵀ``, ``u = L⁻¹ D^{-1/2} y``
        and ``r = d^{-1/2}``.
    """
    r = jax.lax.rsqrt(d)
    P = (Phi * sd) * r[:, None]
    L = jnp.linalg.cholesky(jnp.eye(Phi.shape[0]) + P @ P.T)
    u = jax.scipy.linalg.solve_triangular(L, r * y, lower=True)
    return _gaussian(u @ u, L, d), L, u, P, r


def _gaussian(quadratic, L, d):
    """``−½[yᵀΣ⁻¹y + log|D| + log|LLᵀ| + n log 2π]``, ``|Σ| = |D| |LLᵀ|`` in both forms."""
    return -0.5 * (quadratic + jnp.sum(jnp.log(d)) + 2.0 * jnp.sum(jnp.log(jnp.diag(L)))
                   + d.size * jnp.log(2 * jnp.pi))


def _wide(Phi) -> bool:
    """More columns than data: factor the n × n ``Σ̃`` rather than the J × J ``A``."""
    return Phi.shape[-1] > Phi.shape[-2]


@jax.custom_jvp
def log_marginal(Phi, y, d, sd):
    r"""``log N(y | 0, Σ)``, ``Σ = Φ V Φᵀ + D``, ``V = diag(sd²)``, ``D = diag(d)``.

    Through the J × J matrix ``A`` (Woodbury, :func:`_factored`) where ``J ≤ n``,
    through the n × n matrix ``Σ̃`` (:func:`_factored_dual`) where ``J > n``:
    the same value and derivatives, with the smaller factorisation. The
    derivatives are written out (:func:`_log_marginal_jvp`) rather than traced
    through the factorisation: with ``Φ' = Φ V^{1/2}``, ``A = I + Φ'ᵀD⁻¹Φ'``,
    ``m = A⁻¹Φ'ᵀD⁻¹y = Φ'ᵀα`` and ``α = Σ⁻¹y = D⁻¹(y − Φ'm)``,

    .. math::

        \frac{∂ℓ}{∂Φ} = (α m^T − Σ^{-1}Φ')\,V^{1/2},\qquad
        \frac{∂ℓ}{∂d_i} = \tfrac12\big(α_i^2 − (Σ^{-1})_{ii}\big),

        \frac{∂ℓ}{∂\,sd_j} = \frac{m_j^2 − 1 + (A^{-1})_{jj}}{sd_j},\qquad
        \frac{∂ℓ}{∂y} = −α,

    from ``∂ℓ/∂Σ = ½(ααᵀ − Σ⁻¹)``, with ``Σ⁻¹Φ' = D⁻¹Φ'A⁻¹ = D^{-1/2}Σ̃⁻¹P``.
    One Cholesky factor and its triangle's inverse give them all (the value
    through its own triangular solve, never through ``A⁻¹``: small measurement
    errors make ``A`` ill-conditioned, and ``yᵀD⁻¹y − bᵀA⁻¹b`` a difference of
    large numbers), and NUTS runs faster with them than with reverse mode
    through the factorisation. Second derivatives (the Laplace covariance) still work, as
    the rule is made of differentiable operations. ``tests/test_collapsed.py``
    checks value, gradient and Hessian against the dense Gaussian, and value
    and gradient against reverse mode on an ill-conditioned design, in both forms.
    """
    return (_factored_dual if _wide(Phi) else _factored)(Phi, y, d, sd)[0]


def _woodbury_moments(Phi, y, d, sd):
    """``(value, α, m, Σ⁻¹Φ', diag Σ⁻¹)`` through ``A``, with ``A⁻¹ = L⁻ᵀL⁻¹``.

    One triangular solve (``L⁻¹``), the rest products with it; ``A⁻¹``'s
    eigenvalues are at most 1, so the product does not amplify rounding, and
    the value keeps its own solve (:func:`_factored`).
    """
    value, L, z, PD, Dinv = _factored(Phi, y, d, sd)
    Li = jax.scipy.linalg.solve_triangular(L, jnp.eye(L.shape[0]), lower=True)
    m = Li.T @ z                                    # A⁻¹b
    alpha = Dinv * y - PD @ m
    C = Li @ PD.T                                   # L⁻¹Φ'ᵀD⁻¹, (J, n)
    B = C.T @ Li                                    # D⁻¹Φ'A⁻¹ = Σ⁻¹Φ', (n, J)
    return value, alpha, m, B, Dinv - jnp.sum(C * C, axis=0)


def _dual_moments(Phi, y, d, sd):
    """``(value, α, m, Σ⁻¹Φ', diag Σ⁻¹)`` through ``Σ̃``, with ``Σ̃⁻¹ = L⁻ᵀL⁻¹``.

    ``Σ⁻¹ = D^{-1/2} Σ̃⁻¹ D^{-1/2}``; one triangular solve (``L⁻¹``), the rest
    products with it (``Σ̃⁻¹``'s eigenvalues are at most 1).
    """
    value, L, u, P, r = _factored_dual(Phi, y, d, sd)
    Li = jax.scipy.linalg.solve_triangular(L, jnp.eye(L.shape[0]), lower=True)   # L⁻¹
    S = Li.T @ Li                                                                # Σ̃⁻¹
    alpha = r * (Li.T @ u)                                                       # Σ⁻¹y
    B = r[:, None] * (S @ P)                                                     # Σ⁻¹Φ', (n, J)
    return value, alpha, (Phi * sd).T @ alpha, B, r * r * jnp.diag(S)


@log_marginal.defjvp
def _log_marginal_jvp(primals, tangents):
    """Value and directional derivative of :func:`log_marginal` (its docstring's formulas)."""
    Phi, y, d, sd = primals
    dPhi, dy, dd, dsd = tangents
    value, alpha, m, B, sigma_inv_diag = (_dual_moments if _wide(Phi)
                                          else _woodbury_moments)(Phi, y, d, sd)
    g_Phi = (alpha[:, None] * m[None, :] - B) * sd
    g_d = 0.5 * (alpha**2 - sigma_inv_diag)
    # 1 − (A⁻¹)_jj = (Φ'ᵀΣ⁻¹Φ')_jj = Σ_i Φ'_ij B_ij, as A − I = Φ'ᵀD⁻¹Φ'
    g_sd = (m**2 - jnp.sum((Phi * sd) * B, axis=0)) / sd
    return value, jnp.sum(g_Phi * dPhi) - alpha @ dy + g_d @ dd + g_sd @ dsd


def conditional_draw(Phi, y, d, sd, eps):
    """A draw of ``β | y, θ`` from standard-normal ``eps``, and the mean ``E[β | y, θ]``.

    In the whitened coordinates the conditional is ``N(A⁻¹b, A⁻¹)``; with
    ``A = L Lᵀ`` a draw is ``A⁻¹b + L⁻ᵀ ε``.
    """
    _, L, z, _, _ = _factored(Phi, y, d, sd)
    mean_w = jax.scipy.linalg.solve_triangular(L.T, z, lower=False)
    noise_w = jax.scipy.linalg.solve_triangular(L.T, eps, lower=False)
    return sd * (mean_w + noise_w), sd * mean_w


def block_log_predictive(Phi, y, d, sd, n_blocks: int):
    r"""``log p(y_b | y_{−b})`` of each of ``n_blocks`` equal contiguous blocks of ``y``.

    Under the collapsed Gaussian ``y ~ N(0, Σ)``, ``Σ = Φ V Φᵀ + D``, with
    ``Q = Σ^{-1}`` and ``g = Q y`` the conditional of block ``b`` given the rest is

    .. math::  y_b \mid y_{-b} \sim N\big(y_b - Q_{bb}^{-1} g_b,\ Q_{bb}^{-1}\big),

    so ``log p(y_b | y_{−b}) = −½[g_bᵀ Q_{bb}^{-1} g_b − log|Q_{bb}| + m log 2π]``
    (block size ``m``): the exact leave-one-recording-out density given θ, the
    map's coefficients refitted without the recording. It is the pointwise
    log-likelihood of PSIS-LOO for this non-factorised model (Bürkner, Gabry &
    Vehtari 2021): ``p(θ | y_{−b}) ∝ p(θ | y) / p(y_b | y_{−b}, θ)``.

    Returns:
        Shape ``(n_blocks,)``.
    """
    n = y.shape[-1]
    m = n // n_blocks
    Sigma = (Phi * sd**2) @ Phi.T + jnp.diag(d)
    Q = jax.scipy.linalg.cho_solve((jnp.linalg.cholesky(Sigma), True), jnp.eye(n))
    g = Q @ y
    out = []
    for b in range(n_blocks):        # a loop, not a batch: XLA's batched Cholesky is slow on CPU
        sl = slice(b * m, (b + 1) * m)
        Lb = jnp.linalg.cholesky(Q[sl, sl])
        z = jax.scipy.linalg.solve_triangular(Lb, g[sl], lower=True)
        out.append(-0.5 * (z @ z - 2.0 * jnp.sum(jnp.log(jnp.diag(Lb))) + m * jnp.log(2 * jnp.pi)))
    return jnp.stack(out)
