r"""The map's network at infinite width: a Gaussian process with the network's kernel.

The map's network ``NN(x) = Σ_h v_h ψ(w_hᵀ x + b_h)``, ``x = (ũ1, ũ2, μ̃)``, with
hidden weights ``w_h ~ N(0, I)``, ``b_h ~ N(0, 1)`` and output weights
``v_h ~ N(0, ρ² τ_s² / H)``, tends as ``H → ∞`` to a Gaussian process with
covariance ``ρ² τ_s² k(x, x')``, ``k(x, x') = E[ψ(wᵀx + b) ψ(wᵀx' + b)]``
(Neal 1996). With ``ψ(z) = erf(√π z / 2)`` (the shape of ``tanh``: slope 1 at
0, limits ±1) the expectation is closed (Williams 1998):

.. math::

    k(x, x') = \frac{2}{π} \arcsin \frac{2a^2\, \tilde x^T \tilde x'}
        {\sqrt{(1 + 2a^2 |\tilde x|^2)(1 + 2a^2 |\tilde x'|^2)}},
    \qquad \tilde x = (1, x),\quad a^2 = π/4.

It has no draw of a hidden layer, so nothing in a fit depends on one.

**Its scale in μ.** ``μ̃`` spans one unit over the recordings, so with unit
input weights the network varies in μ only on the scale of the whole span.
With the weight on ``μ̃`` drawn from ``N(0, ν²)`` the kernel is the one above at
``(ũ1, ũ2, ν μ̃)``: ``ν = spec.nn_mu_scale`` (1 by default), or, where that is
``None``, sampled with the normal form (site ``nu_mu``, prior :data:`NU_PRIOR`),
so that the data choose how fast the map may bend in μ and how fast a
prediction's spread grows away from the recordings.

**On the orbits.** The data see the network through each recording's harmonic
coefficients ``f_i = P NN(x_i(φ_n))`` over the ``N`` phases of its orbit
``x_i(φ) = (s_i \cos φ, s_i \sin φ, μ̃_i)`` (``P`` the Fourier projection of
:func:`~bayeshopf.model.collapsed.projection`). On two such circles
``\tilde x_i^T \tilde x_j' = 1 + s_i s_j \cos(φ − φ') + μ̃_i μ̃_j`` and
``|\tilde x_i|² = 1 + s_i² + μ̃_i²``, so ``k`` depends on the phases only through
``Δ = φ − φ'``, as an even function ``g_{ij}(Δ)``; the projection of such a
kernel is diagonal in the coefficients:

.. math::

    \operatorname{Cov}(a_{h,i}, a_{h,j}) = \operatorname{Cov}(b_{h,i}, b_{h,j})
        = C_h(i, j) = \frac{2}{N} \sum_{n} g_{ij}(Δ_n) \cos hΔ_n,\qquad
    \operatorname{Cov}(a_{0,i}, a_{0,j}) = C_0(i, j) = \frac{1}{N}\sum_n g_{ij}(Δ_n),

and every other pair is uncorrelated (exactly, on the uniform grid of phases,
for ``h < N/2``): one ``n × n`` matrix per harmonic (:func:`harmonic_kernel`).

**In the collapsed model.** Over the training recordings the network's
coefficient ``k`` (of harmonic ``h``) is ``ρ τ_s L_h z_k``, ``L_h L_hᵀ = C_h + ε_h I``,
``z_k ~ N(0, I)``: ``n (2K+1)`` more linear columns of the design
(:func:`columns`), integrated out with the rest of the map. The normal form's
radii ``s_i`` move with θ, so the ``C_h`` are recomputed for every draw.

**At a new orbit** its coefficient ``k`` given ``z_k`` is Gaussian, with mean
``ρ τ_s (L_h⁻¹ c_{h*})ᵀ z_k`` (the same :func:`columns`, evaluated there; at a
training orbit, ``L_h``'s row) and variance ``ρ² τ_s² (c_{h**} − |L_h⁻¹ c_{h*}|²)``
(:func:`conditional_var`), which vanishes at the training orbits and grows away
from them.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from bayeshopf.model.discrepancy import harmonic_index
from bayeshopf.model.spec import CollapsedSpec, radius, reference_radius

#: ``a²`` of ``ψ(z) = erf(a z)``, ``a = √π/2``: the erf with tanh's slope at 0.
ERF_SCALE2 = np.pi / 4.0
#: Log-normal prior of ``ν``, the network's input scale on ``μ̃`` (median, log-sd).
NU_PRIOR = (2.0, 0.75)
#: ``ε_h`` relative to the mean of ``C_h``'s diagonal: a smooth function's high
#: harmonics are tiny and nearly the same on nearby orbits, so ``C_h`` is
#: numerically singular without it.
JITTER = 1e-9


def _arcsine(inner, sq_a, sq_b):
    """``(2/π) arcsin(2a² x̃ᵀx̃' / √((1 + 2a²|x̃|²)(1 + 2a²|x̃'|²)))`` from the three products."""
    c = 2.0 * ERF_SCALE2
    return (2.0 / jnp.pi) * jnp.arcsin(c * inner / jnp.sqrt((1.0 + c * sq_a) * (1.0 + c * sq_b)))


def kernel(xa, xb):
    r"""``k(x_a, x_b)`` (module docstring), shape ``(n_a, n_b)`` for ``x`` of shape ``(n, 3)``."""
    sq_a = 1.0 + jnp.sum(xa * xa, axis=-1)
    sq_b = 1.0 + jnp.sum(xb * xb, axis=-1)
    return _arcsine(1.0 + xa @ xb.T, sq_a[:, None], sq_b[None, :])


def harmonic_kernel(s_a, m_a, s_b, m_b, n_harmonics: int, n_phi: int):
    """``C_h(a, b)`` for ``h = 0..K`` (module docstring), ``(K+1, n_a, n_b)``.

    ``s``: the orbits' radii ``r / r_ref``; ``m``: their ``μ̃`` (times ``ν``).
    """
    delta = 2 * np.pi * np.arange(n_phi) / n_phi
    inner = (1.0 + (s_a[:, None] * s_b[None])[..., None] * np.cos(delta)
             + (m_a[:, None] * m_b[None])[..., None])                         # (n_a, n_b, N)
    g = _arcsine(inner, (1.0 + s_a**2 + m_a**2)[:, None, None],
                 (1.0 + s_b**2 + m_b**2)[None, :, None])
    h = np.arange(n_harmonics + 1)
    w = np.where(h[:, None] == 0, 1.0, 2.0) / n_phi * np.cos(h[:, None] * delta)  # (K+1, N)
    return jnp.einsum("hn,abn->hab", w, g)


def _orbit_coordinates(spec: CollapsedSpec, theta: dict, mu, sign):
    """``(s, ν μ̃)`` of the orbits at ``(mu, sign)``: the network's circles."""
    s = radius(spec, mu, sign, theta) / reference_radius(spec, theta.get("a2", -1.0))
    m = spec.mu_tilde(mu) * (theta["nu_mu"] if spec.samples_nu_mu else spec.nn_mu_scale)
    return s, jnp.broadcast_to(m, jnp.shape(s))


