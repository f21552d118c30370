r"""Pseudo-arclength continuation of the periodic orbits born at a Hopf point.

The unknowns are :math:`y = (x_0, T, \mu)`. From a converged point :math:`y_k`
with unit tangent :math:`\tau_k`, the predictor is :math:`y_k + \Delta s\,\tau_k`
and Newton's method corrects it on

.. math::

    \varphi_T(x_0; \mu) - x_0 = 0, \qquad
    (x_0 - x_{0,k})\cdot f(x_{0,k}, \mu_k) = 0, \qquad
    \tau_k\cdot(y - y_k) - \Delta s = 0,

with the exact Jacobian of the shooting map (:mod:`bayeshopf.simulators.periodic`).
The new tangent is the null vector of the Jacobian of the first two blocks,
oriented along :math:`\tau_k`. The step :math:`\Delta s` grows after easy
corrections and shrinks after hard or failed ones.

The first orbit is the linear one of the Hopf point: with the critical
eigenvector :math:`v = p + iq` (:math:`p \perp q`), the orbit of
:math:`\dot x = J x` through :math:`x^* + \varepsilon\,\hat p` has period
:math:`2\pi/\omega_0`. It is corrected with μ free, fixing its amplitude
:math:`(x_0 - x^*)\cdot\hat p = \varepsilon` and its phase
:math:`(x_0 - x^*)\cdot q = 0`, and the continuation leaves in the direction of
growing amplitude. So for a subcritical Hopf point it follows the unstable
branch down to the fold, turns there and follows the stable branch up; for a
supercritical one it follows the stable branch. It stops when μ leaves
``mu_range`` (that last point is kept).

A fold (saddle-node of cycles) is where :math:`d\mu/ds` changes sign; it is
located to solver precision by Brent's method on the μ-component of the
tangent along the arc between the two points that bracket it. The path is cut
at every fold into :class:`Branch` records, each labelled stable or unstable by
the Floquet multipliers of its orbits, with the fold orbit at its end.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import jax.numpy as jnp
import numpy as np
from scipy.optimize import brentq

from bayeshopf._x64 import ensure_x64
from bayeshopf.simulators.base import SimulationError, System
from bayeshopf.simulators.equilibria import HopfPoint, find_hopf
from bayeshopf.simulators.periodic import (
    ATOL,
    N_POINTS,
    RTOL,
    PeriodicOrbit,
    _sorted_multipliers,
    floquet_stable,
    kernels,
    param_tree,
    periodic_orbit,
    refined_ptp,
    sample_batch,
    shoot,
)

__all__ = ["BifurcationDiagram", "Branch", "Fold", "continue_from_hopf", "orbit_at"]


def _frozen(a) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class Fold:
    """A fold (saddle-node) of periodic orbits.

    Attributes:
        mu: Where the stable and unstable branches meet.
        period: Period of the fold orbit.
        x0: A point of the fold orbit.
        amplitude: Peak-to-peak of every observed state over the fold orbit.
    """

    mu: float
    period: float
    x0: np.ndarray
    amplitude: Mapping[str, float]


@dataclass(frozen=True, eq=False)
class Branch:
    """A branch of periodic orbits between a Hopf point, folds and the end of ``mu_range``.

    Arrays run along the branch in continuation order; ``m`` points.

    Attributes:
        kind: ``"stable"`` or ``"unstable"`` (the majority of ``stable``).
        mu: Bifurcation parameter, shape ``(m,)``.
        period: Periods, shape ``(m,)``.
        amplitude: Observed state -> peak-to-peak, shape ``(m,)`` each.
        mean: Observed state -> mean over the orbit, shape ``(m,)`` each.
        stable: Floquet stability of each orbit, shape ``(m,)``.
        floquet: Floquet multipliers, shape ``(m, n)``, by modulus descending.
        x0: Point of each orbit at t = 0, shape ``(m, n)``.
        orbits: States at ``t_k = k T/n_pts``, shape ``(m, n_pts, n)``.
        system: The system.
        solved: Orbits already solved on this branch, by ``(μ, n_points)``:
            :meth:`orbit` returns these instead of solving again (a diagram of
            :mod:`bayeshopf.simulators.stored` carries the stored ones).
    """

    kind: str
    mu: np.ndarray
    period: np.ndarray
    amplitude: Mapping[str, np.ndarray]
    mean: Mapping[str, np.ndarray]
    stable: np.ndarray
    floquet: np.ndarray
    x0: np.ndarray
    orbits: np.ndarray
    system: System = field(repr=False)
    solved: Mapping[tuple[float, int], PeriodicOrbit] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        for name in ("mu", "period", "stable", "floquet", "x0", "orbits"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        for name in ("amplitude", "mean"):
            object.__setattr__(self, name, MappingProxyType(
                {k: _frozen(v) for k, v in getattr(self, name).items()}))
        object.__setattr__(self, "solved", MappingProxyType(dict(self.solved)))

    def __len__(self) -> int:
        return int(self.mu.size)

    @property
    def mu_span(self) -> tuple[float, float]:
        """``(min μ, max μ)`` over the branch."""
        return float(self.mu.min()), float(self.mu.max())

    def exists(self, mu: float) -> bool:
        """Whether the branch has an orbit at ``mu`` (within its computed span)."""
        lo, hi = self.mu_span
        return lo <= float(mu) <= hi

    def orbit(self, mu: float, *, n_points: int | None = None) -> PeriodicOrbit:
        """The orbit of this branch at ``mu`` (see :func:`orbit_at`)."""
        return _orbit_on(self, mu, n_points)

    def guess(self, mu: float) -> tuple[np.ndarray, float, float]:
        """``(x0, period, peak-to-peak of the first observed state)`` at ``mu``, interpolated.

        Linear in μ between the two continuation points that bracket ``mu``
        (the nearest point where none does): the start of Newton's method for
        the orbit there (:meth:`orbit`), or of a batch of them.

        Raises:
            SimulationError: If ``mu`` is outside the branch's span.
        """
        mu = float(mu)
        lo, hi = self.mu_span
        system = self.system
        u = system.parameter_units
        if not lo <= mu <= hi:
            raise SimulationError(
                f"{self.kind} branch of {system.name}: no LCO at {system.parameter} = {mu:g}"
                f"{' ' + u if u else ''}; it exists for {lo:.4g} <= {system.parameter} <= "
                f"{hi:.4g}{' ' + u if u else ''}"
            )
        m, z1 = self.mu, self.amplitude[system.observed[0]]
        idx = [i for i in range(len(m) - 1)
               if (m[i] - mu) * (m[i + 1] - mu) <= 0 and m[i + 1] != m[i]]
        if not idx:
            i = int(np.argmin(np.abs(m - mu)))
            return self.x0[i].copy(), float(self.period[i]), float(z1[i])
        i = idx[0]
        w = (mu - m[i]) / (m[i + 1] - m[i])
        return ((1 - w) * self.x0[i] + w * self.x0[i + 1],
                float((1 - w) * self.period[i] + w * self.period[i + 1]),
                float((1 - w) * z1[i] + w * z1[i + 1]))


@dataclass(frozen=True, eq=False)
class BifurcationDiagram:
    """Periodic orbits continued from a Hopf point.

    Attributes:
        system: The system.
        hopf: The Hopf point the orbits are born at.
        folds: Folds of periodic orbits passed, in continuation order.
        branches: The path cut at the folds, in continuation order.
        criticality: ``"subcritical"`` if the first branch is unstable (orbits
            coexist with the stable equilibrium before the Hopf point), else
            ``"supercritical"``.
        runtime_s: Wall time of the continuation (compilation included; for a
            stored diagram, that of the run that stored it).
        n_steps: Number of continuation steps taken.
    """

    system: System
    hopf: HopfPoint
    folds: tuple[Fold, ...]
    branches: tuple[Branch, ...]
    criticality: str
    runtime_s: float
    n_steps: int

    def branch(self, kind: str) -> Branch:
        """The first branch of ``kind`` (``"stable"`` or ``"unstable"``).

        Raises:
            SimulationError: If there is none.
        """
        if kind not in ("stable", "unstable"):
            raise SimulationError(f"branch must be 'stable' or 'unstable'; got {kind!r}")
        for b in self.branches:
            if b.kind == kind:
                return b
        raise SimulationError(
            f"{self.system.name}: no {kind} branch of periodic orbits in "
            f"{self.system.parameter} in [{self.system.mu_range[0]:g}, "
            f"{self.system.mu_range[1]:g}] (the Hopf point at {self.hopf.mu:.4g} is "
            f"{self.criticality})"
        )

    def orbit_at(self, mu: float, branch: str = "stable", *,
                 n_points: int | None = None) -> PeriodicOrbit:
        """The orbit at ``mu`` on ``branch`` (see :func:`orbit_at`)."""
        return _orbit_on(self.branch(branch), mu, n_points)

    def summary(self) -> dict:
        """JSON-serialisable Hopf point, folds and branch spans."""
        return {
            "system": self.system.name,
            "parameter": self.system.parameter,
            "parameter_units": self.system.parameter_units,
            "hopf": {"mu": self.hopf.mu, "omega": self.hopf.omega,
                     "frequency_hz": self.hopf.frequency_hz},
            "criticality": self.criticality,
            "folds": [{"mu": f.mu, "period": f.period, "amplitude": dict(f.amplitude)}
                      for f in self.folds],
            "branches": [{"kind": b.kind, "mu_span": list(b.mu_span), "n_points": len(b)}
                         for b in self.branches],
        }


class _Path:
    """Converged continuation points ``y = (x0, T, mu)`` with tangents and monodromies."""

    def __init__(self) -> None:
        self.y: list[np.ndarray] = []
        self.tau: list[np.ndarray] = []
        self.mono: list[np.ndarray] = []

    def add(self, y, tau, mono) -> None:
        self.y.append(y)
        self.tau.append(tau)
        self.mono.append(mono)


class _Corrector:
    """Newton on the shooting, phase and one scalar constraint (arclength or amplitude)."""

    def __init__(self, system: System, rtol: float, atol: float, tol: float, max_iter: int):
        self.system, self.rtol, self.atol = system, rtol, atol
        self.tol, self.max_iter = tol, max_iter
        self.n = system.n_states
        k = kernels(system, rtol, atol)
        p = param_tree(system)
        self.f = lambda x, mu: np.asarray(k.f(jnp.asarray(x), jnp.asarray(mu, jnp.float64), p))

    def jac(self, y) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        """Residual of φ_T(x0) − x0, its Jacobian wrt y (n × (n+2)), monodromy, ok."""
        n = self.n
        s = shoot(self.system, y[:n], y[n], y[n + 1], rtol=self.rtol, atol=self.atol)
        J = np.zeros((n, n + 2))
        J[:, :n] = s.monodromy - np.eye(n)
        J[:, n] = s.f1
        J[:, n + 1] = s.dx_dmu
        return s.x1 - y[:n], J, s.monodromy, s.ok

    def solve(self, y, phase, extra):
        """Newton from ``y``. ``phase = (xref, fref)``; ``extra = (a, c)``: ``a·y = c``.

        Returns ``(y, iterations, monodromy, shooting Jacobian)`` or ``None``.
        """
        n = self.n
        xref, fref = phase
        a, c = extra
        y = np.array(y, dtype=np.float64)
        prev = np.inf
        for it in range(1, self.max_iter + 1):
            r, J, mono, ok = self.jac(y)
            if not ok or not np.all(np.isfinite(r)):
                return None
            res = np.concatenate([r, [(y[:n] - xref) @ fref, a @ y - c]])
            A = np.zeros((n + 2, n + 2))
            A[:n] = J
            A[n, :n] = fref
            A[n + 1] = a
            try:
                d = np.linalg.solve(A, -res)
            except np.linalg.LinAlgError:
                return None
            step = np.max(np.abs(d))
            if not np.isfinite(step) or (it > 3 and step > prev):
                return None
            prev = step
            y = y + d
            if y[n] <= 0:
                return None
            if step <= self.tol * (1.0 + np.max(np.abs(y))):
                r, J, mono, ok = self.jac(y)
                return (y, it, mono, J) if ok else None
        return None

    def tangent(self, J, fref, tau_prev) -> np.ndarray:
        """Null vector of [J; fref 0 0], unit, oriented along ``tau_prev``."""
        n = self.n
        A = np.zeros((n + 2, n + 2))
        A[:n] = J
        A[n, :n] = fref
        A[n + 1] = tau_prev
        b = np.zeros(n + 2)
        b[-1] = 1.0
        t = np.linalg.solve(A, b)
        t /= np.linalg.norm(t)
        return t if t @ tau_prev >= 0 else -t


def _start(system: System, hopf: HopfPoint, corr: _Corrector, eps: float):
    n = system.n_states
    v = hopf.eigenvector
    p, q = v.real / np.linalg.norm(v.real), v.imag
    y0 = np.concatenate([hopf.equilibrium + eps * p, [hopf.period, hopf.mu]])
    a = np.concatenate([p, [0.0, 0.0]])
    out = corr.solve(y0, (hopf.equilibrium, q), (a, a @ y0))
    if out is None:
        raise SimulationError(
            f"{system.name}: the small orbit near the Hopf point at {system.parameter} = "
            f"{hopf.mu:.6g} did not converge (try another start_amplitude)"
        )
    y, _, mono, J = out
    fref = corr.f(y[:n], y[n + 1])
    guess = np.concatenate([p, [0.0, 0.0]])
    tau = corr.tangent(J, fref, guess)
    return y, tau, mono


def _continue(system, hopf, corr, *, mu_range, ds, ds_min, ds_max, max_steps, eps):
    n = system.n_states
    lo, hi = mu_range
    y, tau, mono = _start(system, hopf, corr, eps)
    path = _Path()
    path.add(y, tau, mono)
    h = ds
    steps = 0
    while steps < max_steps:
        yk, tk = path.y[-1], path.tau[-1]
        fref = corr.f(yk[:n], yk[n + 1])
        out = corr.solve(yk + h * tk, (yk[:n], fref), (tk, tk @ yk + h))
        if out is None:
            h *= 0.5
            if h < ds_min:
                raise SimulationError(
                    f"{system.name}: continuation stalled at {system.parameter} = "
                    f"{yk[n + 1]:.6g} (step below {ds_min:g})"
                )
            continue
        y, it, mono, J = out
        tau = corr.tangent(J, corr.f(y[:n], y[n + 1]), tk)
        # keep steps short where the branch turns, so folds are bracketed tightly
        turn = float(np.arccos(np.clip(tau @ tk, -1.0, 1.0)))
        if turn > 0.3 and h > 2 * ds_min:
            h *= 0.5
            continue
        path.add(y, tau, mono)
        steps += 1
        if y[n + 1] < lo or y[n + 1] > hi:
            break
        h = min(ds_max, h * (1.5 if it <= 3 else 1.0 if it <= 5 else 0.6))
    return path, steps


def _refine_fold(corr: _Corrector, path: _Path, k: int):
    """Fold between path points k and k+1: Brent's method on τ_μ along the arc from k."""
    n = corr.n
    yk, tk = path.y[k], path.tau[k]
    fref = corr.f(yk[:n], yk[n + 1])
    s_end = float(tk @ (path.y[k + 1] - yk))
    memo: dict[float, tuple] = {}

    def point(s):
        if s not in memo:
            out = corr.solve(yk + s * tk, (yk[:n], fref), (tk, tk @ yk + s))
            if out is None:
                raise SimulationError("fold refinement: Newton's method failed")
            y, _, mono, J = out
            memo[s] = (y, corr.tangent(J, corr.f(y[:n], y[n + 1]), tk), mono)
        return memo[s]

    g0, g1 = path.tau[k][n + 1], path.tau[k + 1][n + 1]
    if g0 * g1 > 0:
        return None
    try:
        s_star = brentq(lambda s: point(s)[1][n + 1] if 0 < s < s_end else
                        (g0 if s <= 0 else g1), 0.0, s_end, xtol=1e-12 * max(1.0, s_end),
                        rtol=1e-12)
        return point(s_star)
    except SimulationError:  # the caller falls back on the path point nearest the fold
        return None


