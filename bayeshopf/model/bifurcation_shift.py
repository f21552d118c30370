r"""The discrepancy in μ at the Hopf point and the fold: where the rig's bifurcations lie.

The model discrepancy (:mod:`bayeshopf.model.discrepancy`) is *vertical*: it
changes the orbit's size at each point ``x`` of the diagram. A smooth vertical
change keeps a curve's vertical tangents, so the fold, where the two branches
meet, and the Hopf point, where the orbit and its relative discrepancy vanish,
stay where the normal form puts them, however much the recordings disagree with
the model. Their *horizontal* twin is an error in μ along the diagram:

.. math::

    μ^*(x) = μ(x) + κ\, η\, G\, h(x),\qquad
    h \sim \mathcal{GP}\big(0, e^{-|x - x'|^2 / 2ℓ^2}\big),\quad h(x_i) = 0,

with ``x = (μ̃, s²/\overline{s^2})`` the discrepancy's coordinates, its scale
``η`` and length ``ℓ`` (the same draws), ``G = μ_0 − μ_{SN}`` the fold–Hopf gap
(``Δμ`` without a fold), and ``κ`` the size of the error in μ relative to the
gap per unit of the orbit's relative error. The process is held at zero at
the training recordings ``x_i``, whose μ is known and through which the fit
passes, so it is the error of the *extrapolation*: it grows with the distance
of the Hopf point ``x_0 = (μ̃_0, 0)`` and the fold ``x_{SN} = (μ̃_{SN}, ½/\overline{s^2})``
from the recordings, in units of ``ℓ``, and with the disagreement ``η``. The
true bifurcation points are ``μ_0 + κηG\,h(x_0)`` and ``μ_{SN} + κηG\,h(x_{SN})``
to first order, ``h`` at the two drawn jointly from the Gaussian-process
conditional (:func:`endpoint_factor`); each moves in the log of its distance
beyond the recordings that bound it (the fold stays below the lowest recording,
the Hopf point above the highest unstable one), as the model's own points do.

The recordings do not see ``h`` (it vanishes where they are), so the
likelihood is unchanged and the shift is drawn after NUTS, one standard
normal pair per posterior draw (:func:`shift_draws`): the posterior predictive
of the rig's bifurcation points under this discrepancy.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from bayeshopf.model import discrepancy as dm
from bayeshopf.model.collapsed import spec_jit
from bayeshopf.model.spec import CollapsedSpec, radius, reference_radius

#: Jitter of the conditional covariance's Cholesky factor (the endpoints may
#: coincide with a recording's coordinates, where the conditional vanishes).
JITTER = 1e-12


def endpoint_factor(x, x_end, ell):
    """Cholesky factor ``(m, m)`` of the unit process's covariance at ``x_end`` given ``h(x) = 0``.

    ``x``: the recordings' coordinates ``(n, 2)``; ``x_end``: the endpoints'
    ``(m, 2)``; ``ell``: the length. The covariance is
    ``k(x_e, x_e) − k(x_e, x) k(x, x)⁻¹ k(x, x_e)`` (noise-free conditioning).
    """
    L = dm.unit_factor(x, ell)
    V = jax.scipy.linalg.solve_triangular(L, dm.kernel(x, x_end, 1.0, ell), lower=True)
    C = dm.kernel(x_end, x_end, 1.0, ell) - V.T @ V
    C = 0.5 * (C + C.T) + JITTER * jnp.eye(x_end.shape[0])
    return jnp.linalg.cholesky(C)


def _one(spec: CollapsedSpec, theta: dict, mu, sign, kappa, xi):
    """The shifts of one posterior draw ``theta`` (scalars), ``(m,)``: Hopf point, then fold."""
    a2 = theta.get("a2", -1.0)
    s = radius(spec, mu, sign, theta) / reference_radius(spec, a2)
    mean_s2 = jnp.mean(s**2)
    x = dm.coordinate(spec.mu_tilde(mu), s, s)
    ends = [jnp.stack([spec.mu_tilde(theta["mu0"]), 0.0])]
    if spec.criticality == "subcritical":
        # the fold's radius: r² = a2/2 (a2² + 4β = 0), r_ref² = a2
        ends.append(jnp.stack([spec.mu_tilde(theta["mu_fold"]), 0.5 / mean_s2]))
        gap = theta["mu0"] - theta["mu_fold"]
    else:
        gap = spec.mu_span
    F = endpoint_factor(x, jnp.stack(ends), theta["ell"])
    return kappa * theta["eta"] * gap * (F @ xi[: len(ends)])


def _moved(spec: CollapsedSpec, theta: dict, eps):
    """The points moved by ``eps`` (Hopf, fold), each beyond the recordings it must lie beyond.

    A point at distance ``d`` beyond its anchor (the model's gaps: the fold
    ``g_fold`` below the lowest recording, the Hopf point ``g_hopf`` above the
    highest unstable one, or below the lowest recording without a fold) moves
    to ``d e^{±ε/d}`` from it: by ``ε`` to first order, never across the anchor.
    """
    g_h = theta["gap_hopf"]
    if spec.criticality != "subcritical":
        return [theta["mu0"] - g_h * jnp.expm1(-eps[0] / g_h)]
    g_f = theta["gap_fold"]
    return [theta["mu0"] + g_h * jnp.expm1(eps[0] / g_h),
            theta["mu_fold"] - g_f * jnp.expm1(-eps[1] / g_f)]


def shift_draws(spec: CollapsedSpec, theta: dict, mu, sign, kappa: float, key) -> dict:
    """Draws of the rig's Hopf point (and fold) under the discrepancy in μ (module docstring).

    Args:
        spec: The model (with the discrepancy, ``spec.has_discrepancy``).
        theta: Posterior draws of the sites, each ``(S,)`` (``mu0``, ``gap_hopf``,
            ``a2``, ``eta``, ``ell``, and ``mu_fold``, ``gap_fold`` and ``w_unfold``
            when subcritical).
        mu: μ of the training recordings ``(n,)``.
        sign: Their branch signs ``(n,)``.
        kappa: ``κ``; 0 gives the model's own points.
        key: JAX random key of the standard normal pair of each draw.

    Returns:
        ``{"mu0": (S,), "mu_fold": (S,)}`` (``mu_fold`` only when subcritical).

    Raises:
        ValueError: Without the discrepancy (no ``η`` and ``ℓ`` to draw from).
    """
    if not spec.has_discrepancy:
        raise ValueError("the discrepancy in μ needs the model discrepancy (its η and ℓ); "
                         "got a model without it")
    names = ["mu0"] + (["mu_fold"] if spec.criticality == "subcritical" else [])
    th = {k: jnp.asarray(v, dtype=float) for k, v in theta.items()}
    xi = jax.random.normal(key, (th["mu0"].shape[0], 2))
    moved = spec_jit(spec, _all)(th, xi, jnp.asarray(mu, dtype=float),
                                 jnp.asarray(sign, dtype=float), jnp.asarray(kappa, dtype=float))
    return {n: np.asarray(moved[:, j]) for j, n in enumerate(names)}


def _all(spec: CollapsedSpec, theta: dict, xi, mu, sign, kappa):
    """The moved points of every draw, ``(S, m)`` (compiled once per spec, :func:`shift_draws`)."""
    return jax.vmap(lambda t, z: jnp.stack(
        _moved(spec, t, _one(spec, t, mu, sign, kappa, z))))(theta, xi)
