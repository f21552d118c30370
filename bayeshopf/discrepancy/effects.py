r"""Hidden effects planted in a simulated truth (for blind tests of the analysis).

:func:`with_effect` returns the system with one effect added:

* any library term ``<coordinate>_<kind>`` (:mod:`bayeshopf.discrepancy.terms`)
  with coefficient ``value`` in the term's unit, through
  :meth:`~bayeshopf.simulators.System.with_extra_force`; the smoothing widths
  are set from the base system's orbits over its default plan;
* ``delayed_aero``, outside the library: a pitch moment proportional to the
  pitch angle seen through a first-order lag of time constant
  :math:`\tau` = ``DELAY_TAU``,

  .. math::  F_\alpha = \kappa\,m, \qquad \dot m = (\alpha - m)/\tau,

  with :math:`\kappa` = ``value`` (N m/rad). It needs an extra state
  :math:`m` (``"m_lag"``, not observed), so it is a new system rather than an
  extra force. For slow motion :math:`m \approx \alpha - \tau\dot\alpha`: a
  linear change of both pitch stiffness and damping, which moves the Hopf
  point itself — something no nonlinear library term does.
"""

from __future__ import annotations

import dataclasses
import functools
from types import SimpleNamespace

import jax.numpy as jnp
import numpy as np

from bayeshopf._x64 import ensure_x64
from bayeshopf.data.recording import RecordingSet
from bayeshopf.discrepancy.orbits import solve_orbits, track
from bayeshopf.discrepancy.terms import KINDS, TermError, library
from bayeshopf.errors import BayesHopfError
from bayeshopf.simulators.base import System
from bayeshopf.simulators.continuation import bifurcation_diagram, continue_from_hopf
from bayeshopf.simulators.periodic import periodic_orbit
from bayeshopf.simulators.recordings import _plan, simulate_recordings

__all__ = ["DELAY_TAU", "EFFECTS_OUTSIDE", "effect_names", "effect_units", "with_effect"]

#: Time constant of the ``delayed_aero`` lag (s).
DELAY_TAU = 0.05
#: Effects that are outside the candidate library.
EFFECTS_OUTSIDE = ("delayed_aero",)


@functools.lru_cache(maxsize=8)
def _typical(system: System) -> tuple[dict[str, float], float]:
    """Half peak-to-peak per coordinate and frequency over the system's default plan."""
    diagram = bifurcation_diagram(system)
    plan = system.default_plan or ((0.5 * sum(diagram.branch("stable").mu_span), "stable"),)
    amps: dict[str, list[float]] = {c: [] for c in system.observed}
    freqs = []
    for mu, b in plan:
        o = diagram.orbit_at(mu, b)
        for c in system.observed:
            amps[c].append(0.5 * o.amplitude[c])
        freqs.append(o.frequency_hz)
    return {c: float(np.median(v)) for c, v in amps.items()}, float(np.median(freqs))


def effect_names(system: System) -> tuple[str, ...]:
    """The effects that can be planted in ``system``."""
    if system.force_input is None or not system.coordinates:
        return ()
    coords = [c for c in system.coordinates if c in system.observed]
    names = tuple(f"{c}_{k}" for c in coords for k in KINDS)
    if "alpha" in system.coordinates:
        names += EFFECTS_OUTSIDE
    return names


def effect_units(system: System, name: str) -> str:
    """Unit of the effect's value."""
    if name == "delayed_aero":
        return "N m/rad"
    amp, f = _typical(system)
    return library(system, amp, f)[name].units


def _delayed_aero(system: System, value: float) -> System:
    n = system.n_states
    base, B = system.rhs, system.force_input
    ia = system.coordinates.index("alpha")
    ka = system.state_names.index("alpha")
    nc = len(system.coordinates)

    def rhs(x, mu, p):
        xs, m = x[:n], x[n]
        F = jnp.zeros(nc, dtype=x.dtype).at[ia].set(p["delay_gain"] * m)
        dx = base(xs, mu, p) + B(xs, mu, p) @ F
        return jnp.concatenate([dx, ((xs[ka] - m) / p["delay_tau"])[None]])

    def force_input(x, mu, p):
        return jnp.concatenate([B(x[:n], mu, p), jnp.zeros((1, nc), dtype=x.dtype)], axis=0)

    return system.replace(
        name=f"{system.name}+delayed_aero", rhs=rhs, force_input=force_input,
        state_names=system.state_names + ("m_lag",), state_units=system.state_units + ("rad",),
        params={**system.params, "delay_gain": float(value), "delay_tau": DELAY_TAU},
        param_units={**system.param_units, "delay_gain": "N m/rad", "delay_tau": "s"})


