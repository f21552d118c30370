r"""The Van der Pol oscillator of the paper (Section 4.1, eq. vdp).

.. math::

    \dot z_1 = z_2, \qquad \dot z_2 = 2\mu z_2 - z_1^2 z_2 - z_1 .

The origin is an equilibrium whose eigenvalues :math:`\mu \pm i\sqrt{1-\mu^2}`
cross the imaginary axis at :math:`\mu = 0` with frequency 1 rad/s: a
supercritical Hopf bifurcation, with one stable limit cycle for
:math:`\mu > 0`. For small :math:`\mu` averaging (with
:math:`z_1 = r\cos\theta`, :math:`z_2 = -r\sin\theta`) gives
:math:`\dot r = \mu r - r^3/8`, so :math:`r = 2\sqrt{2\mu}`: the peak-to-peak of
:math:`z_1` is :math:`4\sqrt{2\mu}` and the period :math:`2\pi + O(\mu^2)`.
Both states are observed and dimensionless.
"""

from __future__ import annotations

import jax.numpy as jnp

from bayeshopf.simulators.base import System

__all__ = ["VANDERPOL", "vanderpol_rhs"]


def vanderpol_rhs(x, mu, params):
    r"""``ż1 = z2``, ``ż2 = 2μ z2 − c z1² z2 − ω² z1`` (paper eq. vdp with c = ω = 1).

    Args:
        x: ``[z1, z2]``.
        mu: The bifurcation parameter μ.
        params: ``{"c": ..., "omega": ...}`` (both 1 in the paper).
    """
    z1, z2 = x[0], x[1]
    return jnp.stack([
        z2,                                                                  # eq. vdp, row 1
        2.0 * mu * z2 - params["c"] * z1**2 * z2 - params["omega"] ** 2 * z1,  # eq. vdp, row 2
    ])


def _force_input(x, mu, params):
    """A generalised force on z1 enters ż2 (unit mass)."""
    return jnp.array([[0.0], [1.0]], dtype=x.dtype)


VANDERPOL = System(
    name="vanderpol",
    state_names=("z1", "z2"),
    state_units=("", ""),
    parameter="mu",
    parameter_units="",
    params={"c": 1.0, "omega": 1.0},
    param_units={"c": "", "omega": "rad/s"},
    rhs=vanderpol_rhs,
    observed=("z1", "z2"),
    mu_range=(-0.5, 1.0),
    parameter_label="mu",
    default_plan=tuple((m, "stable") for m in (0.1, 0.28, 0.46, 0.64, 0.82, 1.0)),
    coordinates=("z1",),
    force_input=_force_input,
    description="Van der Pol oscillator z1' = z2, z2' = 2 mu z2 - z1^2 z2 - z1 (Lee, Barton "
    "& Renson, Section 4.1); supercritical Hopf bifurcation at mu = 0.",
)
