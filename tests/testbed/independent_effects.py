r"""Hidden effects for blind tests, written independently of the term library.

The blind tests of :mod:`bayeshopf.discrepancy` must show that it names
physics *written by someone else*, and what it says when the truth is near but
not in its library. This module builds such truths for the 3-DOF aerofoil
(``flutter3dof``, :mod:`bayeshopf.simulators.flutter`): each function returns a
new :class:`~bayeshopf.simulators.System`, a copy with a new right-hand side,
written here from the equations of motion — it imports nothing from
:mod:`bayeshopf.discrepancy` and uses none of its term formulas, smoothings,
parameterisations or smoothing widths.

The aerofoil integrates :math:`M\ddot q + D(U)\dot q + K(U)q + N(\alpha) = F` in
:math:`q = (h, \alpha, w)`; each effect is a generalised force
:math:`F(x, U; p)` added through the system's ``force_input``
(:math:`\dot x \mathrel{+}= B F`, :math:`B` puts :math:`M^{-1}F` in the
velocity rows). Its size is a parameter of the returned system (``ie_*``), so
a base-parameter perturbation (:func:`perturb_params`) composes with it.

=================================  ==========================  =====================
effect                             size (unit)                 linearisation at 0
=================================  ==========================  =====================
:func:`pitch_freeplay`             gap δ (rad)                 changed: the spring is
                                                               cut inside the gap
:func:`stribeck_friction`          Coulomb level F_c (N, N m)  changed: sticking acts
                                                               as a stiff damper
:func:`stall_saturation`           saturation angle α_s (rad)  unchanged (odd, O(α³))
:func:`pitch_cubic_stiffness`      k₃ (N m/rad³)               unchanged
=================================  ==========================  =====================

**Zero size is exactly the nominal system**: every force is written so that at
size 0 (δ = 0, F_c = 0 with no viscous part, α_s = ∞, k₃ = 0) it is the
floating-point 0 and the right-hand side is bit-identical to the base one.

**What moves the Hopf point.** Freeplay and dry friction do *not* vanish near
the equilibrium: inside the gap the pitch spring is absent (zero structural
pitch stiffness at α = 0), and a regularised friction is a large viscous
damper at zero velocity. Both change the Jacobian at the equilibrium and so
the linear Hopf point (freeplay makes it singular; friction moves it up or
removes it), however small the gap or the friction level. Stall saturation and
cubic stiffness are :math:`O(|x|^3)` at the equilibrium and leave the Hopf
point exactly where it was; they change only the amplitudes of the LCOs.

**Orbits.** Freeplay and friction can remove the Hopf point, so the LCO
branches cannot be continued from it. :func:`stable_orbit` finds a stable LCO
by integrating forward from a guess (the nominal orbit) and correcting with
Newton's method (:func:`bayeshopf.simulators.periodic_orbit`);
:class:`OrbitSet` holds such orbits in the form
:func:`bayeshopf.simulators.simulate_recordings` reads (its ``diagram``), and
:func:`blind_recordings` simulates recordings that name only the base system.

``benchmarks/bench_independent_effects.py`` measures how much each effect, at a few
sizes, changes the stable and unstable LCO amplitudes.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from types import SimpleNamespace

import jax.numpy as jnp
import numpy as np

from bayeshopf._x64 import ensure_x64
from bayeshopf.simulators import (
    PeriodicOrbit,
    SimulationError,
    System,
    periodic_orbit,
    sample_orbit,
    simulate_recordings,
)
from bayeshopf.simulators.recordings import N_ORBIT

__all__ = [
    "EFFECTS", "LIBRARY_LIKE", "POLYNOMIAL_KINDS", "OrbitSet", "blind_recordings",
    "circulatory_lift", "coloured_noise", "coulomb_friction", "dead_band", "lagged_lift",
    "lagged_pitch_moment", "perturb_params", "pitch_cubic_stiffness", "pitch_freeplay",
    "polynomial_force", "stable_orbit", "stall_saturation", "stribeck_force",
    "stribeck_friction", "tracked_orbit",
]


# --------------------------------------------------------------------------- helpers


def _index(system: System, coordinate: str) -> tuple[int, int, int]:
    """Positions of a coordinate in ``coordinates``, of its displacement and velocity states."""
    if system.force_input is None or coordinate not in system.coordinates:
        raise SimulationError(
            f"{system.name}: a mechanical coordinate among {system.coordinates or '(none)'} "
            f"with a force input expected; got {coordinate!r}")
    vel = f"{coordinate}_dot"
    if vel not in system.state_names:
        raise SimulationError(f"{system.name}: a velocity state {vel!r} expected for "
                              f"{coordinate!r}; states are {', '.join(system.state_names)}")
    return (system.coordinates.index(coordinate), system.state_names.index(coordinate),
            system.state_names.index(vel))


def _finite(name: str, value, *, lo: float = -math.inf, lo_open: bool = False,
            allow_inf: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SimulationError(f"{name}: a number expected; got {value!r}") from None
    ok = (math.isfinite(v) or (allow_inf and v == math.inf)) and (v > lo if lo_open
                                                                    else v >= lo)
    if not ok:
        bound = f"> {lo:g}" if lo_open else f">= {lo:g}"
        raise SimulationError(f"{name}: a {'' if allow_inf else 'finite '}number {bound} "
                              f"expected; got {value!r}")
    return v


def _with_force(system: System, force, tag: str, params: Mapping[str, float],
                units: Mapping[str, str]) -> System:
    """``system`` with the generalised force ``force(x, U, p)`` added (a new rhs)."""
    clash = sorted(set(params) & set(system.params))
    if clash:
        raise SimulationError(f"{system.name}: already holds {', '.join(clash)}; one "
                              "independent effect of each kind per system expected")
    return system.with_extra_force(force, name=f"{system.name}+{tag}", params=params,
                                   param_units=units)


def perturb_params(system: System, relative: Mapping[str, float]) -> System:
    r"""A copy of ``system`` with parameters changed by relative amounts.

    :math:`\theta_i = \theta_{i,0}\,(1 + r_i)` for each ``name -> r_i`` of
    ``relative`` (``{"k_alpha": 0.03, "c0": -0.05}``: pitch stiffness +3%, lift
    slope −5%); the other parameters keep their values. It composes with the
    effects (perturb the effect system, or add the effect to the perturbed one).

    Raises:
        SimulationError: If a name is not a parameter of ``system`` or an
            amount is not a finite number > −1.
    """
    unknown = sorted(set(relative) - set(system.params))
    if unknown:
        raise SimulationError(f"{system.name}: parameters to perturb expected among "
                              f"{', '.join(system.params)}; got {', '.join(unknown)}")
    new = {k: float(system.params[k]) * (1.0 + _finite(f"relative change of {k}", r, lo=-1.0,
                                                        lo_open=True))
           for k, r in relative.items()}
    return system.with_params(**new)


# --------------------------------------------------------------------------- (a) freeplay


def dead_band(q, gap, ramp):
    r"""The displacement a spring sees through a gap of half-width ``gap``, smoothed (C²).

    .. math::

        d(q) = \operatorname{sgn}(q)\,g(|q|), \qquad
        g(r) = \begin{cases}
            0 & r \le \delta - w \\
            2w\,(t^3 - t^4/2),\ t = \dfrac{r - \delta + w}{2w} & |r - \delta| < w \\
            r - \delta & r \ge \delta + w
        \end{cases}

    with :math:`w` = ``ramp`` :math:`\cdot\,\delta`: the contact stiffness
    :math:`d'(q)` rises from 0 to 1 as the cubic smoothstep :math:`3t^2 - 2t^3`
    across :math:`[\delta - w, \delta + w]`, so :math:`d` is piecewise quartic
    and twice continuously differentiable. At :math:`\delta = 0`, :math:`d(q) = q`
    exactly (bit for bit). JAX-traceable in ``q``.
    """
    r = jnp.abs(q)
    w = ramp * gap
    w_safe = jnp.where(w > 0, w, 1.0)
    t = jnp.clip((r - gap + w) / (2.0 * w_safe), 0.0, 1.0)
    smooth = jnp.sign(q) * 2.0 * w * (t**3 - 0.5 * t**4)
    # outside the transition: q − sgn(q)δ (so δ = 0 gives q, value and slope, exactly)
    return jnp.where(r >= gap + w, q - jnp.sign(q) * gap,
                     jnp.where(r <= gap - w, 0.0 * q, smooth))


def pitch_freeplay(system: System, gap: float, *, ramp: float = 0.2) -> System:
    r"""Pitch freeplay: the whole pitch spring acts through a gap of half-width ``gap``.

    The simulator's pitch restoring moment is
    :math:`S(\alpha) = k_\alpha\alpha + k_{\alpha2}\alpha^2 + k_{\alpha3}\alpha^3`;
    with freeplay in the linkage between aerofoil and spring the spring sees
    :math:`d(\alpha)` (:func:`dead_band`) instead of :math:`\alpha`, so

    .. math::  F_\alpha = S(\alpha) - S(d(\alpha)),

    and :math:`F_h = F_w = 0`. For :math:`|\alpha| \le \delta - w` the pitch
    spring is absent (so the structural pitch stiffness at the equilibrium is
    0 and the Hopf point of the equilibrium is lost); for
    :math:`|\alpha| \ge \delta + w` the spring is shifted by the gap.

    Args:
        system: ``flutter3dof`` or a copy (needs ``k_alpha``, ``k_alpha2``, ``k_alpha3``).
        gap: Half-width δ of the dead band (rad), ≥ 0; 0 is the nominal system.
        ramp: Half-width of the contact transition as a fraction of δ, in (0, 1].

    **Differs from the library's** ``alpha_freeplay``: the library cuts only the
    *linear* spring, :math:`k_\alpha\,\mathrm{clip}(\alpha, \pm\delta)`, smoothed by
    hyperbolae :math:`\tfrac12(\sqrt{(q+\delta)^2+\varepsilon^2} -
    \sqrt{(q-\delta)^2+\varepsilon^2})` with ε = 1% of the typical amplitude;
    here the quadratic and cubic spring terms also act through the gap, and the
    smoothing is a C² piecewise polynomial, exactly flat inside the gap, whose
    width scales with the gap (20% of δ), not with the amplitude.
    """
    gap = _finite("freeplay gap (rad)", gap, lo=0.0)
    ramp = _finite("freeplay ramp (fraction of the gap)", ramp, lo=0.0, lo_open=True)
    if ramp > 1.0:
        raise SimulationError(f"freeplay ramp: a fraction of the gap in (0, 1] expected; "
                              f"got {ramp!r}")
    ia, ka, _ = _index(system, "alpha")
    nc = len(system.coordinates)

    def spring(a, p):
        return p["k_alpha"] * a + p["k_alpha2"] * a**2 + p["k_alpha3"] * a**3

    def force(x, U, p):
        a = x[ka]
        seen = dead_band(a, p["ie_freeplay_gap"], p["ie_freeplay_ramp"])
        return jnp.zeros(nc, dtype=x.dtype).at[ia].set(spring(a, p) - spring(seen, p))

    return _with_force(system, force, "ie_freeplay",
                       {"ie_freeplay_gap": gap, "ie_freeplay_ramp": ramp},
                       {"ie_freeplay_gap": "rad", "ie_freeplay_ramp": ""})


# --------------------------------------------------------------------------- (b) friction

#: Default Stribeck and regularisation velocities per coordinate (m/s for h, rad/s for α):
#: about 1/8 and 1/70 of the stable LCOs' velocity amplitudes (0.34–0.49 m/s, 1.1–1.4 rad/s
#: at U = 15.25–17.5 m/s).
FRICTION_VELOCITIES = {"h": (0.05, 0.005), "alpha": (0.15, 0.015)}


def stribeck_force(v, coulomb, static_ratio, v_stribeck, viscous, v_reg):
    r"""Friction force of the Stribeck law at velocity ``v`` (JAX-traceable).

    .. math::

        F(v) = -\Big[F_c + (F_s - F_c)\,e^{-(v/v_s)^2}\Big]\,\frac{v}{\sqrt{v^2 + v_r^2}}
               - c_v\,v, \qquad F_s = r_s F_c .
    """
    level = coulomb * (1.0 + (static_ratio - 1.0) * jnp.exp(-((v / v_stribeck) ** 2)))
    return -level * v / jnp.sqrt(v**2 + v_reg**2) - viscous * v


def stribeck_friction(system: System, coulomb: float, *, coordinate: str = "h",
                      static_ratio: float = 1.5, stribeck_velocity: float | None = None,
                      viscous: float = 0.0, regularisation: float | None = None) -> System:
    r"""Dry friction with a Stribeck dip on one coordinate (:func:`stribeck_force`).

    .. math::

        F_q = -\Big[F_c + (F_s - F_c)\,e^{-(\dot q/v_s)^2}\Big]
              \frac{\dot q}{\sqrt{\dot q^2 + v_r^2}} - c_v\,\dot q,

    on ``coordinate`` only. The breakaway (static) level :math:`F_s = r_s F_c`
    drops to the Coulomb level :math:`F_c` as the speed passes :math:`v_s`
    (the Stribeck dip: a force that *falls* with speed, negative damping between
    stick and slip), and a viscous part :math:`c_v\dot q` is added. At zero
    velocity the law is a damper of rate :math:`F_s/v_r + c_v`, so it changes
    the linearisation at the equilibrium (the Hopf point moves up, or the
    equilibrium stays stable: small oscillations stick).

    Args:
        system: ``flutter3dof`` or a copy.
        coulomb: Coulomb level :math:`F_c` ≥ 0 (N for ``"h"``, N m for ``"alpha"``).
        coordinate: ``"h"`` or ``"alpha"``.
        static_ratio: :math:`r_s = F_s/F_c` ≥ 1 (1.5: 50% breakaway overshoot).
        stribeck_velocity: :math:`v_s` (m/s or rad/s) > 0; default
            :data:`FRICTION_VELOCITIES`.
        viscous: :math:`c_v` ≥ 0 (N s/m or N m s/rad); 0 by default, so that
            ``coulomb = 0`` is the nominal system.
        regularisation: :math:`v_r` (m/s or rad/s) > 0, the velocity scale of
            the algebraic sign :math:`v/\sqrt{v^2+v_r^2}`; default
            :data:`FRICTION_VELOCITIES`.

    **Differs from the library's** ``<q>_coulomb_friction``
    (:math:`-c\tanh(\dot q/\varepsilon)`, ε = 1% of the typical velocity
    amplitude): a Stribeck dip and a viscous part, an algebraic (not tanh)
    regularisation that approaches the sign function as :math:`1/v^2` rather than
    exponentially, and a fixed physical :math:`v_r` rather than one set by the
    amplitudes.
    """
    iq, _, kv = _index(system, coordinate)
    dv_s, dv_r = FRICTION_VELOCITIES.get(coordinate, (None, None))
    coulomb = _finite("Coulomb friction level", coulomb, lo=0.0)
    static_ratio = _finite("Stribeck static ratio F_s/F_c", static_ratio, lo=1.0)
    vs = _finite("Stribeck velocity", stribeck_velocity if stribeck_velocity is not None
                 else dv_s, lo=0.0, lo_open=True)
    vr = _finite("friction regularisation velocity", regularisation if regularisation
                 is not None else dv_r, lo=0.0, lo_open=True)
    viscous = _finite("viscous friction coefficient", viscous, lo=0.0)
    nc = len(system.coordinates)
    fu, vu = ("N", "m/s") if coordinate == "h" else ("N m", "rad/s")

    def force(x, U, p):
        f = stribeck_force(x[kv], p["ie_friction_coulomb"], p["ie_friction_static_ratio"],
                           p["ie_friction_v_stribeck"], p["ie_friction_viscous"],
                           p["ie_friction_v_reg"])
        return jnp.zeros(nc, dtype=x.dtype).at[iq].set(f)

    params = {"ie_friction_coulomb": coulomb, "ie_friction_static_ratio": static_ratio,
              "ie_friction_v_stribeck": vs, "ie_friction_viscous": viscous,
              "ie_friction_v_reg": vr}
    units = {"ie_friction_coulomb": fu, "ie_friction_static_ratio": "",
             "ie_friction_v_stribeck": vu, "ie_friction_viscous": f"{fu}/({vu})",
             "ie_friction_v_reg": vu}
    return _with_force(system, force, f"ie_friction_{coordinate}", params, units)


# --------------------------------------------------------------------------- (c) stall


def circulatory_lift(x, U, p):
    r"""Circulatory lift of the aerofoil (Jones' approximation of Wagner's function), N per m span.

    .. math::

        L_c = 2\pi\rho b U\Big[\hat c\,\big(\dot h + U\alpha + b(\tfrac12 - a)\dot\alpha\big)
              + U(c_1c_2 + c_3c_4)\,\dot w + \tfrac{U^2}{b}c_2c_4(c_1+c_3)\,w\Big],

    :math:`\hat c = c_0 - c_1 - c_3`: the circulatory parts of the heave rows of
    :math:`D` and :math:`K` in :mod:`bayeshopf.simulators.flutter` (the
    downwash at the three-quarter chord and the two lag terms). In steady
    flow (:math:`\dot h = \dot\alpha = \dot w = 0`,
    :math:`w = b\alpha/(c_2c_4U)`) it is :math:`2\pi c_0\,\rho U^2 b\,\alpha`.
    """
    h_dot, alpha, alpha_dot, w, w_dot = x[1], x[2], x[3], x[4], x[5]
    b, a, rho = p["b"], p["a"], p["rho"]
    c0, c1, c2, c3, c4 = p["c0"], p["c1"], p["c2"], p["c3"], p["c4"]
    ch = c0 - c1 - c3
    downwash = h_dot + U * alpha + b * (0.5 - a) * alpha_dot
    lag = U * (c1 * c2 + c3 * c4) * w_dot + U**2 / b * c2 * c4 * (c1 + c3) * w
    return 2.0 * jnp.pi * rho * b * U * (ch * downwash + lag)


def stall_saturation(system: System, alpha_sat: float) -> System:
    r"""Stall-like saturation of the circulatory lift with the effective angle of attack.

    With the lift slope :math:`2\pi c_0` the circulatory lift
    (:func:`circulatory_lift`) defines an effective angle of attack
    :math:`\alpha_e = L_c/(2\pi c_0\rho U^2 b)` (the quasi-steady angle seen
    through the Wagner lags). The aerofoil with stall has

    .. math::

        L = 2\pi c_0\rho U^2 b\;\alpha_s\tanh(\alpha_e/\alpha_s)
          = L_c\,\frac{\tanh(\alpha_e/\alpha_s)}{\alpha_e/\alpha_s},

    i.e. the lift saturates at :math:`2\pi c_0\rho U^2 b\,\alpha_s` and is
    reduced by :math:`(\alpha_e/\alpha_s)^2/3` (relative) at small angles. The
    lift acts at the quarter chord, :math:`b(a + \tfrac12)` ahead of the
    elastic axis, so the generalised forces of the change are

    .. math::  F_h = L_c - L, \qquad F_\alpha = b(a + \tfrac12)\,(L - L_c), \qquad F_w = 0

    (the heave row of the simulator carries :math:`+L_c`, the pitch row
    :math:`-b(a+\frac12)L_c`; for the aerofoil's :math:`a = -\tfrac12`,
    :math:`F_\alpha = 0`).

    Args:
        system: ``flutter3dof`` or a copy.
        alpha_sat: Saturation angle :math:`\alpha_s` (rad) > 0; ``math.inf``
            is the nominal system.

    **Differs from every library term**: the library has structural terms only,
    each a function of one coordinate and its own velocity; this is an
    aerodynamic force on heave that depends on :math:`\alpha, \dot h, \dot\alpha,
    w, \dot w` and on :math:`U`, cubic at leading order
    (:math:`F_h \approx L_c\,\alpha_e^2/(3\alpha_s^2)`). The nearest library
    terms (``h_cubic_stiffness``, ``alpha_cubic_stiffness``) act on the wrong
    variable.
    """
    a_s = _finite("stall saturation angle (rad)", alpha_sat, lo=0.0, lo_open=True,
                  allow_inf=True)
    inv = 0.0 if a_s == math.inf else 1.0 / a_s
    ih, _, _ = _index(system, "h")
    ia, _, _ = _index(system, "alpha")
    nc = len(system.coordinates)

    def force(x, U, p):
        lc = circulatory_lift(x, U, p)
        inv_s = p["ie_stall_inv_angle"]
        z = lc / (2.0 * jnp.pi * p["c0"] * p["rho"] * U**2 * p["b"]) * inv_s   # α_e/α_s
        small = jnp.abs(z) < 1e-2
        z_safe = jnp.where(small, 1.0, z)
        # tanh(z)/z − 1, by its Taylor series where |z| < 0.01 (exactly 0 at z = 0;
        # truncation error < 3e-18 there)
        z2 = z**2
        series = z2 * (-1.0 / 3.0 + z2 * (2.0 / 15.0 - z2 * 17.0 / 315.0))
        rel = jnp.where(small, series, jnp.tanh(z_safe) / z_safe - 1.0)
        dl = lc * rel                                                        # L − L_c
        F = jnp.zeros(nc, dtype=x.dtype)
        return F.at[ih].set(-dl).at[ia].set(p["b"] * (p["a"] + 0.5) * dl)

    return _with_force(system, force, "ie_stall", {"ie_stall_inv_angle": inv},
                       {"ie_stall_inv_angle": "1/rad"})


# --------------------------------------------------------------------------- (d) cubic


def pitch_cubic_stiffness(system: System, k3: float) -> System:
    r"""An extra cubic pitch spring (the control case: a library-like effect, written here).

    .. math::  F_\alpha = -k_3\,\alpha^3, \qquad F_h = F_w = 0,

    so the pitch spring's cubic coefficient becomes :math:`k_{\alpha3} + k_3`.

    Args:
        system: ``flutter3dof`` or a copy.
        k3: :math:`k_3` (N m/rad³), any sign (> 0 hardens); 0 is the nominal system.

    **Same functional form as the library's** ``alpha_cubic_stiffness``
    (coefficient :math:`c = k_3`); the case in which the truth *is* in the
    library, written without it.
    """
    k3 = _finite("cubic pitch stiffness (N m/rad^3)", k3)
    ia, ka, _ = _index(system, "alpha")
    nc = len(system.coordinates)

    def force(x, U, p):
        return jnp.zeros(nc, dtype=x.dtype).at[ia].set(-p["ie_cubic_k3"] * x[ka] ** 3)

    return _with_force(system, force, "ie_cubic", {"ie_cubic_k3": k3},
                       {"ie_cubic_k3": "N m/rad^3"})


# --------------------------------------------------------------------------- (e) library-like


#: Forces of the library's kinds, written here from their equations: ``kind -> (force of
#: (q, q_dot, c), unit suffix)``. Stiffness acts on the displacement, damping on the velocity.
POLYNOMIAL_KINDS = {
    "quadratic_stiffness": (lambda q, v, c: -c * q * q, "/{q}^2"),
    "cubic_stiffness": (lambda q, v, c: -c * q * q * q, "/{q}^3"),
    "quintic_stiffness": (lambda q, v, c: -c * q**5, "/{q}^5"),
    "quadratic_damping": (lambda q, v, c: -c * v * jnp.abs(v), "/({q}/s)^2"),
    "cubic_damping": (lambda q, v, c: -c * v * v * v, "/({q}/s)^3"),
}


def polynomial_force(system: System, coefficient: float, *, coordinate: str = "h",
                     kind: str = "cubic_stiffness") -> System:
    r"""A polynomial spring or damper on one coordinate (a library-like effect, written here).

    .. math::

        F_q = -c\,q^2,\ -c\,q^3,\ -c\,q^5 \quad\text{(stiffness)}, \qquad
        F_q = -c\,\dot q\,|\dot q|,\ -c\,\dot q^3 \quad\text{(damping)},

    on ``coordinate`` only, the other generalised forces 0.

    Args:
        system: ``flutter3dof`` or a copy.
        coefficient: :math:`c` (N or N m over the power of m, rad, m/s or rad/s),
            any sign; 0 is the nominal system.
        coordinate: ``"h"`` or ``"alpha"``.
        kind: A key of :data:`POLYNOMIAL_KINDS`.

    **Same physics as the library's** ``<q>_<kind>`` (positive :math:`c` adds
    to the restoring or damping force), written without it: no smoothing of
    :math:`|\dot q|` (the library smooths it near 0).
    """
    if kind not in POLYNOMIAL_KINDS:
        raise SimulationError(f"polynomial force: kind expected among "
                              f"{', '.join(POLYNOMIAL_KINDS)}; got {kind!r}")
    c = _finite(f"{kind} coefficient", coefficient)
    iq, kq, kv = _index(system, coordinate)
    law, suffix = POLYNOMIAL_KINDS[kind]
    nc = len(system.coordinates)
    qu = "m" if coordinate == "h" else "rad"
    fu = "N" if coordinate == "h" else "N m"
    key = f"ie_poly_{coordinate}_{kind}"

    def force(x, U, p):
        return jnp.zeros(nc, dtype=x.dtype).at[iq].set(law(x[kq], x[kv], p[key]))

    return _with_force(system, force, key, {key: c}, {key: fu + suffix.format(q=qu)})


def coulomb_friction(system: System, level: float, *, coordinate: str = "h") -> System:
    r"""Dry (Coulomb) friction without a Stribeck dip: :func:`stribeck_friction` at :math:`r_s = 1`.

    .. math::  F_q = -F_c\,\frac{\dot q}{\sqrt{\dot q^2 + v_r^2}}

    (the library's ``<q>_coulomb_friction`` is :math:`-c\tanh(\dot q/\varepsilon_v)`:
    the same physics, another regularisation and width).
    """
    return stribeck_friction(system, level, coordinate=coordinate, static_ratio=1.0)


def lagged_lift(x, U, p):
    r"""The lagged (Wagner) part of the circulatory lift, N per m span (:func:`circulatory_lift`).

    .. math::  L_w = 2\pi\rho b U\Big[U(c_1c_2 + c_3c_4)\,\dot w
               + \tfrac{U^2}{b}c_2c_4(c_1+c_3)\,w\Big].
    """
    w, w_dot = x[4], x[5]
    b, rho = p["b"], p["rho"]
    c1, c2, c3, c4 = p["c1"], p["c2"], p["c3"], p["c4"]
    return 2.0 * jnp.pi * rho * b * U * (U * (c1 * c2 + c3 * c4) * w_dot
                                         + U**2 / b * c2 * c4 * (c1 + c3) * w)


def lagged_pitch_moment(system: System, offset: float) -> System:
    r"""A lagged aerodynamic pitching moment: the lift's lag part acting off the elastic axis.

    .. math::  F_\alpha = e\,b\,L_w(w, \dot w, U), \qquad F_h = F_w = 0,

    with :math:`L_w` the lagged part of the circulatory lift (:func:`lagged_lift`):
    as if that part of the lift acted :math:`e` semichords ahead of the elastic
    axis (positive :math:`e`: nose-up), while the simulator puts all of it at the
    quarter chord (on the elastic axis for :math:`a = -\tfrac12`).

    Args:
        system: ``flutter3dof`` or a copy.
        offset: :math:`e` (semichords), any sign; 0 is the nominal system.

    **Differs from every library term**: it depends on the aerodynamic lag state
    :math:`w` and on :math:`U`, and it is linear, so it moves the Hopf point.
    """
    e = _finite("lagged moment offset (semichords)", offset)
    ia, _, _ = _index(system, "alpha")
    nc = len(system.coordinates)

    def force(x, U, p):
        return jnp.zeros(nc, dtype=x.dtype).at[ia].set(
            p["ie_lag_offset"] * p["b"] * lagged_lift(x, U, p))

    return _with_force(system, force, "ie_lag_moment", {"ie_lag_offset": e},
                       {"ie_lag_offset": "semichord"})


#: Library-like effects written here, by the library term whose physics each is:
#: ``term name -> (builder(system, size), size unit, size parameter)``.
LIBRARY_LIKE = {
    **{f"{c}_{k}": ((lambda s, v, c=c, k=k: polynomial_force(s, v, coordinate=c, kind=k)),
                    ("N" if c == "h" else "N m")
                    + POLYNOMIAL_KINDS[k][1].format(q="m" if c == "h" else "rad"),
                    f"ie_poly_{c}_{k}")
       for c in ("h", "alpha") for k in POLYNOMIAL_KINDS},
    "h_coulomb_friction": (lambda s, v: coulomb_friction(s, v, coordinate="h"), "N",
                           "ie_friction_coulomb"),
    "alpha_coulomb_friction": (lambda s, v: coulomb_friction(s, v, coordinate="alpha"),
                               "N m", "ie_friction_coulomb"),
    "alpha_freeplay": (lambda s, v: pitch_freeplay(s, v), "rad", "ie_freeplay_gap"),
}


# --------------------------------------------------------------------------- noise


def coloured_noise(recordings, fraction: float, *, phi: float = 0.9,
                   outlier_rate: float = 0.0, outlier_scale: float = 6.0, seed: int = 0):
    r"""The recordings with coloured noise and occasional outliers added (a new set).

    Each channel gets :math:`\sigma e_t`, with :math:`\sigma` = ``fraction`` times
    the channel's standard deviation and :math:`e` a stationary AR(1) process of
    unit variance, :math:`e_t = \phi e_{t-1} + \sqrt{1-\phi^2}\,\xi_t`,
    :math:`\xi_t \sim \mathcal N(0, 1)`; each sample is, with probability
    ``outlier_rate``, moved by a spike :math:`\pm\sigma s\,(1 + |\zeta|)`,
    ``s`` = ``outlier_scale``, :math:`\zeta \sim \mathcal N(0, 1)`, random sign.
    The likelihood of :mod:`bayeshopf` assumes neither the correlation nor the
    outliers. Names, times and metadata are kept; the inputs are not changed.
    """
    from scipy.signal import lfilter

    from bayeshopf.data.recording import RecordingSet

    fraction = _finite("noise fraction", fraction, lo=0.0)
    phi = _finite("AR(1) coefficient", phi, lo=0.0)
    if phi >= 1.0:
        raise SimulationError(f"AR(1) coefficient: a number in [0, 1) expected; got {phi!r}")
    rate = _finite("outlier rate", outlier_rate, lo=0.0)
    rng = np.random.default_rng(seed)
    out = []
    for r in recordings:
        chans = {}
        for name, z in r.channels.items():
            z = np.asarray(z, float)
            sigma = fraction * float(np.std(z))
            e = lfilter([math.sqrt(1.0 - phi * phi)], [1.0, -phi], rng.standard_normal(z.size),
                        zi=[phi * rng.standard_normal()])[0]
            spikes = (rng.random(z.size) < rate) * rng.choice([-1.0, 1.0], z.size) * (
                outlier_scale * (1.0 + np.abs(rng.standard_normal(z.size))))
            chans[name] = z + sigma * (e + spikes)
        out.append(dataclasses.replace(r, channels=chans))
    return RecordingSet(tuple(out), recordings.planar, mu_label=recordings.mu_label,
                        mu_units=recordings.mu_units, extra=dict(recordings.extra))


#: The effects by name: ``name -> (builder(system, size), size unit, size parameter)``.
#: The size parameter is the one :func:`tracked_orbit` continues from 0 (for the stall:
#: the inverse saturation angle, 0 for none).
EFFECTS = {
    "pitch_freeplay": (pitch_freeplay, "rad", "ie_freeplay_gap"),
    "heave_stribeck_friction": (lambda s, v: stribeck_friction(s, v, coordinate="h"), "N",
                                "ie_friction_coulomb"),
    "pitch_stribeck_friction": (lambda s, v: stribeck_friction(s, v, coordinate="alpha"),
                                "N m", "ie_friction_coulomb"),
    "stall_saturation": (stall_saturation, "rad", "ie_stall_inv_angle"),
    "lagged_pitch_moment": (lagged_pitch_moment, "semichord", "ie_lag_offset"),
    "pitch_cubic_stiffness": (pitch_cubic_stiffness, "N m/rad^3", "ie_cubic_k3"),
}
#: Base-parameter errors for comparison: ``perturb_<name>`` changes ``name`` by a relative
#: amount (:func:`perturb_params`), continued from its nominal value.
def _perturb_one(name: str):
    def build(system: System, relative: float) -> System:
        return perturb_params(system, {name: relative})
    return build


PERTURBATIONS = {f"perturb_{k}": (_perturb_one(k), "relative", k)
                 for k in ("k_h", "k_alpha", "c_h", "c0")}


# --------------------------------------------------------------------------- orbits


def stable_orbit(system: System, mu: float, x0, period: float, *, settle_periods: int = 40,
                 n_points: int = N_ORBIT) -> PeriodicOrbit:
    """The stable LCO reached from ``x0``: integrate, then correct by Newton's method.

    The flow is integrated for ``settle_periods`` periods (transients of a
    stable LCO decay as its largest nontrivial Floquet multiplier to that
    power), then :func:`~bayeshopf.simulators.periodic_orbit` corrects the
    end point and period.

    Args:
        system: The system.
        mu: The bifurcation parameter.
        x0: A starting point (e.g. on the nominal system's stable orbit).
        period: A guess of the period.
        settle_periods: Periods integrated before the correction.
        n_points: Samples of the returned orbit (default: as many as
            :func:`~bayeshopf.simulators.simulate_recordings` reads, so that one
            compiled sampler serves the settling, the orbit and the recordings).

    Raises:
        SimulationError: If the integration leaves the domain, Newton's method
            fails, or the orbit found is not Floquet-stable.
    """
    ensure_x64()
    xs = sample_orbit(system, np.asarray(x0, float), float(period) * settle_periods, mu,
                      n_points)
    x_end = xs[-1]
    if not np.all(np.isfinite(x_end)) or np.max(np.abs(x_end)) > 1e3 * (1 + np.max(np.abs(x0))):
        raise SimulationError(f"{system.name}: the flow from the guess at {system.parameter} "
                              f"= {mu:g} does not settle on an LCO (diverged)")
    orbit = periodic_orbit(system, mu, x_end, period, n_points=n_points)
    if not orbit.stable:
        raise SimulationError(f"{system.name}: the orbit found at {system.parameter} = {mu:g} "
                              f"is not Floquet-stable (|multipliers| "
                              f"{np.round(np.abs(orbit.floquet), 4).tolist()})")
    return orbit


def _newton(system: System, p: dict, mu: float, x0: np.ndarray, period: float, *,
            tol: float = 1e-10, max_iter: int = 20) -> tuple[np.ndarray, float] | None:
    r"""Periodic orbit near ``(x0, period)`` with the parameters ``p`` (a pytree), or ``None``.

    The equations of :func:`~bayeshopf.simulators.periodic_orbit`
    (:math:`\varphi_T(x_0) = x_0`, phase condition on the guess), solved with the
    system's compiled shooting kernel at parameters other than its own, so that
    a homotopy in one parameter compiles nothing new.
    """
    from bayeshopf.simulators.periodic import kernels

    k = kernels(system)
    m = jnp.asarray(mu, dtype=jnp.float64)
    xhat = np.array(x0, dtype=np.float64)
    fhat = np.asarray(k.f(jnp.asarray(xhat), m, p))
    x, T, n = xhat.copy(), float(period), xhat.size
    for _ in range(max_iter):
        out = np.asarray(k.shoot(jnp.asarray(x), jnp.asarray(T), m, p))
        if out[-1] < 0.5 or not np.all(np.isfinite(out)):
            return None
        x1, phi, f1 = out[:n], out[n:n + n * n].reshape(n, n), out[2 * n + n * n:3 * n + n * n]
        A = np.zeros((n + 1, n + 1))
        A[:n, :n], A[:n, n], A[n, :n] = phi - np.eye(n), f1, fhat
        try:
            d = np.linalg.solve(A, -np.concatenate([x1 - x, [(x - xhat) @ fhat]]))
        except np.linalg.LinAlgError:
            return None
        x, T = x + d[:n], T + d[n]
        if T <= 0:
            return None
        if np.max(np.abs(d[:n])) <= tol * (1 + np.max(np.abs(x))) and abs(d[n]) <= tol * T:
            return x, T
    return None


def tracked_orbit(system: System, param: str, mu: float, x0, period: float, *,
                  start: float = 0.0, steps: int = 8, stable: bool | None = None,
                  n_points: int = N_ORBIT) -> PeriodicOrbit:
    """The orbit of ``system`` continued from ``(x0, period)`` at ``param = start`` (homotopy).

    ``param`` (an effect's size, e.g. ``"ie_freeplay_gap"``) goes from
    ``start`` to the system's value in ``steps`` equal steps (halved, up to
    three times, where Newton's method fails); the last orbit is corrected by
    :func:`~bayeshopf.simulators.periodic_orbit` on ``system`` itself. This
    follows unstable LCOs too, and works where the effect removes the Hopf
    point the branches are born at. ``(x0, period)`` is usually the nominal
    system's orbit at ``mu``, with ``start = 0``; ``stable`` (if given) is the
    Floquet stability the orbit must keep (its branch): Newton's method can
    jump to the other branch where the tracked one ends at a fold in ``param``.

    Raises:
        SimulationError: If the orbit is lost on the way or ends on the other branch.
    """
    ensure_x64()
    if param not in system.params:
        raise SimulationError(f"{system.name}: homotopy parameter expected among "
                              f"{', '.join(system.params)}; got {param!r}")
    target = float(system.params[param])
    base = system.param_tree()
    x, T = np.asarray(x0, float), float(period)
    done, h = 0.0, 1.0 / max(int(steps), 1)
    halvings = 0
    while done < 1.0 - 1e-12:
        step = min(h, 1.0 - done)
        w = done + step
        p = {**base, param: jnp.asarray(start + w * (target - start), dtype=jnp.float64)}
        sol = _newton(system, p, mu, x, T)
        if sol is None:
            halvings += 1
            if halvings > 3:
                raise SimulationError(
                    f"{system.name}: orbit at {system.parameter} = {mu:g} lost at {param} = "
                    f"{start + done * (target - start):.6g} (target {target:.6g})")
            h *= 0.5
            continue
        (x, T), done = sol, w
    orbit = periodic_orbit(system, mu, x, T, n_points=n_points)
    if stable is not None and orbit.stable != stable:
        raise SimulationError(
            f"{system.name}: the {'stable' if stable else 'unstable'} orbit at "
            f"{system.parameter} = {mu:g} is lost: the homotopy in {param} ended on a "
            f"{'stable' if orbit.stable else 'unstable'} one (amplitude "
            f"{', '.join(f'{c} {v:.4g}' for c, v in orbit.amplitude.items())})")
    return orbit


@dataclasses.dataclass(frozen=True)
class _Span:
    kind: str
    mus: tuple[float, ...]

    @property
    def mu_span(self) -> tuple[float, float]:
        return (min(self.mus), max(self.mus)) if self.mus else (math.nan, math.nan)

    def exists(self, mu: float) -> bool:
        return float(mu) in self.mus


class OrbitSet:
    """Orbits found one by one, in the form ``simulate_recordings(diagram=...)`` reads.

    Args:
        system: The system the orbits belong to.
        orbits: ``(mu, branch) -> PeriodicOrbit`` (``branch`` ``"stable"`` or
            ``"unstable"``); ``orbit_at`` re-samples them at the requested
            number of points.
    """

    def __init__(self, system: System, orbits: Mapping[tuple[float, str], PeriodicOrbit]):
        self.system = system
        self.orbits = {(float(m), str(b)): o for (m, b), o in orbits.items()}
        self.hopf = SimpleNamespace(mu=math.nan)
        self.folds = ()

    def branch(self, kind: str) -> _Span:
        return _Span(kind, tuple(m for m, b in self.orbits if b == kind))

    def orbit_at(self, mu: float, branch: str = "stable", *, n_points: int | None = None
                 ) -> PeriodicOrbit:
        o = self.orbits[(float(mu), branch)]
        if n_points is None or n_points == o.states.shape[0]:
            return o
        states = sample_orbit(self.system, o.x0, o.period, o.mu, int(n_points))
        return dataclasses.replace(o, states=states)


def blind_recordings(system: System, base_name: str, orbits: OrbitSet, mu, branch, **kwargs):
    """``simulate_recordings`` of ``system`` on ``orbits``, naming only ``base_name`` as source.

    The recordings carry no trace of the effect (source and set metadata name
    the base system); keyword arguments go to
    :func:`~bayeshopf.simulators.simulate_recordings`.
    """
    from bayeshopf.data.recording import RecordingSet

    rs = simulate_recordings(system, mu, branch, diagram=orbits, **kwargs)
    seed = kwargs.get("seed", 0)
    src = f"simulated {base_name} (bayeshopf.simulators, seed={seed})"
    recs = tuple(dataclasses.replace(r, source=src) for r in rs)
    return RecordingSet(recs, rs.planar, mu_label=rs.mu_label, mu_units=rs.mu_units,
                        extra={"simulated": base_name, "seed": str(seed),
                               "noise": repr(kwargs.get("noise", 0.01))})