def _assemble(system: System, path: _Path, hopf: HopfPoint, corr: _Corrector, n_points: int,
              rtol: float, atol: float, runtime_start: float, steps: int) -> BifurcationDiagram:
    n = system.n_states
    Y = np.array(path.y)
    taus = np.array(path.tau)
    monos = list(path.mono)
    # folds: sign changes of dμ/ds
    sgn = np.sign(taus[:, n + 1])
    cuts: list[tuple[int, np.ndarray, np.ndarray]] = []
    for k in range(len(Y) - 1):
        if sgn[k] != 0 and sgn[k + 1] != 0 and sgn[k] != sgn[k + 1]:
            got = _refine_fold(corr, path, k)
            if got is None:  # fall back on the best path point
                j = k if abs(taus[k, n + 1]) < abs(taus[k + 1, n + 1]) else k + 1
                got = (Y[j], taus[j], monos[j])
            cuts.append((k, got[0], got[2]))
    # pieces of the path between folds, each fold orbit appended to both sides
    pieces: list[tuple[list[np.ndarray], list[np.ndarray]]] = []
    start = 0
    prev_fold = None
    for k, yf, mf in cuts:
        ys = ([prev_fold[0]] if prev_fold is not None else []) + list(Y[start:k + 1]) + [yf]
        ms = ([prev_fold[1]] if prev_fold is not None else []) + monos[start:k + 1] + [mf]
        pieces.append((ys, ms))
        start, prev_fold = k + 1, (yf, mf)
    ys = ([prev_fold[0]] if prev_fold is not None else []) + list(Y[start:])
    ms = ([prev_fold[1]] if prev_fold is not None else []) + monos[start:]
    pieces.append((ys, ms))

    obs = list(system.observed_index)
    all_y = np.array([y for ys, _ in pieces for y in ys])
    orbits_all = sample_batch(system, all_y[:, :n], all_y[:, n], all_y[:, n + 1], n_points,
                              rtol=rtol, atol=atol)
    branches = []
    folds = []
    i0 = 0
    for ys, ms in pieces:
        m = len(ys)
        Yp = np.array(ys)
        orbits = orbits_all[i0:i0 + m]
        i0 += m
        fl = np.array([_sorted_multipliers(M) for M in ms])
        st = np.array([floquet_stable(f) for f in fl])
        ptp = np.array([refined_ptp(o[:, obs]) for o in orbits])
        mean = orbits[:, :, obs].mean(axis=1)
        inner = st[1:-1] if m > 2 else st
        kind = "stable" if inner.mean() > 0.5 else "unstable"
        branches.append(Branch(
            kind=kind, mu=Yp[:, n + 1].copy(), period=Yp[:, n].copy(),
            amplitude=MappingProxyType({c: ptp[:, j] for j, c in enumerate(system.observed)}),
            mean=MappingProxyType({c: mean[:, j] for j, c in enumerate(system.observed)}),
            stable=st, floquet=fl, x0=Yp[:, :n].copy(), orbits=orbits, system=system,
        ))
    for (_, yf, _), b in zip(cuts, branches, strict=False):
        folds.append(Fold(mu=float(yf[n + 1]), period=float(yf[n]), x0=yf[:n].copy(),
                          amplitude=MappingProxyType({c: float(v[-1]) for c, v in
                                                      b.amplitude.items()})))
    crit = "subcritical" if branches[0].kind == "unstable" else "supercritical"
    return BifurcationDiagram(system=system, hopf=hopf, folds=tuple(folds),
                              branches=tuple(branches), criticality=crit,
                              runtime_s=time.perf_counter() - runtime_start, n_steps=steps)


