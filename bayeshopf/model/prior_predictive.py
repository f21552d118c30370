r"""Data sets drawn from the collapsed model's prior: the prior predictive.

For a model's structure ``spec``, a design (each recording's μ_i and branch
s_i) and the standard errors of its coefficients, one draw is the generative
process that :mod:`bayeshopf.model.collapsed` integrates, step by step:

.. math::

    θ &\sim p(θ) && \text{(the normal form's and the hyperparameters' sites)}\\
    β_c &\sim N(0, V(θ)),\quad z_c \sim N(0, I) && \text{(the map; the discrepancy's latents)}\\
    y_c &= Φ_c(θ)\,[β_c; z_c] + ε_c,\quad ε_c \sim N(0, D_c(θ)) && \text{(each frame axis } c)\\
    ω &= ω̄ + X(θ) γ + ε_ω,\quad γ \sim N(0, s_ω^2 ω̄^2 I),\
        ε_ω \sim N(0, se_ω^2 + σ_ω^2) && \text{(with the frequency model)}

with ``Φ_c``, ``V`` and ``D_c`` those of
:func:`~bayeshopf.model.collapsed.linear_system`. Fitting such draws and
ranking the truth among the posterior draws is simulation-based calibration
(Talts et al. 2018): the ranks are uniform when the inference is exact.

The draw is defined only for a model whose noise does not depend on the
datum, the model with the discrepancy (``spec.has_discrepancy``): without it
the relative model error multiplies the observed coefficient, ``σ_rel y``,
which is not a density in ``y``.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from numpyro import handlers

from bayeshopf.errors import FitError
from bayeshopf.model import collapsed as cm
from bayeshopf.model import frequency as fm


@dataclass(frozen=True)
class PriorDraw:
    """One data set drawn from the prior (immutable).

    Attributes:
        theta: The drawn sites and deterministic quantities (``mu0``,
            ``mu_fold``, ``a2``, ``eta``, …), each a scalar or ``(2,)`` array.
        beta: The map's coefficients and the discrepancy's latents ``(J', 2)``.
        coeffs: The recorded coefficients ``(n_rec, 2, 2K+1)``.
        omega: The recorded angular frequencies ``(n_rec,)`` (``ω̄`` without
            the frequency model).
    """

    theta: dict
    beta: np.ndarray
    coeffs: np.ndarray
    omega: np.ndarray


def _prior_sites(spec: cm.CollapsedSpec) -> dict:
    theta = {**cm.normal_form_sites(spec), **cm.hyper_sites(spec)}
    if spec.omega_centre is not None:
        theta["sigma_omega"] = cm.frequency_site(spec)
    return theta


def draw_data(spec: cm.CollapsedSpec, mu, sign, coeffs_se, key, omega_se=None) -> PriorDraw:
    """One data set from the prior of the model ``spec`` at a design (module docstring).

    Args:
        spec: The model's structure and data constants; it must have the
            discrepancy (``spec.has_discrepancy``).
        mu: μ of each recording ``(n_rec,)``.
        sign: ``+1`` stable, ``−1`` unstable ``(n_rec,)``.
        coeffs_se: Standard errors of the coefficients ``(n_rec, 2, 2K+1)``.
        key: A JAX random key.
        omega_se: Standard errors of the frequencies ``(n_rec,)`` (0 if ``None``).

    Raises:
        FitError: For a model without the discrepancy, a design whose
            shapes disagree, or (a network at infinite width) a design other
            than the recordings ``spec.nn_training`` names.
    """
    if not spec.has_discrepancy:
        raise FitError("spec: a model with the discrepancy expected (its noise does not depend "
                       "on the datum); got one without it, whose σ_rel·y has no prior predictive")
    mu, sign = jnp.asarray(mu, dtype=float), jnp.asarray(sign, dtype=float)
    se = jnp.asarray(coeffs_se, dtype=float)
    shape = (mu.shape[0], 2, 2 * spec.n_harmonics + 1)
    if sign.shape != mu.shape or se.shape != shape:
        raise FitError(f"design: mu {mu.shape}, sign {sign.shape} and coeffs_se {shape} "
                       f"expected; got sign {sign.shape} and coeffs_se {se.shape}")
    if spec.nn_training is not None and not (
            mu.shape == np.shape(spec.nn_training[0])
            and np.allclose(mu, spec.nn_training[0])
            and np.allclose(sign, spec.nn_training[1])):
        raise FitError("design: the recordings the model's infinite-width network was built on "
                       f"expected (mu {list(spec.nn_training[0])}, sign "
                       f"{list(spec.nn_training[1])}); got mu {np.asarray(mu).tolist()}")
    k_theta, k_beta, k_eps, k_gamma, k_omega = jax.random.split(key, 5)
    with handlers.seed(rng_seed=k_theta):
        trace = handlers.trace(_prior_sites).get_trace(spec)
    theta = {k: jnp.asarray(v["value"]) for k, v in trace.items()
             if v["type"] in ("sample", "deterministic")}
    Phis, sd, ds = cm.linear_system(spec, theta, mu, sign, jnp.zeros(shape), se)
    eps_b = jax.random.normal(k_beta, (sd.shape[0], 2))
    eps_y = jax.random.normal(k_eps, (2, ds[0].shape[0]))
    beta = sd[:, None] * eps_b
    y = jnp.stack([Phis[c] @ beta[:, c] + jnp.sqrt(ds[c]) * eps_y[c] for c in range(2)],
                  axis=1)                                       # (n (2K+1), 2)
    coeffs = y.reshape(shape[0], shape[2], 2).transpose(0, 2, 1)
    if spec.omega_centre is None:
        omega = jnp.full(mu.shape, np.nan)
    else:
        o_se = jnp.zeros(mu.shape) if omega_se is None else jnp.asarray(omega_se, dtype=float)
        gamma = fm.frequency_prior_sd(spec) * jax.random.normal(k_gamma, (len(fm.FREQUENCY_TERMS),))
        noise = jnp.sqrt(o_se**2 + theta["sigma_omega"] ** 2) * jax.random.normal(k_omega, mu.shape)
        omega = spec.omega_centre + fm.frequency_design(spec, mu, sign, theta) @ gamma + noise
    return PriorDraw({k: np.asarray(v) for k, v in theta.items()}, np.asarray(beta),
                     np.asarray(coeffs), np.asarray(omega))
