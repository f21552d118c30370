r"""Periodic orbits by single shooting, with their Floquet multipliers.

A periodic orbit of period :math:`T` through :math:`x_0` solves

.. math::  \varphi_T(x_0; \mu) - x_0 = 0, \qquad (x_0 - \hat x)\cdot f(\hat x, \mu) = 0,

where :math:`\varphi_T` is the flow and the second (phase) condition puts
:math:`x_0` on the hyperplane through a reference point :math:`\hat x` (a
guess, or the previous orbit of a continuation) orthogonal to the flow there.
With time scaled to :math:`s = t/T \in [0, 1]`, one adaptive diffrax solve
(Dormand–Prince 8(7), ``diffrax.Dopri8``; tolerances ``rtol``/``atol``)
integrates the state together with its variational equations

.. math::

    x' = T f(x, \mu), \quad \Phi' = T J(x, \mu)\,\Phi, \quad
    w' = T\,(J(x, \mu)\,w + \partial_\mu f(x, \mu)),
    \qquad \Phi(0) = I,\ w(0) = 0,

so that :math:`\partial\varphi_T/\partial x_0 = \Phi(1)` (the monodromy matrix),
:math:`\partial\varphi_T/\partial T = f(\varphi_T(x_0), \mu)` and
:math:`\partial\varphi_T/\partial\mu = w(1)`: Newton's method gets its exact
Jacobian from the same solve. The eigenvalues of the monodromy matrix are the
Floquet multipliers; one is 1 (along the flow) and the orbit is stable when all
the others lie inside the unit circle.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import NamedTuple

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from bayeshopf._x64 import ensure_x64
from bayeshopf.simulators.base import SimulationError, System
from bayeshopf.simulators.compiled import program

__all__ = ["PeriodicOrbit", "batch_size", "floquet_stable", "padded", "periodic_orbit",
           "sample_batch", "sample_orbit"]


#: The smallest batch of more than one orbit: on a CPU a batch of two costs about
#: as much to run as one of four, and each size is another program to compile.
MIN_BATCH = 4


def batch_size(count: int) -> int:
    """The batch ``count`` orbits are padded to: 1, else a power of two, at least :data:`MIN_BATCH`.

    The power of two is the smallest not below ``count``.

    A batched program compiles once per shape, so padding (repeating the last
    orbit, dropped from the result) lets one program serve every count up to it.
    """
    if count <= 1:
        return 1
    return max(MIN_BATCH, 1 << (count - 1).bit_length())


def padded(*arrays) -> tuple:
    """``arrays`` (one row per orbit) padded to :func:`batch_size` rows, the last one repeated.

    Returns NumPy arrays (a compiled program takes them as they are, without a
    JAX array made per argument first); a caller keeps the first
    ``len(arrays[0])`` rows of the result.
    """
    rows = [np.asarray(a) for a in arrays]
    pad = batch_size(len(rows[0])) - len(rows[0])
    return tuple(np.concatenate([a, np.repeat(a[-1:], pad, axis=0)]) if pad else a
                 for a in rows)


#: Default tolerances of the adaptive solver.
RTOL, ATOL = 1e-10, 1e-12
#: Default number of points an orbit is sampled at (uniform in time over one period).
N_POINTS = 256
#: Refinement factor of the trigonometric interpolation used for peak-to-peak.
_PTP_REFINE = 16


class Shot(NamedTuple):
    """Shooting solves: end point, its derivatives, and whether the solver succeeded.

    One orbit's, or a batch's with the orbits along the leading axis.
    """

    x1: np.ndarray
    monodromy: np.ndarray
    dx_dmu: np.ndarray
    f1: np.ndarray
    ok: bool | np.ndarray


@functools.lru_cache(maxsize=64)
def param_tree(system: System) -> dict:
    """``system.param_tree()``, built once per system (systems are immutable)."""
    return system.param_tree()


#: Largest number of solver steps per period.
MAX_STEPS = 2**16


class _Kernels(NamedTuple):
    f: object
    shoot: object
    sample: object
    sample_batch: object
    f_batch: object
    shoot_batch: object


def kernels(system: System, rtol: float = RTOL, atol: float = ATOL, *,
            max_steps: int = MAX_STEPS, mu_sensitivity: bool = True) -> _Kernels:
    r"""Compiled shooting and sampling functions of one system, one orbit or a batch.

    ``shoot(x0, T, mu, p)`` integrates one period of the state with its
    variational equations (module docstring) and returns one flat array
    :math:`(x_1, \Phi(1), w(1), f(x_1, \mu), \text{ok})` (see :func:`split_shot`);
    ``sample(x0, T, mu, p, n)`` gives the states at :math:`t_k = kT/n`. The
    ``*_batch`` forms map them over a leading axis of ``x0``, ``T`` and ``mu``
    (one set of parameters ``p``). Without ``mu_sensitivity`` the solve leaves
    out :math:`w` (returned as zeros), which also takes it out of the step
    size control. A solve that needs more than ``max_steps`` steps fails
    (``ok`` false) instead of raising.

    Cached per right-hand side, not per system: the parameters are arguments
    (:func:`param_tree`), so the copies of a system that differ in their
    parameter values only (``System.with_params``: the calibration's and the
    continuation's variants) share one traced and compiled solver.
    """
    return _kernels(system.rhs, rtol, atol, max_steps, mu_sensitivity)


@functools.lru_cache(maxsize=32)
def _kernels(rhs, rtol: float, atol: float, max_steps: int = MAX_STEPS,
             mu_sensitivity: bool = True) -> _Kernels:
    ensure_x64()
    jac_x = jax.jacfwd(rhs, argnums=0)
    jac_mu = jax.jacfwd(rhs, argnums=1)
    solver = diffrax.Dopri8()
    ctrl = diffrax.PIDController(rtol=rtol, atol=atol)

    def aug(s, y, args):
        x, phi, w = y
        T, mu, p = args
        J = jac_x(x, mu, p)
        return T * rhs(x, mu, p), T * (J @ phi), T * (J @ w + jac_mu(x, mu, p))

    def aug_x(s, y, args):
        x, phi = y
        T, mu, p = args
        return T * rhs(x, mu, p), T * (jac_x(x, mu, p) @ phi)

    def shoot(x0, T, mu, p):
        n = x0.shape[0]
        y0 = (x0, jnp.eye(n), jnp.zeros(n)) if mu_sensitivity else (x0, jnp.eye(n))
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(aug if mu_sensitivity else aug_x), solver, 0.0, 1.0, None, y0,
            args=(T, mu, p), stepsize_controller=ctrl, saveat=diffrax.SaveAt(t1=True),
            max_steps=max_steps, throw=False,
        )
        x1, phi, *w = (leaf[-1] for leaf in sol.ys)
        w = w[0] if mu_sensitivity else jnp.zeros(n)
        ok = (sol.result == diffrax.RESULTS.successful).astype(x0.dtype)
        # one flat array: a single device-to-host transfer per shot
        return jnp.concatenate([x1, phi.ravel(), w, rhs(x1, mu, p), ok[None]])

    def field_(s, x, args):
        T, mu, p = args
        return T * rhs(x, mu, p)

    def sample(x0, T, mu, p, n):
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field_), solver, 0.0, 1.0, None, x0, args=(T, mu, p),
            stepsize_controller=ctrl, saveat=diffrax.SaveAt(ts=jnp.arange(n) / n),
            max_steps=max_steps, throw=False,
        )
        return sol.ys

    return _Kernels(
        f=jax.jit(rhs),
        shoot=jax.jit(shoot),
        sample=jax.jit(sample, static_argnums=4),
        sample_batch=jax.jit(jax.vmap(sample, in_axes=(0, 0, 0, None, None)), static_argnums=4),
        f_batch=jax.jit(jax.vmap(rhs, in_axes=(0, 0, None))),
        shoot_batch=jax.jit(jax.vmap(shoot, in_axes=(0, 0, 0, None))),
    )


def split_shot(out: np.ndarray, n: int) -> Shot:
    """The parts of ``shoot``'s flat output (last axis) for ``n`` states, any leading axes."""
    lead = out.shape[:-1]
    return Shot(x1=out[..., :n], monodromy=out[..., n:n + n * n].reshape(*lead, n, n),
                dx_dmu=out[..., n + n * n:2 * n + n * n], f1=out[..., 2 * n + n * n:3 * n + n * n],
                ok=out[..., -1] > 0.5)


def shoot(system: System, x0, T, mu, *, rtol: float = RTOL, atol: float = ATOL) -> Shot:
    r"""Integrate one period: :math:`\varphi_T(x_0)` with its derivatives (module docstring)."""
    ensure_x64()
    k = kernels(system, rtol, atol)
    n = system.n_states
    args = (jnp.asarray(x0, dtype=jnp.float64), jnp.asarray(T, dtype=jnp.float64),
            jnp.asarray(mu, dtype=jnp.float64), param_tree(system))
    fn = program(system.rhs, "shot", lambda: k.shoot, args, (rtol, atol, MAX_STEPS))
    out = np.asarray(fn(*args))
    s = split_shot(out, n)
    return s._replace(ok=bool(s.ok))


def sample_orbit(system: System, x0, T, mu, n_points: int = N_POINTS, *,
                 rtol: float = RTOL, atol: float = ATOL) -> np.ndarray:
    """States at ``t_k = k T / n_points``, ``k = 0..n_points−1``, shape ``(n_points, n)``."""
    ensure_x64()
    return np.asarray(sample_batch(system, np.asarray(x0, np.float64)[None],
                                   np.atleast_1d(np.float64(T)), np.atleast_1d(np.float64(mu)),
                                   n_points, rtol=rtol, atol=atol)[0])


def sample_batch(system: System, x0, T, mu, n_points: int = N_POINTS, *,
                 rtol: float = RTOL, atol: float = ATOL) -> np.ndarray:
    """:func:`sample_orbit` of ``R`` orbits at once, shape ``(R, n_points, n)``.

    The orbits are padded to :func:`batch_size` (the last repeated), so that one
    compiled program serves every number of orbits up to it, and it is stored
    across processes where the system's code allows
    (:mod:`bayeshopf.simulators.compiled`).
    """
    ensure_x64()
    k = kernels(system, rtol, atol)
    R = len(x0)
    args = (*padded(np.asarray(x0, np.float64), np.asarray(T, np.float64),
                    np.asarray(mu, np.float64)), param_tree(system))
    n_points = int(n_points)

    def states(x, t, m, p):
        return k.sample_batch(x, t, m, p, n_points)

    fn = program(system.rhs, "states", lambda: states, args, (rtol, atol, MAX_STEPS, n_points))
    return np.asarray(fn(*args))[:R]


def floquet_stable(multipliers: np.ndarray, tol: float = 1e-6) -> bool:
    """Stable if every multiplier except the trivial one (closest to 1) has modulus < 1."""
    m = np.asarray(multipliers)
    rest = np.delete(m, int(np.argmin(np.abs(m - 1.0))))
    return bool(rest.size == 0 or np.max(np.abs(rest)) < 1.0 - tol)


def _sorted_multipliers(monodromy: np.ndarray) -> np.ndarray:
    ev = np.linalg.eigvals(monodromy)
    return ev[np.argsort(-np.abs(ev))]


def refined_ptp(samples: np.ndarray, refine: int = _PTP_REFINE) -> np.ndarray:
    """Peak-to-peak of periodic samples (axis 0) from their trigonometric interpolant.

    The samples are zero-padded in frequency to ``refine`` times as many points,
    so the extremes between samples are found to spectral accuracy.
    """
    x = np.asarray(samples, dtype=np.float64)
    n = x.shape[0]
    c = np.fft.rfft(x, axis=0)
    if n % 2 == 0:  # split the Nyquist term so the interpolant stays real and exact
        c[-1] *= 0.5
    fine = np.fft.irfft(c, n * refine, axis=0) * refine
    return fine.max(axis=0) - fine.min(axis=0)


@dataclass(frozen=True)
class PeriodicOrbit:
    r"""One periodic orbit (limit cycle) at a fixed μ.

    Attributes:
        mu: The bifurcation parameter.
        period: :math:`T`.
        x0: The point at :math:`t = 0`, shape ``(n,)``.
        states: States at :math:`t_k = kT/n_{pts}`, shape ``(n_pts, n)``.
        floquet: Floquet multipliers (complex), by modulus descending.
        stable: Whether all non-trivial multipliers lie inside the unit circle.
        state_names: Names of the states (columns of ``states``).
        amplitude: Peak-to-peak of every observed state over the orbit.
        mean: Mean over one period of every observed state.
    """

    mu: float
    period: float
    x0: np.ndarray
    states: np.ndarray
    floquet: np.ndarray
    stable: bool
    state_names: tuple[str, ...]
    amplitude: Mapping[str, float] = field(default_factory=dict)
    mean: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("x0", "states", "floquet"):
            a = np.array(getattr(self, name), copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @property
    def t(self) -> np.ndarray:
        """Sample times of ``states`` (one period, end excluded)."""
        return np.arange(self.states.shape[0]) * self.period / self.states.shape[0]

    @property
    def frequency_hz(self) -> float:
        """``1 / period``."""
        return 1.0 / self.period

    def channel(self, name: str) -> np.ndarray:
        """Samples of one state over the orbit."""
        if name not in self.state_names:
            raise SimulationError(
                f"state {name!r} expected among {', '.join(self.state_names)}; not found"
            )
        return self.states[:, self.state_names.index(name)]


def make_orbit(system: System, mu: float, period: float, x0: np.ndarray,
               monodromy: np.ndarray, states: np.ndarray) -> PeriodicOrbit:
    """Assemble a :class:`PeriodicOrbit` (amplitudes and means of the observed states)."""
    ensure_x64()
    fl = _sorted_multipliers(monodromy)
    obs = states[:, list(system.observed_index)]
    ptp, mean = refined_ptp(obs), obs.mean(axis=0)
    return PeriodicOrbit(
        mu=float(mu), period=float(period), x0=np.asarray(x0), states=np.asarray(states),
        floquet=fl, stable=floquet_stable(fl), state_names=system.state_names,
        amplitude=MappingProxyType(dict(zip(system.observed, map(float, ptp), strict=True))),
        mean=MappingProxyType(dict(zip(system.observed, map(float, mean), strict=True))),
    )


def periodic_orbit(system: System, mu: float, x0, period: float, *, n_points: int = N_POINTS,
                   tol: float = 1e-10, max_iter: int = 25, rtol: float = RTOL,
                   atol: float = ATOL) -> PeriodicOrbit:
    r"""The periodic orbit at ``mu`` near the guess ``(x0, period)``, by Newton's method.

    Solves :math:`\varphi_T(x_0) - x_0 = 0` and :math:`(x_0 - \hat x)\cdot f(\hat x) = 0`
    (:math:`\hat x` the guess) for :math:`(x_0, T)` at fixed μ.

    Args:
        system: The system.
        mu: The bifurcation parameter.
        x0: Guess of a point on the orbit.
        period: Guess of the period.
        n_points: Number of samples of the returned orbit.
        tol: Convergence when the Newton step is below ``tol`` relative to the
            size of the orbit point and the period.
        max_iter: Largest number of Newton steps.
        rtol: Relative tolerance of the ODE solver.
        atol: Absolute tolerance of the ODE solver.

    Raises:
        SimulationError: If Newton's method does not converge.
    """
    ensure_x64()
    k = kernels(system, rtol, atol)
    p = param_tree(system)
    m = jnp.asarray(mu, dtype=jnp.float64)
    xhat = np.array(x0, dtype=np.float64)
    fhat = np.asarray(k.f(jnp.asarray(xhat), m, p))
    x, T = xhat.copy(), float(period)
    n = x.size
    for _ in range(max_iter):
        s = shoot(system, x, T, mu, rtol=rtol, atol=atol)
        if not s.ok:
            break
        A = np.zeros((n + 1, n + 1))
        A[:n, :n] = s.monodromy - np.eye(n)
        A[:n, n] = s.f1
        A[n, :n] = fhat
        r = np.concatenate([s.x1 - x, [(x - xhat) @ fhat]])
        try:
            d = np.linalg.solve(A, -r)
        except np.linalg.LinAlgError:
            break
        x, T = x + d[:n], T + d[n]
        if T <= 0:
            break
        if np.max(np.abs(d[:n])) <= tol * (1 + np.max(np.abs(x))) and abs(d[n]) <= tol * T:
            s = shoot(system, x, T, mu, rtol=rtol, atol=atol)
            states = sample_orbit(system, x, T, mu, n_points, rtol=rtol, atol=atol)
            return make_orbit(system, mu, T, x, s.monodromy, states)
    raise SimulationError(
        f"{system.name}: no periodic orbit found at {system.parameter} = {float(mu):g} "
        f"near the guess (period {float(period):.4g}); Newton's method did not converge"
    )