def continue_from_hopf(system: System, *, hopf: HopfPoint | None = None,
                       mu_range: tuple[float, float] | None = None, ds: float = 0.02,
                       ds_max: float = 0.15, ds_min: float = 1e-7, max_steps: int = 1000,
                       n_points: int = N_POINTS, start_amplitude: float = 1e-3,
                       tol: float = 1e-11, rtol: float = RTOL, atol: float = ATOL
                       ) -> BifurcationDiagram:
    r"""Continue the periodic orbits born at a Hopf point over ``mu_range``.

    **Main arguments**

    Args:
        system: The system.
        hopf: The Hopf point (default :func:`find_hopf` over ``mu_range``).
        mu_range: Stop once μ leaves this interval (default ``system.mu_range``).

    **Other arguments**

    Args:
        ds: First arclength step (in the Euclidean norm of :math:`(x_0, T, \mu)`).
        ds_max: Largest step.
        ds_min: Smallest step before giving up.
        max_steps: Largest number of continuation steps.
        n_points: Samples per orbit in the returned branches.
        start_amplitude: :math:`\varepsilon`, size of the first orbit (norm of
            :math:`x_0 - x^*`).
        tol: Newton tolerance (relative to the size of :math:`y`).
        rtol: Relative tolerance of the ODE solver.
        atol: Absolute tolerance of the ODE solver.

    Returns:
        The :class:`BifurcationDiagram`: Hopf point, folds and branches.

    Raises:
        SimulationError: If no Hopf point is found or the continuation stalls.
    """
    ensure_x64()
    t0 = time.perf_counter()
    mu_range = system.mu_range if mu_range is None else (float(mu_range[0]), float(mu_range[1]))
    hopf = find_hopf(system, mu_range) if hopf is None else hopf
    corr = _Corrector(system, rtol, atol, tol, max_iter=12)
    path, steps = _continue(system, hopf, corr, mu_range=mu_range, ds=ds, ds_min=ds_min,
                            ds_max=ds_max, max_steps=max_steps, eps=start_amplitude)
    return _assemble(system, path, hopf, corr, n_points, rtol, atol, t0, steps)