def training_factor(spec: CollapsedSpec, theta: dict, n_phi: int):
    """``(L, s, μ̃)``: ``L_h L_hᵀ = C_h + ε_h I`` ``(K+1, n, n)`` over the training orbits."""
    mu, sign = (jnp.asarray(a, dtype=float) for a in spec.nn_training)
    s, m = _orbit_coordinates(spec, theta, mu, sign)
    C = harmonic_kernel(s, m, s, m, spec.n_harmonics, n_phi)
    eps = JITTER * jnp.mean(jnp.diagonal(C, axis1=1, axis2=2), axis=1)
    n = s.shape[0]
    return jnp.linalg.cholesky(C + eps[:, None, None] * jnp.eye(n)), s, m


def _per_coefficient(V, n_harmonics: int):
    """``(K+1, n_tr, n)`` per harmonic → design columns ``(n, M, M n_tr)`` (coefficient-major)."""
    Vk = V[harmonic_index(n_harmonics)]                              # (M, n_tr, n)
    M = Vk.shape[0]
    cols = jnp.einsum("kmj,kl->jklm", Vk, jnp.eye(M))                         # (n, M, M, n_tr)
    return cols.reshape(cols.shape[0], M, -1)


def _solved(spec: CollapsedSpec, theta: dict, mu, sign, n_phi: int):
    """``V_h = L_h⁻¹ c_{h*}`` ``(K+1, n_tr, n)`` at orbits ``(mu, sign)``, and their ``(s, μ̃)``."""
    L, s_tr, m_tr = training_factor(spec, theta, n_phi)
    s, m = _orbit_coordinates(spec, theta, mu, sign)
    Cs = harmonic_kernel(s_tr, m_tr, s, m, spec.n_harmonics, n_phi)          # (K+1, n_tr, n)
    V = jax.vmap(lambda a, b: jax.scipy.linalg.solve_triangular(a, b, lower=True))(L, Cs)
    return V, s, m


def columns(spec: CollapsedSpec, theta: dict, mu, sign, n_phi: int, *, training: bool = False):
    """The network's columns of the design at orbits ``(mu, sign)``, ``(n, M, M n_train)``.

    Latent ``k n_train + m`` is coefficient ``k`` of training recording ``m``.
    ``(L_h⁻¹ c_{h*})ᵀ``: times ``ρ τ_s z`` the conditional mean of the network's
    coefficients there. ``training``: the orbits are the training ones
    (``spec.nn_training``), whose columns are ``L_h``'s rows (exactly).
    """
    if training:
        L = training_factor(spec, theta, n_phi)[0]
        return _per_coefficient(jnp.swapaxes(L, 1, 2), spec.n_harmonics)
    return _per_coefficient(_solved(spec, theta, mu, sign, n_phi)[0], spec.n_harmonics)


def conditional_var(spec: CollapsedSpec, theta: dict, mu, sign, n_phi: int):
    """``c_{h**} − |L_h⁻¹ c_{h*}|²`` of each coefficient at orbits ``(mu, sign)``, ``(n, M)``.

    The variance of the network's coefficients there given the training ones,
    per unit ``ρ² τ_s²``; independent between coefficients (module docstring).
    """
    V, s, m = _solved(spec, theta, mu, sign, n_phi)
    own = jax.vmap(lambda a, b: harmonic_kernel(a[None], b[None], a[None], b[None],
                                                spec.n_harmonics, n_phi)[:, 0, 0])(s, m)  # (n, K+1)
    var = jnp.maximum(own - jnp.sum(V * V, axis=1).T, 0.0)                   # (n, K+1)
    return var[:, harmonic_index(spec.n_harmonics)]
