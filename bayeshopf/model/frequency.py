r"""The frequency model: the phase speed ``Ω(r, μ)`` of the normal form, integrated out.

The phase equation ``θ̇ = Ω``: by the rotational symmetry of the
normal form the phase speed depends on ``r`` and ``μ`` only, so each recording's
frequency is one number, ``ω_i = Ω(r_i, μ_i)``. ``Ω`` is a polynomial in
``r̃² = (r/r_ref)²`` and ``μ̃`` (:data:`FREQUENCY_TERMS`) about the mean measured
frequency ``ω̄``,

.. math::  ω_i = ω̄ + χ(r̃_i^2, μ̃_i)^T γ + ε_i,\qquad
           γ_j \sim N(0, (s_ω ω̄)^2),\quad ε_i \sim N(0, se_{ω,i}^2 + σ_ω^2),

with ``σ_ω ~ HalfNormal(0.01 ω̄)``: linear in ``γ``, so ``γ`` is integrated out by
the Woodbury marginal of the map's coefficients (:mod:`bayeshopf.model.marginal`)
and drawn exactly per draw, and only ``σ_ω`` joins the sampled parameters. The
record is then the map applied to the circle traversed at ``Ω(r_i, μ_i)``: no
phase integration is needed.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from bayeshopf.model.marginal import conditional_draw, log_marginal
from bayeshopf.model.spec import CollapsedSpec, radius, reference_radius

#: Prior sd of each frequency coefficient ``γ_j`` as a fraction of ``ω̄`` (broad: a
#: 10% change of the frequency per unit of ``r̃²`` or of ``μ̃``).
FREQUENCY_SCALE = 0.1
#: Half-normal scale of the frequency's model error ``σ_ω`` as a fraction of ``ω̄``.
SIGMA_OMEGA_PRIOR = 0.01
#: Terms ``(r̃²)^i μ̃^j`` of the phase speed ``Ω(r, μ) − ω̄``, as ``(i, j)``: the
#: normal form's ``ω_0 + ω_1 (μ − μ_0) + b_1 r² + b_2 r⁴`` (a constant, μ̃, r̃², r̃⁴).
FREQUENCY_TERMS = ((0, 0), (0, 1), (1, 0), (2, 0))


def frequency_basis(r2, mu_tilde):
    """``χ(r̃², μ̃)``: the terms :data:`FREQUENCY_TERMS`, shape ``broadcast + (4,)``."""
    r2, m = jnp.broadcast_arrays(r2, mu_tilde)
    return jnp.stack([r2**i * m**j for i, j in FREQUENCY_TERMS], axis=-1)


def radius_tilde_squared(spec: CollapsedSpec, mu, sign, theta: dict):
    """``r̃² = (r / r_ref)²`` of the LCO at μ (``nan`` where the branch does not exist)."""
    return (radius(spec, mu, sign, theta) / reference_radius(spec, theta.get("a2", -1.0))) ** 2


def frequency_design(spec: CollapsedSpec, mu, sign, theta: dict):
    """``X_i = χ(r̃_i², μ̃_i)`` for every recording, shape ``(n_rec, 4)``."""
    return frequency_basis(radius_tilde_squared(spec, mu, sign, theta), spec.mu_tilde(mu))


def frequency_prior_sd(spec: CollapsedSpec):
    """Prior sds of ``γ``: :data:`FREQUENCY_SCALE` ``· ω̄`` each."""
    return jnp.full(len(FREQUENCY_TERMS), FREQUENCY_SCALE * spec.omega_centre)


def frequency(spec: CollapsedSpec, theta: dict, gamma, mu, sign):
    """``Ω(r(μ), μ) = ω̄ + χ(r̃², μ̃)ᵀγ`` (rad/s), broadcast over μ; ``nan`` where no LCO."""
    r2 = radius_tilde_squared(spec, mu, sign, theta)
    return spec.omega_centre + jnp.sum(frequency_basis(r2, spec.mu_tilde(mu)) * gamma, axis=-1)


def frequency_marginal(spec: CollapsedSpec, theta: dict, sigma_omega, mu, sign, omega, omega_se):
    """``log p(ω | θ)``, the frequency's coefficients ``γ`` integrated out."""
    return log_marginal(frequency_design(spec, mu, sign, theta), omega - spec.omega_centre,
                        omega_se**2 + sigma_omega**2, frequency_prior_sd(spec))


def draw_frequency(spec: CollapsedSpec, theta: dict, mu, sign, omega, omega_se, key):
    """One exact draw of the frequency coefficients ``γ`` (4,) given one draw ``θ``."""
    eps = jax.random.normal(key, (len(FREQUENCY_TERMS),))
    d = omega_se**2 + theta["sigma_omega"] ** 2
    return conditional_draw(frequency_design(spec, mu, sign, theta), omega - spec.omega_centre,
                            d, frequency_prior_sd(spec), eps)[0]