def _orbit_on(branch: Branch, mu: float, n_points: int | None) -> PeriodicOrbit:
    """The orbit at ``mu``: the branch's own where it has one (``solved``), else Newton's."""
    system = branch.system
    mu = float(mu)
    x0, T, guess = branch.guess(mu)       # raises outside the branch's span
    n_points = branch.orbits.shape[1] if n_points is None else n_points
    solved = branch.solved.get((mu, int(n_points)))
    if solved is not None:
        return solved
    orbit = periodic_orbit(system, mu, x0, T, n_points=n_points)
    # the corrected orbit must be the one interpolated, not one of another branch
    got = orbit.amplitude[system.observed[0]]
    if abs(got - guess) > 0.05 * abs(guess) + 1e-9:
        raise SimulationError(
            f"{branch.kind} branch of {system.name}: the orbit at {system.parameter} = {mu:g} "
            f"converged away from the branch (amplitude {got:.4g}, expected about {guess:.4g}); "
            "too close to a fold?"
        )
    return orbit


def orbit_at(diagram: BifurcationDiagram | Branch, mu: float, branch: str = "stable", *,
             n_points: int | None = None) -> PeriodicOrbit:
    """The periodic orbit at ``mu`` on a branch: interpolated, then corrected by Newton.

    The continuation points that bracket ``mu`` are interpolated linearly in
    :math:`(x_0, T)` and Newton's method corrects the guess at fixed μ
    (:func:`~bayeshopf.simulators.periodic.periodic_orbit`).

    Args:
        diagram: A :class:`BifurcationDiagram` (then ``branch`` picks the branch)
            or a :class:`Branch`.
        mu: The bifurcation parameter.
        branch: ``"stable"`` or ``"unstable"``.
        n_points: Samples of the returned orbit (default as in the branch).

    Raises:
        SimulationError: If the branch has no orbit at ``mu``, or Newton's method
            does not converge to it.
    """
    ensure_x64()
    b = diagram if isinstance(diagram, Branch) else diagram.branch(branch)
    return _orbit_on(b, mu, n_points)