@functools.lru_cache(maxsize=16)
def with_effect(system: System, name: str, value: float) -> System:
    """``system`` with the hidden effect ``name`` of size ``value`` (module docstring).

    The same arguments give the same system (cached), so its compiled solvers
    (:func:`~bayeshopf.simulators.periodic.kernels`, per right-hand side) are
    traced once: simulating the recordings and finding their truth's Hopf
    point and fold ask for it twice.

    Raises:
        TermError: If ``name`` is not an effect of this system, or ``value`` is
            not finite (or negative for a freeplay gap).
    """
    ensure_x64()
    names = effect_names(system)
    if name not in names:
        raise TermError(f"effect name: expected one of {', '.join(names) or '(none)'} for "
                        f"{system.name}; got {name!r}")
    value = float(value)
    if not np.isfinite(value):
        raise TermError(f"effect value: a finite number expected; got {value!r}")
    if name == "delayed_aero":
        return _delayed_aero(system, value)
    amp, f = _typical(system)
    term = library(system, amp, f)[name]
    if term.kind == "freeplay" and value < 0:
        raise TermError(f"effect value: a freeplay gap >= 0 expected; got {value!r}")
    pos = system.state_names.index(term.coordinate)
    vname = f"{term.coordinate}_dot"
    vel = system.state_names.index(vname) if vname in system.state_names else pos + 1
    nc = len(system.coordinates)

    def force(x, mu, p):
        F = jnp.zeros(nc, dtype=x.dtype)
        return F.at[term.index].set(term.force(x[pos], x[vel], p["effect_value"]))

    return system.with_extra_force(force, name=f"{system.name}+{name}",
                                   params={"effect_value": value},
                                   param_units={"effect_value": term.units})


class _TrackedBranch:
    def __init__(self, kind: str):
        self.kind = kind
        self.mu_span = (-np.inf, np.inf)

    def exists(self, mu: float) -> bool:
        return True


class _TrackedDiagram:
    """The few members of a BifurcationDiagram that ``simulate_recordings`` reads."""

    def __init__(self, system: System, orbits: dict):
        self.system = system
        self._orbits = orbits
        self.hopf = SimpleNamespace(mu=float("nan"))
        self.folds = ()

    def branch(self, kind: str) -> _TrackedBranch:
        return _TrackedBranch(kind)

    def orbit_at(self, mu: float, branch: str = "stable", *, n_points: int | None = None):
        x0, T = self._orbits[(float(mu), branch)]
        return periodic_orbit(self.system, mu, x0, T, n_points=n_points or 256)


def effect_orbits(system: System, name: str, value: float, plan) -> tuple[System, dict]:
    """The effect system and its orbits ``(mu, branch) -> (x0, T)`` at the plan's points.

    Library effects are reached by homotopy in the effect's value from the
    base system's orbits (:func:`bayeshopf.discrepancy.orbits.track`): this also
    works when the effect removes the Hopf point (Coulomb friction stops
    small oscillations, so the branches cannot be continued from one).
    ``delayed_aero`` changes the state space and is continued from its Hopf point.

    Raises:
        TermError: If the branch has no LCO at a requested point with the effect.
    """
    ensure_x64()
    eff = with_effect(system, name, value)
    if name == "delayed_aero":
        d = continue_from_hopf(eff)
        out = {}
        for mu, b in plan:
            o = d.orbit_at(mu, b)
            out[(float(mu), b)] = (o.x0, o.period)
        return eff, out
    d = bifurcation_diagram(system)
    orbs = [d.orbit_at(mu, b) for mu, b in plan]
    stable = np.array([b == "stable" for _, b in plan])
    p0 = {**eff.params, "effect_value": 0.0}
    start = solve_orbits(eff, p0, np.stack([o.x0 for o in orbs]),
                         np.array([o.period for o in orbs]), np.array([m for m, _ in plan]),
                         stable)
    res = track(eff, p0, dict(eff.params), start, stable)
    lost = [f"{b} {system.parameter} = {m:g}" for (m, b), ok in zip(plan, res.ok, strict=True)
            if not ok]
    if lost:
        raise TermError(f"{name} = {value:g}: an LCO at every requested point expected; the "
                        f"system with the effect has none at {', '.join(lost)}")
    return eff, {(float(m), b): (res.x0[i], float(res.period[i]))
                 for i, (m, b) in enumerate(plan)}


def simulate_with_effect(system: System, name: str, value: float, mu=None, branch=None,
                         **kwargs):
    """Recordings of ``system`` with a hidden effect, and the truth (kept apart).

    The recordings carry no trace of the effect: their source and set metadata
    name the base system only. Keyword arguments go to
    :func:`~bayeshopf.simulators.simulate_recordings`.

    Returns:
        ``(recordings, truth)`` with ``truth`` a JSON-serialisable dict: effect,
        value, units and the Hopf point and fold of the system with the effect
        (``None`` where they cannot be computed).
    """
    ensure_x64()
    plan = _plan(system, mu, branch)
    eff, orbits = effect_orbits(system, name, value, plan)
    rs = simulate_recordings(eff, [m for m, _ in plan], [b for _, b in plan],
                             diagram=_TrackedDiagram(eff, orbits), **kwargs)
    seed = kwargs.get("seed", 0)
    src = f"simulated {system.name} (bayeshopf.simulators, seed={seed})"
    recs = tuple(dataclasses.replace(r, source=src) for r in rs)
    rs = RecordingSet(recs, rs.planar, mu_label=rs.mu_label, mu_units=rs.mu_units,
                      extra={"simulated": system.name, "seed": str(seed),
                             "noise": repr(kwargs.get("noise", 0.01))})
    truth = {"system": system.name, "effect": name, "value": float(value),
             "units": effect_units(system, name), "hopf": None, "fold": None}
    return rs, truth


def truth_points(system: System, name: str, value: float) -> dict:
    """Hopf point and folds (lowest μ first) of ``system`` with the effect (``None``: none)."""
    ensure_x64()
    try:
        d = continue_from_hopf(with_effect(system, name, value))
    except BayesHopfError as exc:
        return {"hopf": None, "fold": None, "note": str(exc)}
    folds = sorted(float(f.mu) for f in d.folds)
    return {"hopf": float(d.hopf.mu), "fold": folds or None}
