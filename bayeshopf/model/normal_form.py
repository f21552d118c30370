r"""The mechanistic part: the Hopf normal form to fifth order (paper eq. NF-model-polar).

.. math::

    \\dot r = (\\mu-\\mu_0)\\,r + a_2 r^3 + a_4 r^5,
    \\qquad \\dot\\theta = \\Omega(r, \\theta, \\mu).

The scale of ``r`` is free (the map to the measurements absorbs it), so one of
the two nonlinear coefficients is fixed, the *gauge*:

* **subcritical** (the paper's eq. NF-model-polar): ``a4 = −1`` and ``a2 > 0``.
  The limit cycles are the non-zero roots of ``r⁴ − a2 r² − (μ − μ0) = 0``,

  .. math::  r^2 = \\tfrac12\\left(a_2 \\pm \\sqrt{a_2^2 + 4(\\mu-\\mu_0)}\\right),

  ``+`` on the stable and ``−`` on the unstable branch. Both exist for
  ``μ0 − a2²/4 ≤ μ ≤ μ0`` and meet at the fold (saddle-node of cycles)
  ``μ_SN = μ0 − a2²/4``; the stable one continues for ``μ > μ0``.
* **supercritical** (the paper's Van der Pol example, Section 4.1, which sets
  ``a2 = −1`` and drops the fifth-order term): ``a2 = −1`` and ``a4 = −κ ≤ 0``.
  The single stable branch exists for ``μ > μ0``,

  .. math::  r^2 = \\frac{2(\\mu-\\mu_0)}{1 + \\sqrt{1 + 4\\kappa(\\mu-\\mu_0)}},

  which is ``r² = μ − μ0`` (the square-root law of a generic supercritical Hopf
  point) at ``κ = 0``. The quintic gauge ``a4 = −1, a2 < 0`` is the same family
  with ``κ = 1/a2²`` and ``r`` scaled by ``√|a2|``, but it reaches the generic
  square-root law only as ``a2 → −∞``, where no prior on a2 can sit.

For any gauge, with ``q = −a4 ≥ 0`` and ``D = a2² + 4q(μ−μ0)``, the roots of
``q r⁴ − a2 r² − (μ−μ0) = 0`` are ``r² = (a2 ± √D)/(2q)``; they are evaluated
in the form that stays finite as ``q → 0``.
"""

from __future__ import annotations

import jax.numpy as jnp

from bayeshopf.errors import FitError

#: Branch signs in the closed form: +1 stable, −1 unstable.
STABLE, UNSTABLE = 1.0, -1.0


def branch_sign(branch: str) -> float:
    """``+1`` (stable) or ``−1`` (unstable); a :class:`FitError` for any other name."""
    if branch not in ("stable", "unstable"):
        raise FitError(f"branch must be 'stable' or 'unstable'; got {branch!r}")
    return STABLE if branch == "stable" else UNSTABLE


def radial_field(r, mu, mu0, a2, a4=-1.0):
    """``ṙ = (μ − μ0) r + a2 r³ + a4 r⁵`` (eq. NF-model-polar, first line)."""
    return (mu - mu0) * r + a2 * r**3 + a4 * r**5


def fold_point(mu0, a2, a4=-1.0):
    """Saddle-node of cycles ``μ_SN = μ0 − a2²/(4q)``, ``q = −a4`` (meaningful for ``a2 > 0``)."""
    return mu0 - a2**2 / (4.0 * -a4)


def _fold_tolerance(a2, mu0):
    """Round-off allowed in ``a2² + 4q(μ−μ0)``, so that the fold counts as on both branches."""
    return 64.0 * jnp.finfo(jnp.float64).eps * (a2**2 + 4.0 * jnp.abs(mu0))


def _radius_squared(mu, mu0, a2, sign, a4):
    """``r² = (a2 ± √D)/(2q)`` and whether it is a real, positive root.

    The stable root is ``(a2 + √D)/(2q)`` for ``a2 > 0`` and ``2Δ/(√D − a2)``
    otherwise (finite at ``q = 0``); the unstable one is ``−2Δ/(a2 + √D)``.
    """
    q = -a4
    delta = mu - mu0
    disc = a2**2 + 4.0 * q * delta
    sq = jnp.sqrt(jnp.maximum(disc, 0.0))
    pos = a2 > 0
    stable = jnp.where(
        pos,
        (a2 + sq) / (2.0 * jnp.where(pos, q, 1.0)),
        2.0 * delta / jnp.where(pos, 1.0, sq - a2),
    )
    den_u = a2 + sq
    unstable = jnp.where(pos, -2.0 * delta / jnp.where(pos, den_u, 1.0), -1.0)
    r2 = jnp.where(sign > 0, stable, unstable)
    ok = (disc >= -_fold_tolerance(a2, mu0)) & (r2 > 0.0)
    return r2, ok


def branch_exists(mu, mu0, a2, sign, a4=-1.0):
    """Whether the LCO branch with ``sign`` (+1 stable, −1 unstable) exists at ``mu``.

    The stable root needs ``D ≥ 0`` and ``r² > 0``; the unstable root exists
    only for ``a2 > 0``, between the fold and μ0.
    """
    return _radius_squared(mu, mu0, a2, sign, a4)[1]


def lco_radius(mu, mu0, a2, sign, a4=-1.0):
    """Closed-form LCO radius, ``r² = (a2 ± √(a2² − 4 a4 (μ−μ0)))/(−2 a4)``.

    Args:
        mu: Bifurcation parameter (any shape, broadcasts).
        mu0: Hopf point μ0.
        a2: Cubic coefficient (``> 0`` subcritical, ``< 0`` supercritical).
        sign: ``+1`` for the stable branch, ``−1`` for the unstable one.
        a4: Quintic coefficient ``≤ 0`` (``−1``: the subcritical gauge; with
            ``a2 = −1``, ``a4 = −κ``: the supercritical gauge, module docstring).

    Returns:
        The radius; ``nan`` where the branch does not exist. Gradients stay
        finite where the branch exists (safe square roots).
    """
    r2, ok = _radius_squared(mu, mu0, a2, sign, a4)
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, r2, 1.0)), jnp.nan)
