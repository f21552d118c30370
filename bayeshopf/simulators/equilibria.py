r"""Equilibria, their Jacobian eigenvalues, and the Hopf point.

An equilibrium :math:`x^*(\mu)` solves :math:`f(x^*, \mu) = 0` (Newton's method
with the Jacobian :math:`J = \partial f/\partial x` from :func:`jax.jacfwd`).
A Hopf point is a :math:`\mu_0` where a complex pair of eigenvalues of
:math:`J(x^*(\mu_0), \mu_0)` crosses the imaginary axis,
:math:`\lambda = \pm i\omega_0`: :func:`find_hopf` follows the equilibrium over a
grid of μ, brackets the first sign change of
:math:`g(\mu) = \max\{\operatorname{Re}\lambda : \operatorname{Im}\lambda \ne 0\}`
from negative to positive, and solves :math:`g(\mu_0) = 0` by Brent's method
(bisection safeguarded by secant steps).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import brentq

from bayeshopf._x64 import ensure_x64
from bayeshopf.simulators.base import SimulationError, System

__all__ = ["HopfPoint", "eigenvalues", "equilibrium", "find_hopf", "jacobian"]


@functools.lru_cache(maxsize=32)
def _fns(system: System):
    """Compiled ``f(x, mu, p)`` and ``J(x, mu, p)`` of one system."""
    return jax.jit(system.rhs), jax.jit(jax.jacfwd(system.rhs, argnums=0))


@functools.lru_cache(maxsize=64)
def _params(system: System) -> dict:
    return system.param_tree()


def _mu(mu) -> jax.Array:
    return jnp.asarray(mu, dtype=jnp.float64)


def jacobian(system: System, x, mu) -> np.ndarray:
    r"""The Jacobian :math:`J = \partial f/\partial x` at ``(x, mu)``, shape ``(n, n)``."""
    ensure_x64()
    _, jac = _fns(system)
    return np.asarray(jac(jnp.asarray(x, dtype=jnp.float64), _mu(mu), _params(system)))


def equilibrium(system: System, mu, x0=None, *, tol: float = 1e-12, max_iter: int = 50
                ) -> np.ndarray:
    r"""An equilibrium :math:`x^*` with :math:`f(x^*, \mu) = 0`, by Newton's method.

    Args:
        system: The system.
        mu: The bifurcation parameter.
        x0: Starting guess (default the origin).
        tol: Convergence when :math:`\|\Delta x\|_\infty \le` ``tol`` (1 + :math:`\|x\|_\infty`).
        max_iter: Largest number of Newton steps.

    Raises:
        SimulationError: If Newton's method does not converge.
    """
    ensure_x64()
    f, jac = _fns(system)
    p = _params(system)
    x = np.zeros(system.n_states) if x0 is None else np.array(x0, dtype=np.float64)
    m = _mu(mu)
    for _ in range(max_iter):
        r = np.asarray(f(jnp.asarray(x), m, p))
        J = np.asarray(jac(jnp.asarray(x), m, p))
        try:
            dx = np.linalg.solve(J, -r)
        except np.linalg.LinAlgError:
            break
        x = x + dx
        if np.max(np.abs(dx)) <= tol * (1.0 + np.max(np.abs(x))):
            return x
    raise SimulationError(
        f"{system.name}: no equilibrium found at {system.parameter} = {float(mu):g} "
        f"from {np.array2string(np.asarray(x0 if x0 is not None else x), precision=3)}"
    )


def eigenvalues(system: System, mu, x=None) -> np.ndarray:
    """Eigenvalues of the Jacobian at the equilibrium (or at ``x``), by real part descending."""
    ensure_x64()
    x = equilibrium(system, mu) if x is None else x
    ev = np.linalg.eigvals(jacobian(system, x, mu))
    return ev[np.argsort(-ev.real)]


@dataclass(frozen=True)
class HopfPoint:
    r"""A Hopf point: eigenvalues :math:`\pm i\omega_0` at :math:`\mu_0`.

    Attributes:
        mu: :math:`\mu_0`.
        omega: :math:`\omega_0` in rad/s (per unit time of the system).
        equilibrium: :math:`x^*(\mu_0)`, shape ``(n,)``.
        eigenvector: Critical eigenvector for :math:`+i\omega_0` (complex, unit
            norm, phase chosen so that its real and imaginary parts are
            orthogonal with the real part the longer).
        crossing_speed: :math:`d\operatorname{Re}\lambda/d\mu` at :math:`\mu_0`
            (positive: the equilibrium loses stability as μ grows).
    """

    mu: float
    omega: float
    equilibrium: np.ndarray
    eigenvector: np.ndarray
    crossing_speed: float

    @property
    def frequency_hz(self) -> float:
        r""":math:`\omega_0 / 2\pi`."""
        return self.omega / (2.0 * np.pi)

    @property
    def period(self) -> float:
        r""":math:`2\pi / \omega_0`."""
        return 2.0 * np.pi / self.omega


def _max_oscillatory(system: System, mu: float, x: np.ndarray) -> tuple[float, np.ndarray]:
    ev = np.linalg.eigvals(jacobian(system, x, mu))
    osc = ev[np.abs(ev.imag) > 1e-9 * (1.0 + np.abs(ev))]
    return (float(np.max(osc.real)) if osc.size else -np.inf), ev


def _normalise(v: np.ndarray) -> np.ndarray:
    """Unit ``v`` rotated so that Re v ⟂ Im v and |Re v| ≥ |Im v|."""
    v = v / np.linalg.norm(v)
    p, q = v.real, v.imag
    phi = 0.5 * np.arctan2(-2.0 * p @ q, p @ p - q @ q)   # maximises |Re(e^{iφ} v)|
    v = v * np.exp(1j * phi)
    return v if v.real @ v.real >= v.imag @ v.imag else v * 1j


def find_hopf(system: System, mu_range: tuple[float, float] | None = None, *,
              n_grid: int = 81, xtol: float = 1e-12) -> HopfPoint:
    r"""The first Hopf point in ``mu_range`` where the equilibrium loses stability.

    The equilibrium is followed from ``mu_range[0]`` (starting at the origin)
    over ``n_grid`` values of μ; the first interval where
    :math:`g(\mu) = \max \operatorname{Re}\lambda` over the complex eigenvalues
    changes sign from negative to positive is refined by Brent's method to
    ``xtol``.

    Args:
        system: The system.
        mu_range: Interval searched (default ``system.mu_range``).
        n_grid: Number of grid points.
        xtol: Absolute tolerance on :math:`\mu_0`.

    Raises:
        SimulationError: If no such crossing is found.
    """
    ensure_x64()
    lo, hi = system.mu_range if mu_range is None else (float(mu_range[0]), float(mu_range[1]))
    grid = np.linspace(lo, hi, n_grid)
    x = None
    prev = None
    for a, b in zip(grid[:-1], grid[1:], strict=True):
        xa = equilibrium(system, a, x)
        xb = equilibrium(system, b, xa)
        ga = prev if prev is not None else _max_oscillatory(system, a, xa)[0]
        gb = _max_oscillatory(system, b, xb)[0]
        x, prev = xb, gb
        if ga < 0.0 <= gb:
            cache = {"x": xa}

            def g(mu, cache=cache):
                cache["x"] = equilibrium(system, mu, cache["x"])
                return _max_oscillatory(system, mu, cache["x"])[0]

            mu0 = brentq(g, a, b, xtol=xtol, rtol=4 * np.finfo(float).eps)
            x0 = equilibrium(system, mu0, cache["x"])
            ev, vec = np.linalg.eig(jacobian(system, x0, mu0))
            k = int(np.argmin(np.abs(ev.real) + 1e3 * (ev.imag <= 0)))
            h = 1e-6 * max(1.0, abs(mu0))
            speed = (g(mu0 + h) - g(mu0 - h)) / (2 * h)
            return HopfPoint(mu=float(mu0), omega=float(ev[k].imag), equilibrium=x0,
                             eigenvector=_normalise(vec[:, k]), crossing_speed=float(speed))
    raise SimulationError(
        f"{system.name}: no Hopf point found for {lo:g} <= {system.parameter} <= {hi:g} "
        "(no complex pair of eigenvalues crosses into the right half-plane)"
    )
