r"""The library of candidate missing-physics terms.

Every term is an additive generalised force on one mechanical coordinate
:math:`q` of a :class:`~bayeshopf.simulators.System` with one unknown
coefficient :math:`c`; the system integrates
:math:`M\ddot q + D\dot q + Kq + N(q) = F_{\text{extra}}`
(:meth:`~bayeshopf.simulators.System.with_extra_force`). **Sign convention:**
the terms model restoring and dissipative forces that the simulator lacks, so
a positive coefficient *adds* to the restoring or damping force. The
dissipative terms (Coulomb friction, quadratic and cubic damping) model
damping the simulator lacks, and their coefficient is restricted to
:math:`c \ge 0` (:attr:`Term.positive`, :data:`DISSIPATIVE`): a negative one
would feed energy into the motion, which is not a missing friction or damper
but an unmodelled source (an aerodynamic effect), and naming it "damping" would
mislead. A stiffness coefficient may have either sign (hardening or softening).

=====================  ==========================================  =================
kind                   :math:`F_{\text{extra}}`                    coefficient unit
=====================  ==========================================  =================
quadratic_stiffness    :math:`-c\,q^2`                             F / [q]²
cubic_stiffness        :math:`-c\,q^3`                             F / [q]³
quintic_stiffness      :math:`-c\,q^5`                             F / [q]⁵
freeplay               :math:`+k_q\,\mathrm{sat}_\varepsilon(q, \delta)`   [q] (the gap δ)
coulomb_friction       :math:`-c\,\tanh(\dot q/\varepsilon_v)`     F
quadratic_damping      :math:`-c\,\dot q\,|\dot q|_\varepsilon`    F / [q̇]²
cubic_damping          :math:`-c\,\dot q^3`                        F / [q̇]³
=====================  ==========================================  =================

F is N for a translation (m) and N m for a rotation (rad). **Freeplay** is a
dead band of half-width δ in the structural spring :math:`k_q`: the restoring
force becomes :math:`k_q\,\mathrm{dz}(q, \delta)` (zero for :math:`|q|<\delta`,
:math:`k_q(q \mp \delta)` outside), i.e.
:math:`F_{\text{extra}} = k_q\,\mathrm{clip}(q, -\delta, \delta)`, smoothed as
:math:`\mathrm{sat}_\varepsilon(q,\delta) =
\tfrac12\big(\sqrt{(q+\delta)^2+\varepsilon^2} - \sqrt{(q-\delta)^2+\varepsilon^2}\big)`,
which is exactly 0 at δ = 0 and differentiable in δ. Its unknown coefficient is
the gap δ (≥ 0), and it needs
the linear structural stiffness :math:`k_q` of the coordinate: a parameter
named ``k_<coordinate>`` of the system (``k_h``, ``k_alpha`` for the
aerofoil); a system without one gets no freeplay term (:func:`library` says
so in :attr:`Library.skipped`). The smoothing widths are
:math:`\varepsilon = 10^{-2}A_q` and :math:`\varepsilon_v = 10^{-2}V_q` with the
typical displacement and velocity amplitudes :math:`A_q`, :math:`V_q = \omega A_q`.

A wrong value of a term the simulator already has is that term: the aerofoil's
:math:`k_{\alpha3}\alpha^3` and the added :math:`c\,\alpha^3` sum, so an error
:math:`\Delta k_{\alpha3}` is ``alpha_cubic_stiffness`` with :math:`c = \Delta k_{\alpha3}`.

**Terms that are parameters.** When such a parameter is among those
calibrated (``parameters`` of :func:`library`), the term would only be a
wider prior on it filed under "term missing", so it is left out of the
candidates and recorded in :attr:`Library.skipped` ("the same force as
parameter k_alpha3"). The test is numerical, not by name
(:func:`same_force_as`): on :data:`N_STATES` random states and values of μ, the
term's contribution to the state derivative, :math:`B(x)\,e_q\,
\partial F/\partial c|_{c=0}`, is compared with :math:`\partial\dot x/\partial\theta`
for each calibrated :math:`\theta`; the term is that parameter when a least-squares
multiple of one fits the other to a relative residual below :data:`SAME_FORCE_TOL`.

**Prior scale.** Each coefficient gets a zero-mean normal prior (half-normal,
:math:`p(c) = 2\,\mathcal N(c; 0, s^2)` on :math:`c \ge 0`, for the gap and the
dissipative terms: :meth:`Term.log_prior`) whose scale :math:`s` makes the
term's force at the typical amplitude 20% of the linear restoring force there,
:math:`k_q A_q`: :math:`|F(s; A_q, V_q)| = 0.2\,k_q A_q`, e.g. :math:`s = 0.2\,k_q/A_q^2` for
cubic stiffness, :math:`s = 0.2\,k_q A_q/V_q^3` for cubic damping,
:math:`s = 0.2\,A_q` for the freeplay gap. A missing term larger than that
would be a gross modelling error, not a hidden one; a much wider prior would
only add an Occam penalty of :math:`\log` (width ratio) to every term alike.
Coordinates are the system's ``coordinates`` that are observed states (the
aerofoil's h and α; its aerodynamic lag state w is not a mechanical
coordinate one could add a spring to).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from bayeshopf._x64 import ensure_x64
from bayeshopf.errors import BayesHopfError
from bayeshopf.simulators import compiled as programs
from bayeshopf.simulators.base import System

__all__ = ["DISSIPATIVE", "KINDS", "Library", "Term", "library", "library_system", "plain_name",
           "same_force_as", "term_force"]

#: The kinds of term, in the order they are listed.
KINDS: tuple[str, ...] = (
    "quadratic_stiffness", "cubic_stiffness", "quintic_stiffness", "freeplay",
    "coulomb_friction", "quadratic_damping", "cubic_damping",
)
#: The kinds whose coefficient is restricted to c ≥ 0 (half-normal prior): the freeplay
#: gap and the dissipative terms.
DISSIPATIVE: tuple[str, ...] = ("coulomb_friction", "quadratic_damping", "cubic_damping")
#: Fraction of the linear restoring force that a term of one prior scale gives.
PRIOR_FRACTION = 0.2
#: Smoothing widths relative to the typical amplitudes.
SMOOTHING = 1e-2
#: Random states on which a term's force is compared with a parameter's (:func:`same_force_as`).
N_STATES = 8
#: Relative least-squares residual below which a term's force is a parameter's.
SAME_FORCE_TOL = 1e-8

_PLAIN = {"quadratic_stiffness": "quadratic stiffness", "cubic_stiffness": "cubic stiffness",
          "quintic_stiffness": "quintic stiffness", "freeplay": "freeplay",
          "coulomb_friction": "Coulomb friction", "quadratic_damping": "quadratic damping",
          "cubic_damping": "cubic damping"}
_COORD_WORDS = {"h": "heave", "alpha": "pitch"}


def plain_name(name: str) -> str:
    """A term's name in plain words (``"alpha_cubic_stiffness"`` → ``"cubic stiffness in pitch"``).

    A name that is not ``<coordinate>_<kind>`` of :data:`KINDS` is returned as it is.
    """
    kind = next((k for k in KINDS if name.endswith("_" + k)), None)
    if kind is None:
        return name
    coordinate = name[: -len(kind) - 1]
    return f"{_PLAIN[kind]} in {_COORD_WORDS.get(coordinate, coordinate)}"


class TermError(BayesHopfError, ValueError):
    """A term name or a system is not what the library accepts."""


@dataclass(frozen=True)
class Term:
    r"""One candidate term: an extra force on one coordinate with one coefficient.

    Attributes:
        name: ``<coordinate>_<kind>`` (``"alpha_cubic_stiffness"``).
        coordinate: The mechanical coordinate q it acts on.
        kind: One of :data:`KINDS`.
        units: Unit of the coefficient (``"N m/rad^3"``; the gap's unit for freeplay).
        scale: Prior scale of the coefficient (module docstring).
        stiffness: :math:`k_q` for freeplay, else 0.
        eps: Smoothing width (displacement for freeplay, velocity for friction
            and quadratic damping).
        index: Position of q in ``system.coordinates``.
    """

    name: str
    coordinate: str
    kind: str
    units: str
    scale: float
    stiffness: float = 0.0
    eps: float = 0.0
    index: int = 0

    @property
    def param(self) -> str:
        """Name of the coefficient's parameter in :func:`library_system`."""
        return f"dc_{self.name}"

    @property
    def positive(self) -> bool:
        """Whether the coefficient is constrained to be ≥ 0 (the gap; dissipative terms)."""
        return self.kind == "freeplay" or self.kind in DISSIPATIVE

    def log_prior(self, c):
        r"""Log prior density of the coefficient ``c`` (in the term's unit).

        :math:`\log\mathcal N(c; 0, s^2)`; when :attr:`positive`, the half-normal
        :math:`\log 2 + \log\mathcal N(c; 0, s^2)` on :math:`c \ge 0` and
        :math:`-\infty` below.
        """
        c = np.asarray(c, float)
        lp = -0.5 * (c / self.scale) ** 2 - 0.5 * np.log(2 * np.pi * self.scale**2)
        if self.positive:
            lp = np.where(c >= 0, lp + np.log(2.0), -np.inf)
        return lp

    @property
    def plain(self) -> str:
        """Plain words: ``"cubic stiffness in pitch"``."""
        return plain_name(self.name)

    def force(self, q, qd, c):
        r"""The generalised force :math:`F_{\text{extra}}(q, \dot q; c)` (module docstring)."""
        return term_force(self.kind, q, qd, c, self.stiffness, self.eps)


def term_force(kind: str, q, qd, c, stiffness: float = 0.0, eps: float = 1e-6):
    r"""``F_extra`` of one kind of term at displacement ``q`` and velocity ``qd``.

    Args:
        kind: One of :data:`KINDS`.
        q: Displacement of the coordinate.
        qd: Its velocity.
        c: The coefficient (the gap δ for freeplay).
        stiffness: :math:`k_q` (freeplay only).
        eps: Smoothing width (freeplay: of q; friction, quadratic damping: of q̇).
    """
    if kind == "quadratic_stiffness":
        return -c * q**2
    if kind == "cubic_stiffness":
        return -c * q**3
    if kind == "quintic_stiffness":
        return -c * q**5
    if kind == "freeplay":
        sat = 0.5 * (jnp.sqrt((q + c) ** 2 + eps**2) - jnp.sqrt((q - c) ** 2 + eps**2))
        return stiffness * sat
    if kind == "coulomb_friction":
        return -c * jnp.tanh(qd / eps)
    if kind == "quadratic_damping":
        return -c * qd * jnp.sqrt(qd**2 + eps**2)
    if kind == "cubic_damping":
        return -c * qd**3
    raise TermError(f"term kind expected among {', '.join(KINDS)}; got {kind!r}")


def _scale(kind: str, k: float, A: float, V: float) -> float:
    """Prior scale: force at amplitude ``A``/``V`` equal to ``PRIOR_FRACTION·k·A``."""
    f = PRIOR_FRACTION * k * A
    return {"quadratic_stiffness": f / A**2, "cubic_stiffness": f / A**3,
            "quintic_stiffness": f / A**5, "freeplay": PRIOR_FRACTION * A,
            "coulomb_friction": f, "quadratic_damping": f / V**2,
            "cubic_damping": f / V**3}[kind]


def _units(kind: str, qu: str, fu: str) -> str:
    vu = f"{qu}/s" if qu else "1/s"
    pw = {"quadratic_stiffness": (qu, 2), "cubic_stiffness": (qu, 3),
          "quintic_stiffness": (qu, 5), "quadratic_damping": (f"({vu})", 2),
          "cubic_damping": (f"({vu})", 3)}
    if kind == "freeplay":
        return qu
    if kind == "coulomb_friction":
        return fu
    u, n = pw[kind]
    return f"{fu}/{u}^{n}" if u else fu


@dataclass(frozen=True)
class Library:
    """The candidate terms of one system.

    Attributes:
        terms: The terms, by coordinate then kind.
        skipped: ``name -> reason`` for terms left out (freeplay without a
            known linear stiffness; a term whose force is that of a calibrated
            parameter).
        amplitude: Typical displacement amplitude :math:`A_q` per coordinate.
        velocity: Typical velocity amplitude :math:`V_q` per coordinate.
        duplicates: ``(term, parameter)`` for each term left out because its
            force is that of a calibrated parameter (:func:`same_force_as`).
    """

    terms: tuple[Term, ...]
    skipped: Mapping[str, str] = field(default_factory=dict)
    amplitude: Mapping[str, float] = field(default_factory=dict)
    velocity: Mapping[str, float] = field(default_factory=dict)
    duplicates: tuple[tuple[Term, str], ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the terms."""
        return tuple(t.name for t in self.terms)

    def __getitem__(self, name: str) -> Term:
        for t in self.terms:
            if t.name == name:
                return t
        raise TermError(f"term expected among {', '.join(self.names)}; got {name!r}")


def _force_unit(qu: str) -> str:
    return "N m" if qu == "rad" else ("N" if qu == "m" else "force")


def _linear_stiffness(system: System, coord: str) -> float:
    r"""Linear restoring stiffness of ``coord`` in force units, from the Jacobian at ``x = 0``.

    :math:`k = -J_{vq} / B_{vq}`: the acceleration per unit displacement over the
    acceleration per unit force, at the middle of ``system.mu_range``. Used for
    the prior scales when the system has no ``k_<coordinate>`` parameter.
    """
    pos = system.state_names.index(coord)
    vel = (system.state_names.index(f"{coord}_dot") if f"{coord}_dot" in system.state_names
           else pos + 1)
    mu = 0.5 * sum(system.mu_range)
    x = jnp.zeros(system.n_states)
    p = system.param_tree()
    J = np.asarray(jax.jacfwd(system.rhs)(x, jnp.asarray(mu), p))
    B = np.asarray(system.force_input(x, jnp.asarray(mu), p))
    b = B[vel, system.coordinates.index(coord)]
    return float(-J[vel, pos] / b) if b != 0 else float("nan")


def _unit_force(t: Term, q, qd, c):
    return term_force(t.kind, q, qd, c, t.stiffness, t.eps)


def same_force_as(system: System, terms: Sequence[Term], parameters: Sequence[str],
                  amplitude: Mapping[str, float], velocity: Mapping[str, float], *,
                  seed: int = 0) -> dict[str, str]:
    r"""The terms whose force is a multiple of a parameter's: ``term name -> parameter``.

    On :data:`N_STATES` states drawn at random (displacement and velocity of
    each coordinate normal with standard deviations :math:`A_q`, :math:`V_q`;
    every other state with 0.1) and values of μ uniform on ``system.mu_range``,
    the stacked vectors :math:`a_\theta = \partial\dot x/\partial\theta` and
    :math:`b = B(x)\,e_q\,\partial F/\partial c|_{c=0}` are compared: the term is
    parameter :math:`\theta` when
    :math:`\min_\lambda\lVert a_\theta - \lambda b\rVert <` :data:`SAME_FORCE_TOL`
    :math:`\cdot\lVert a_\theta\rVert`.

    Args:
        system: The simulator (with ``force_input``).
        terms: The candidate terms.
        parameters: Names of the parameters to compare with (the calibrated ones).
        amplitude: :math:`A_q` per coordinate.
        velocity: :math:`V_q` per coordinate.
        seed: Seed of the random states.
    """
    names = [n for n in parameters if n in system.params]
    if not names or not terms:
        return {}
    rng = np.random.default_rng(seed)
    sd = np.full(system.n_states, 0.1)
    for c, A in amplitude.items():
        pos = system.state_names.index(c)
        vel = (system.state_names.index(f"{c}_dot") if f"{c}_dot" in system.state_names
               else pos + 1)
        sd[pos], sd[vel] = A, velocity[c]
    xs = jnp.asarray(rng.normal(size=(N_STATES, system.n_states)) * sd)
    mus = jnp.asarray(rng.uniform(*system.mu_range, size=N_STATES))
    p0 = system.param_tree()
    theta0 = jnp.stack([p0[n] for n in names])

    def rhs_theta(theta, x, mu):
        return system.rhs(x, mu, {**p0, **dict(zip(names, theta, strict=True))})

    # ∂ẋ/∂θ at every state: (N_STATES, n_states, n_parameters); compiled, as run
    # op by op a simulator's right-hand side takes seconds
    A = np.asarray(jax.jit(jax.vmap(jax.jacfwd(rhs_theta), in_axes=(None, 0, 0)))(
        theta0, xs, mus))
    B = np.asarray(jax.jit(jax.vmap(system.force_input, in_axes=(0, 0, None)))(xs, mus, p0))
    out = {}
    for t in terms:
        pos = system.state_names.index(t.coordinate)
        vel = (system.state_names.index(f"{t.coordinate}_dot")
               if f"{t.coordinate}_dot" in system.state_names else pos + 1)
        dF = np.asarray(jax.jacfwd(functools.partial(_unit_force, t, xs[:, pos], xs[:, vel]))(
            jnp.asarray(0.0)))
        b = (B[:, :, t.index] * dF[:, None]).ravel()
        if not np.any(b):
            continue
        for j, n in enumerate(names):
            a = A[:, :, j].ravel()
            na = float(np.linalg.norm(a))
            if na == 0.0:
                continue
            lam = float(a @ b) / float(b @ b)
            if np.linalg.norm(a - lam * b) < SAME_FORCE_TOL * na:
                out[t.name] = n
                break
    return out


def library(system: System, amplitude: Mapping[str, float], frequency_hz: float, *,
            kinds: tuple[str, ...] = KINDS, parameters: Sequence[str] = ()) -> Library:
    r"""The candidate terms for ``system``'s observed mechanical coordinates.

    Args:
        system: A system with ``coordinates`` and ``force_input``.
        amplitude: Typical displacement amplitude (half peak-to-peak) per
            coordinate, :math:`A_q`.
        frequency_hz: Typical oscillation frequency; :math:`V_q = 2\pi f A_q`.
        kinds: The kinds to include.
        parameters: The parameters that are calibrated: a term whose force is
            one of theirs (:func:`same_force_as`) is left out and recorded in
            :attr:`Library.skipped` (module docstring, "Terms that are parameters").

    Raises:
        TermError: If the system declares no extra-force input or no observed
            coordinate.
    """
    ensure_x64()
    if system.force_input is None or not system.coordinates:
        raise TermError(f"{system.name}: a system with coordinates and force_input expected; "
                        "found none (terms cannot be added to it)")
    coords = [c for c in system.coordinates if c in system.observed]
    if not coords:
        raise TermError(f"{system.name}: an observed mechanical coordinate expected; "
                        f"found coordinates {system.coordinates} and observed {system.observed}")
    terms, skipped = [], {}
    A_out, V_out = {}, {}
    for c in coords:
        qu = system.state_units[system.state_names.index(c)]
        fu = _force_unit(qu)
        A = float(amplitude[c])
        V = 2 * np.pi * float(frequency_hz) * A
        A_out[c], V_out[c] = A, V
        k = system.params.get(f"k_{c}")
        k_eff = float(k) if k is not None else _linear_stiffness(system, c)
        for kind in kinds:
            name = f"{c}_{kind}"
            if kind == "freeplay" and k is None:
                skipped[name] = (f"no linear structural stiffness parameter k_{c} in "
                                 f"{system.name} (the spring a dead band would act on)")
                continue
            kk = float(k) if kind == "freeplay" else k_eff
            if not (np.isfinite(kk) and kk > 0):
                skipped[name] = f"no positive linear stiffness of {c} for the prior scale"
                continue
            eps = SMOOTHING * (A if kind == "freeplay" else V)
            terms.append(Term(name=name, coordinate=c, kind=kind, units=_units(kind, qu, fu),
                              scale=_scale(kind, kk, A, V),
                              stiffness=kk if kind == "freeplay" else 0.0, eps=eps,
                              index=system.coordinates.index(c)))
    same = same_force_as(system, terms, parameters, A_out, V_out)
    for name, par in same.items():
        skipped[name] = (f"the same force as parameter {par}, which is calibrated (an error "
                         f"in it is named as {par} off)")
    duplicates = tuple((t, same[t.name]) for t in terms if t.name in same)
    terms = [t for t in terms if t.name not in skipped]
    if not terms:
        raise TermError(f"{system.name}: candidate terms expected; found none ("
                        + "; ".join(sorted(set(skipped.values()))) + ")")
    return Library(tuple(terms), skipped, A_out, V_out, duplicates)


def library_params(lib: Library) -> dict[str, float]:
    """The values of the smoothing widths and stiffnesses of ``lib`` as system parameters."""
    out = {}
    for t in lib.terms:
        out[f"eps_{t.name}"] = t.eps
        out[f"k_{t.name}"] = t.stiffness
    return out


def library_system(system: System, lib: Library) -> System:
    r"""``system`` with every term of ``lib`` added, each with coefficient parameter ``dc_<name>``.

    All coefficients default to 0, so the system equals ``system``; setting one
    parameter switches one term on. One compiled solver then serves every term
    and every coefficient value: coefficients, smoothing widths (``eps_<name>``)
    and freeplay stiffnesses (``k_<name>``) are parameters, arguments of the
    compiled functions, and the system is cached per base system and term names,
    so a second analysis with other amplitudes compiles nothing.
    """
    ensure_x64()
    base = _library_system(system, tuple((t.name, t.kind, t.coordinate, t.index)
                                         for t in lib.terms))
    return base


@functools.lru_cache(maxsize=8)
def _library_system(system: System, spec: tuple) -> System:
    terms = [Term(name=n, coordinate=c, kind=k, units="", scale=1.0, index=i)
             for n, k, c, i in spec]
    n = len(system.coordinates)
    pos = {c: system.state_names.index(c) for c in system.coordinates}
    vel = {}
    for c in system.coordinates:  # velocity state: "<c>_dot" by convention, else the next state
        vel[c] = (system.state_names.index(f"{c}_dot") if f"{c}_dot" in system.state_names
                  else pos[c] + 1)

    def force(x, mu, p):
        F = [0.0 * x[0] for _ in range(n)]
        for t in terms:
            q, qd = x[pos[t.coordinate]], x[vel[t.coordinate]]
            F[t.index] = F[t.index] + term_force(t.kind, q, qd, p[t.param], p[f"k_{t.name}"],
                                                 p[f"eps_{t.name}"])
        return jnp.stack(F)

    params = {t.param: 0.0 for t in terms}
    params.update({f"eps_{t.name}": 1e-6 for t in terms})
    params.update({f"k_{t.name}": 0.0 for t in terms})
    out = system.with_extra_force(force, name=f"{system.name}+library", params=params)
    base, force_input = programs.key_of(system.rhs), programs.key_of(system.force_input)
    if base is not None and force_input is not None:  # the closure is pinned down by these
        programs.register(out.rhs, ("library", *base, *force_input, spec, system.state_names,
                                    system.coordinates))
    return out
