r"""The oscillation speed Ω on the limit cycles (paper eq. Om_V) and the phase ODE.

.. math::

    \Omega(r, \theta, \mu) = \omega_0 + s_\Omega\,\mathrm{NN}_{\Theta_\Omega}(r, \tilde\mu)^T
        [1, \cos\theta, \ldots, \cos n_h\theta, \sin\theta, \ldots, \sin n_h\theta]^T,

a tanh MLP with inputs ``(r, μ̃)`` and ``2 n_h + 1`` linear outputs (the Fourier
coefficients of Ω in θ), multiplied by a learnt output scale ``s_Ω``. With
``n_h = 0`` the speed is constant along an orbit but varies with its amplitude
and μ.

On an LCO the radius is a fixed point of ``ṙ = (μ−μ0) r + a2 r³ − r⁵``, so only

.. math::  \dot\theta = \Omega(r(\mu), \theta, \mu), \qquad \theta(0) = \theta_0

is integrated (eq. NF-model-polar, second line; diffrax Tsit5, adaptive steps).
Integrating θ alone is stable on unstable orbits too: θ is the direction of the
trivial Floquet multiplier. The period is exact by quadrature,

.. math::  T = \int_0^{2\pi} \frac{d\theta}{\Omega(r, \theta, \mu)}, \qquad f = 1/T,

with the trapezoidal rule on a uniform θ grid, which converges geometrically
for a smooth periodic integrand.

The initial phase solves the paper's eq. (zp_ang),
``ang(U12(r[cos θ0, sin θ0], μ̃)) = ang(w(t1))``, the angle of the measured
first point about the frame centre, by a grid search followed by Newton steps
on the wrapped angle difference.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import diffrax
import jax
import jax.numpy as jnp

from bayeshopf.model import hybrid, normal_form
from bayeshopf.model.coordinate_map import MLPParams, mlp, mlp_shapes
from bayeshopf.model.hybrid import HopfParams, ModelSpec


@dataclass(frozen=True)
class SpeedSpec:
    """Static structure of the speed model.

    Attributes:
        n_h: Harmonics of Ω in θ (0: constant along each orbit).
        nn_width: Neurons per hidden layer of the speed MLP.
        nn_depth: Hidden layers of the speed MLP.
        omega_ref: Prior centre of ω0 (rad/s), from the measured frequencies.
        omega_spread: Prior scale of the speed MLP's output scale, relative to
            ``|omega_ref|`` (from the spread of the measured frequencies).
        r_scale: Scale of the radius input (the typical normal-form radius).
        rtol: Relative tolerance of the phase ODE.
        atol: Absolute tolerance of the phase ODE.
        max_steps: Most ODE steps per solve.
        n_quad: Points of the trapezoidal rule for the period.
    """

    n_h: int = 1
    nn_width: int = 8
    nn_depth: int = 1
    omega_ref: float = 1.0
    omega_spread: float = 0.05
    r_scale: float = 1.0
    rtol: float = 1e-6
    atol: float = 1e-6
    max_steps: int = 2048
    n_quad: int = 128

    @property
    def nn_shapes(self) -> list[tuple[int, int]]:
        """Weight shapes of the speed MLP (inputs r/r̄, μ̃; outputs 2n_h+1)."""
        return mlp_shapes(2, self.nn_width, self.nn_depth, 2 * self.n_h + 1)

    def to_dict(self) -> dict:
        """JSON-serialisable form."""
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


class SpeedParams(NamedTuple):
    """Parameters of Ω (one draw).

    Attributes:
        omega0: Fundamental angular frequency ω0 (rad/s).
        nn: Weights of the MLP ``NN_Ω(r, μ̃)``.
        nn_scale: Output scale ``s_Ω`` (rad/s).
    """

    omega0: jax.Array
    nn: MLPParams
    nn_scale: jax.Array


def speed_params_from_sites(sites: dict, spec: SpeedSpec) -> SpeedParams:
    """Build :class:`SpeedParams` from NumPyro site values (``omega0``, ``om_W*``…)."""
    n = len(spec.nn_shapes)
    nn = MLPParams(
        tuple(sites[f"om_W{i}"] for i in range(n)), tuple(sites[f"om_b{i}"] for i in range(n))
    )
    return SpeedParams(sites["omega0"], nn, sites["om_scale"])


def fourier_basis(theta, n_h: int):
    """``[1, cos θ, …, cos n_hθ, sin θ, …, sin n_hθ]``, shape ``theta.shape + (2n_h+1,)``."""
    theta = jnp.asarray(theta)
    k = jnp.arange(1, n_h + 1, dtype=theta.dtype)
    kt = theta[..., None] * k
    return jnp.concatenate([jnp.ones_like(theta)[..., None], jnp.cos(kt), jnp.sin(kt)], axis=-1)


def speed(params: SpeedParams, r, theta, mu_tilde, spec: SpeedSpec):
    """``Ω(r, θ, μ) = ω0 + s_Ω NN(r, μ̃)ᵀ [1, cos kθ, sin kθ]`` (eq. Om_V), scalar r and μ̃."""
    coef = mlp(params.nn, jnp.stack([r / spec.r_scale, mu_tilde]))
    return params.omega0 + params.nn_scale * fourier_basis(theta, spec.n_h) @ coef


def period(params: SpeedParams, r, mu_tilde, spec: SpeedSpec):
    """``T = ∫₀^{2π} dθ / Ω(r, θ, μ)`` by the trapezoidal rule (periodic: geometric convergence).

    Returns ``nan`` where Ω changes sign on the orbit (no oscillation).
    """
    theta = jnp.linspace(0.0, 2.0 * jnp.pi, spec.n_quad, endpoint=False)
    coef = mlp(params.nn, jnp.stack([r / spec.r_scale, mu_tilde]))
    om = params.omega0 + params.nn_scale * fourier_basis(theta, spec.n_h) @ coef
    ok = jnp.all(om > 0) | jnp.all(om < 0)
    T = 2.0 * jnp.pi * jnp.mean(1.0 / om)
    return jnp.where(ok, jnp.abs(T), jnp.nan)


def frequency_hz(params: SpeedParams, map_params: HopfParams, mu, sign, spec: SpeedSpec,
                 map_spec: ModelSpec):
    """Mean oscillation frequency ``f = 1/T`` (Hz) of the LCO at μ on branch ``sign``."""
    r = normal_form.lco_radius(mu, map_params.mu0, map_params.a2, sign, map_params.a4)
    return 1.0 / period(params, r, map_spec.mu_tilde(mu), spec)


def integrate_phase(params: SpeedParams, r, mu_tilde, theta0, t, spec: SpeedSpec,
                    *, return_steps: bool = False):
    """θ(t) from ``θ̇ = Ω(r, θ, μ)``, ``θ(t[0]) = θ0``, saved at the times ``t``.

    Diffrax Tsit5 with a PID step-size controller (``spec.rtol``, ``spec.atol``);
    the solution is not wrapped, so it increases by 2π per period.

    Args:
        params: Speed parameters.
        r: LCO radius (fixed point of the radial equation).
        mu_tilde: Scaled bifurcation parameter μ̃.
        theta0: Phase at ``t[0]``.
        t: Increasing save times, shape ``(n_t,)``.
        spec: Speed structure and solver tolerances.
        return_steps: Also return the number of accepted steps.

    Returns:
        θ at ``t``, shape ``(n_t,)`` (and the step count).
    """
    term = diffrax.ODETerm(lambda s, th, args: speed(params, r, th, mu_tilde, spec))
    sol = diffrax.diffeqsolve(
        term, diffrax.Tsit5(), t0=t[0], t1=t[-1], dt0=None, y0=jnp.asarray(theta0, t.dtype),
        saveat=diffrax.SaveAt(ts=t),
        stepsize_controller=diffrax.PIDController(rtol=spec.rtol, atol=spec.atol),
        max_steps=spec.max_steps, throw=False,
    )
    ys = jnp.where(sol.result == diffrax.RESULTS.successful, sol.ys, jnp.nan)
    return (ys, sol.stats["num_accepted_steps"]) if return_steps else ys


def _wrap(x):
    """Wrap an angle to ``(−π, π]``."""
    return jnp.angle(jnp.exp(1j * x))


def initial_phase(map_params: HopfParams, mu, sign, w1, map_spec: ModelSpec,
                  *, n_grid: int = 256, n_newton: int = 8):
    """θ0 with ``ang(U12(r[cos θ0, sin θ0], μ̃)) = ang(w1)`` (eq. zp_ang), in ``(−π, π]``.

    ``w1`` is the measured first point in the planar frame and ``ang`` the angle
    about the frame centre. The grid point with the smallest wrapped angle
    difference starts Newton's method on ``wrap(ang(U12(θ)) − ang(w1))``; the
    wrapping makes it valid across ±π. Works on either branch (only r differs).

    Args:
        map_params: Map parameters (one draw).
        mu: Bifurcation parameter.
        sign: +1 stable, −1 unstable branch.
        w1: Measured point in the frame, shape ``(2,)``.
        map_spec: The map's structure.
        n_grid: Grid points for the start.
        n_newton: Newton iterations.

    Returns:
        θ0 (``nan`` where the branch does not exist).
    """
    target = jnp.arctan2(w1[1], w1[0])

    def resid(phi):
        p = hybrid.orbit_at(map_params, mu, sign, phi, map_spec)
        return _wrap(jnp.arctan2(p[..., 1], p[..., 0]) - target)

    grid = jnp.linspace(-jnp.pi, jnp.pi, n_grid, endpoint=False)
    phi = grid[jnp.argmin(jnp.abs(resid(grid)))]
    dres = jax.grad(resid)

    def newton(phi, _):
        step = resid(phi) / dres(phi)
        # stay within one grid cell of the start: the root is bracketed there
        step = jnp.clip(step, -2 * jnp.pi / n_grid, 2 * jnp.pi / n_grid)
        return phi - step, None

    phi, _ = jax.lax.scan(newton, phi, None, length=n_newton)
    return _wrap(phi)


def trajectory_in_frame(params: SpeedParams, map_params: HopfParams, mu, sign, theta0, t,
                        spec: SpeedSpec, map_spec: ModelSpec):
    """Predicted trajectory ``w(t) = U12(r[cos θ(t), sin θ(t)], μ̃)`` in the frame, ``(n_t, 2)``."""
    r = normal_form.lco_radius(mu, map_params.mu0, map_params.a2, sign, map_params.a4)
    theta = integrate_phase(params, r, map_spec.mu_tilde(mu), theta0, t, spec)
    return hybrid.orbit_at(map_params, mu, sign, theta, map_spec)
