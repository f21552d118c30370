r"""The mechanistic part: the Hopf normal form with a quintic term (paper eq. NF-model-polar).

.. math::

    \\dot r = (\\mu-\\mu_0)\\,r + a_2 r^3 - r^5, \\qquad \\dot\\theta = \\Omega(r, \\theta, \\mu).

Its limit cycles are the non-zero roots of ``r⁴ − a2 r² − (μ − μ0) = 0``:

.. math::  r^2 = \\tfrac12\\left(a_2 \\pm \\sqrt{a_2^2 + 4(\\mu-\\mu_0)}\\right),

``+`` on the stable and ``−`` on the unstable branch. For ``a2 > 0``
(subcritical) both exist for ``μ0 − a2²/4 ≤ μ ≤ μ0`` and meet at the fold
(saddle-node of cycles) ``μ_SN = μ0 − a2²/4``; the stable one continues for
``μ > μ0``. For ``a2 < 0`` (supercritical) the single stable branch exists for
``μ > μ0``.
"""

from __future__ import annotations

import jax.numpy as jnp

#: Branch signs in the closed form: +1 stable, −1 unstable.
STABLE, UNSTABLE = 1.0, -1.0


def radial_field(r, mu, mu0, a2):
    """``ṙ = (μ − μ0) r + a2 r³ − r⁵`` (eq. NF-model-polar, first line)."""
    return (mu - mu0) * r + a2 * r**3 - r**5


def fold_point(mu0, a2):
    """Saddle-node of cycles ``μ_SN = μ0 − a2²/4`` (meaningful for ``a2 > 0``)."""
    return mu0 - a2**2 / 4.0


def _fold_tolerance(a2, mu0):
    """Round-off allowed in ``a2² + 4(μ−μ0)`` so that the fold itself counts as on both branches."""
    return 64.0 * jnp.finfo(jnp.float64).eps * (a2**2 + 4.0 * jnp.abs(mu0))


def branch_exists(mu, mu0, a2, sign):
    """Whether the LCO branch with ``sign`` (+1 stable, −1 unstable) exists at ``mu``.

    The stable root needs ``a2² + 4(μ−μ0) ≥ 0`` and ``r² > 0``; the unstable root
    also needs ``μ ≤ μ0`` (and ``a2 > 0``).
    """
    disc = a2**2 + 4.0 * (mu - mu0)
    r2 = 0.5 * (a2 + sign * jnp.sqrt(jnp.maximum(disc, 0.0)))
    return (disc >= -_fold_tolerance(a2, mu0)) & (r2 > 0.0)


def lco_radius(mu, mu0, a2, sign):
    """Closed-form LCO radius ``r = √((a2 ± √(a2² + 4(μ−μ0)))/2)``.

    Args:
        mu: Bifurcation parameter (any shape, broadcasts).
        mu0: Hopf point μ0.
        a2: Cubic coefficient (``> 0`` subcritical, ``< 0`` supercritical).
        sign: ``+1`` for the stable branch, ``−1`` for the unstable one.

    Returns:
        The radius; ``nan`` where the branch does not exist. Gradients stay
        finite where the branch exists (safe square roots).
    """
    disc = a2**2 + 4.0 * (mu - mu0)
    r2 = 0.5 * (a2 + sign * jnp.sqrt(jnp.maximum(disc, 0.0)))
    ok = (disc >= -_fold_tolerance(a2, mu0)) & (r2 > 0.0)
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, r2, 1.0)), jnp.nan)
