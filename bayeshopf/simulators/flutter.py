r"""The 3-DOF aeroelastic aerofoil of the paper (Section 4.2, eq. flutter2, Table t1).

Heave :math:`h` (m), pitch :math:`\alpha` (rad) and an aerodynamic lag state
:math:`w` obey

.. math::  M\ddot q + D(U)\dot q + K(U) q + N(\alpha) = 0, \qquad q = [h, \alpha, w]^T,

with the airspeed :math:`U` (m/s) as bifurcation parameter,
:math:`\hat c = c_0 - c_1 - c_3`, :math:`N = [0,\ k_{\alpha2}\alpha^2 + k_{\alpha3}\alpha^3,\ 0]^T`
(so the pitch stiffness is :math:`k_\alpha + k_{\alpha2}\alpha + k_{\alpha3}\alpha^2`
per radian) and

.. math::

    M = \begin{bmatrix}
        m_T + \pi\rho b^2 & m_w x_\alpha b - a\pi\rho b^3 & 0 \\
        m_w x_\alpha b - a\pi\rho b^3 & I_\alpha + \pi(1/8 + a^2)\rho b^4 & 0 \\
        0 & 0 & 1 \end{bmatrix},

    D = \begin{bmatrix}
        c_h + 2\pi\rho b U \hat c & (1 + \hat c(1-2a))\pi\rho b^2 U
            & 2\pi\rho b U^2 (c_1c_2 + c_3c_4) \\
        -2\pi(a+1/2)\rho b^2 \hat c U & c_\alpha + (1/2-a)(1-\hat c(1+2a))\pi\rho b^3 U
            & -2\pi\rho b^2 U^2 (a+1/2)(c_1c_2 + c_3c_4) \\
        -1/b & a - 1/2 & (c_2 + c_4) U/b \end{bmatrix},

    K = \begin{bmatrix}
        k_h & 2\pi\rho b U^2 \hat c & 2\pi\rho U^3 c_2c_4(c_1 + c_3) \\
        0 & k_\alpha - 2\pi(1/2+a)\rho \hat c b^2 U^2 & -2\pi\rho b U^3 (a+1/2) c_2c_4(c_1+c_3) \\
        0 & -U/b & c_2c_4 U^2/b^2 \end{bmatrix}.

It is integrated, as the authors' Julia code does, in the six first-order
states :math:`x = [h, \dot h, \alpha, \dot\alpha, w, \dot w]` with
:math:`\ddot q = -M^{-1}(D\dot q + Kq + N(\alpha))`.

**Which reading.** The third row of :math:`M` is :math:`[0, 0, 1]`: the lag
equation is :math:`\ddot w + (c_2+c_4)(U/b)\dot w + c_2c_4(U/b)^2 w = \dot h/b
+ (1/2 - a)\dot\alpha + (U/b)\alpha`, so :math:`w` is a second-order state
(unit: s) and needs both :math:`w` and :math:`\dot w`. The paper's eq. (12) and
Table t1 print the two heave-row couplings to the lag state as
:math:`2\pi U^2 b(c_1c_2+c_3c_4)` (in :math:`D_{13}`) and
:math:`2\pi U^3 c_2c_4(c_1+c_3)` (in :math:`K_{13}`), without the air density.
The derivation keeps :math:`\rho`: every aerodynamic force is proportional to
:math:`\rho`, the pitch-row terms next to them have it, and only with it are
the units those of a force per unit span (kg/s² for :math:`D_{13}\dot w`,
kg/s³ for :math:`K_{13}`). This module implements the derivation, with
:math:`\rho`. That reading puts the Hopf point at :math:`U_0 = 18.2747` m/s
with frequency 15.50 rad/s (2.466 Hz) and the fold of the LCO branch at
14.94 m/s, the values the paper reports (:math:`\mu_0 = 18.28`,
:math:`a_2 = 3.65`, i.e. fold :math:`\mu_0 - a_2^2/4 \approx 14.95`) and the
authors' code computes; the literal reading without :math:`\rho` puts the Hopf
point at 18.97 m/s instead.

With :math:`a = -1/2` (elastic axis at the quarter chord) every :math:`(a + 1/2)`
term vanishes, so the lag state drives only the heave equation.

The parameter values are those of the authors' code: :math:`c_\alpha` and
:math:`k_\alpha` to full precision (Table t1 rounds them) and
:math:`k_{\alpha3} = 5006` (Table t1 says 5006.7). Heave ``h`` (m) and
pitch ``alpha`` (rad) are observed; :math:`w` never is.

**Uncertain parameters** (:data:`FLUTTER_UNCERTAIN`, priors centred on the
values above; :class:`~bayeshopf.simulators.base.UncertainParameter`). The
aerodynamic coefficients are those of Jones' approximation of Wagner's
indicial lift function, :math:`\phi(s) = c_0 - c_1 e^{-c_2 s} - c_3 e^{-c_4 s}`
in reduced time :math:`s = Ut/b` (1, 0.165, 0.0455, 0.335, 0.3 for a thin
aerofoil in inviscid flow): :math:`c_0` scales the steady circulatory lift
(lift-curve slope :math:`2\pi c_0`), :math:`c_1, c_3` are the amplitudes and
:math:`c_2, c_4` the rates of the two lags. The widths (relative standard
deviations) are what a test engineer would accept for a rig of this kind:

==================  =========  ======  ===================================================
parameter           prior      width   why
==================  =========  ======  ===================================================
k_h, k_alpha        lognormal  10%     linear springs, from static load tests and the
                                       measured natural frequencies
c_h, c_alpha        lognormal  30%     structural damping from free decays: varies with
                                       amplitude and mounting
c0                  lognormal  10%     a real section's lift-curve slope at the rig's
                                       Reynolds number (~10⁵) is 0.85–1.0 × 2π
c1, c2, c3, c4      lognormal  30%     the lags are fitted to thin-aerofoil theory; a real
                                       section's indicial response differs by tens of %
k_alpha2            normal     30%     the asymmetric (even) part of the measured moment–
                                       angle curve, the least certain term of its fit
k_alpha3            lognormal  20%     the hardening of the pitch spring, from the same fit;
                                       log-normal keeps it hardening
==================  =========  ======  ===================================================

The geometry and inertia (b, a, ρ, masses, :math:`I_\alpha`, :math:`x_\alpha`) are
measured directly and are taken as exact.
"""

from __future__ import annotations

import jax.numpy as jnp

from bayeshopf.simulators.base import System, UncertainParameter

__all__ = ["FLUTTER3DOF", "FLUTTER_PARAMS", "FLUTTER_UNCERTAIN", "flutter_matrices", "flutter_rhs"]

#: Table t1 with the authors' code's precision.
FLUTTER_PARAMS: dict[str, float] = {
    "b": 0.15,
    "a": -0.5,
    "rho": 1.204,
    "m_w": 5.3,
    "m_T": 16.9,
    "I_alpha": 0.1726,
    "c_alpha": 0.562766779889303,
    "c_h": 15.443,
    "k_alpha": 54.116182926744390,
    "k_alpha2": 751.6,
    "k_alpha3": 5006.0,
    "k_h": 3529.4,
    "x_alpha": 0.234,
    "c0": 1.0,
    "c1": 0.1650,
    "c2": 0.0455,
    "c3": 0.335,
    "c4": 0.3,
}
FLUTTER_UNITS: dict[str, str] = {
    "b": "m", "a": "", "rho": "kg/m^3", "m_w": "kg", "m_T": "kg", "I_alpha": "kg m^2",
    "c_alpha": "kg m^2/s", "c_h": "kg/s", "k_alpha": "N m/rad", "k_alpha2": "N m/rad^2",
    "k_alpha3": "N m/rad^3", "k_h": "N/m", "x_alpha": "", "c0": "", "c1": "", "c2": "",
    "c3": "", "c4": "",
}

_WHY_K = "linear spring: static load tests and the measured natural frequencies (±10%)"
_WHY_D = "structural damping from free decays, amplitude- and mounting-dependent (±30%)"
_WHY_LAG = "Jones' lag fitted to thin-aerofoil theory; real sections differ (±30%)"
#: The parameters of :data:`FLUTTER_PARAMS` known only to within a prior (module docstring).
#: Tolerances (the error that still counts as right): 1% for the springs (what
#: a static load test resolves), 2% for the lift slope and the pitch spring's
#: hardening, 3% for the damping, the lag coefficients and the spring's even term.
FLUTTER_UNCERTAIN: tuple[UncertainParameter, ...] = (
    # springs
    *(UncertainParameter(k, "lognormal", 0.10, _WHY_K, tolerance=0.01)
      for k in ("k_h", "k_alpha")),
    # damping
    *(UncertainParameter(c, "lognormal", 0.30, _WHY_D, tolerance=0.03)
      for c in ("c_h", "c_alpha")),
    # aerodynamics: the lift slope, then the lag coefficients
    UncertainParameter("c0", "lognormal", 0.10,
                       "steady lift-curve slope 2π·c0; real sections at Re ~ 1e5: 0.85–1.0 "
                       "(±10%)", tolerance=0.02),
    *(UncertainParameter(c, "lognormal", 0.30, _WHY_LAG, tolerance=0.03)
      for c in ("c1", "c2", "c3", "c4")),
    # the pitch spring's nonlinearity
    UncertainParameter("k_alpha2", "normal", 0.30,
                       "even part of the fitted moment-angle curve, its least certain term "
                       "(±30%)", tolerance=0.03),
    UncertainParameter("k_alpha3", "lognormal", 0.20,
                       "hardening of the pitch spring from the same fit; stays hardening (±20%)",
                       tolerance=0.02),
)


def flutter_matrices(U, p):
    """``M``, ``D(U)`` and ``K(U)`` of eq. flutter2 (with ρ in D13 and K13; module docstring).

    Args:
        U: Airspeed (m/s).
        p: Parameters by name (:data:`FLUTTER_PARAMS`).

    Returns:
        ``(M, D, K)``, each of shape ``(3, 3)``.
    """
    b, a, rho = p["b"], p["a"], p["rho"]
    c1, c2, c3, c4 = p["c1"], p["c2"], p["c3"], p["c4"]
    ch = p["c0"] - c1 - c3                                          # ĉ = c0 − c1 − c3
    pi = jnp.pi
    m12 = p["m_w"] * p["x_alpha"] * b - a * pi * rho * b**3
    M = jnp.array([
        [p["m_T"] + pi * rho * b**2, m12, 0.0],
        [m12, p["I_alpha"] + pi * (1.0 / 8.0 + a**2) * rho * b**4, 0.0],
        [0.0, 0.0, 1.0],                                            # lag row of M: [0, 0, 1]
    ])
    s12, s34 = c1 * c2 + c3 * c4, c2 * c4 * (c1 + c3)
    D = jnp.array([
        [p["c_h"] + 2 * pi * rho * b * U * ch,
         (1 + ch * (1 - 2 * a)) * pi * rho * b**2 * U,
         2 * pi * rho * b * U**2 * s12],                            # ρ kept (paper drops it)
        [-2 * pi * (a + 0.5) * rho * b**2 * ch * U,
         p["c_alpha"] + (0.5 - a) * (1 - ch * (1 + 2 * a)) * pi * rho * b**3 * U,
         -2 * pi * rho * b**2 * U**2 * (a + 0.5) * s12],
        [-1.0 / b, a - 0.5, (c2 + c4) * U / b],
    ])
    K = jnp.array([
        [p["k_h"], 2 * pi * rho * b * U**2 * ch, 2 * pi * rho * U**3 * s34],  # ρ kept in K13
        [0.0, p["k_alpha"] - 2 * pi * (0.5 + a) * rho * ch * b**2 * U**2,
         -2 * pi * rho * b * U**3 * (a + 0.5) * s34],
        [0.0, -U / b, c2 * c4 * U**2 / b**2],
    ])
    return M, D, K


def _inv3(M):
    """Inverse of a 3 × 3 matrix by cofactors (cheaper than an LU solve inside jacfwd)."""
    a, b, c = M[0]
    d, e, f = M[1]
    g, h, i = M[2]
    adj = jnp.array([
        [e * i - f * h, c * h - b * i, b * f - c * e],
        [f * g - d * i, a * i - c * g, c * d - a * f],
        [d * h - e * g, b * g - a * h, a * e - b * d],
    ])
    return adj / (a * adj[0, 0] + b * adj[1, 0] + c * adj[2, 0])


def flutter_rhs(x, U, p):
    r"""``ẋ`` for ``x = [h, ḣ, α, α̇, w, ẇ]``: ``q̈ = −M⁻¹(D q̇ + K q + N(α))`` (eq. flutter2).

    Args:
        x: The six states.
        U: Airspeed (m/s), the bifurcation parameter.
        p: Parameters by name (:data:`FLUTTER_PARAMS`).
    """
    M, D, K = flutter_matrices(U, p)
    q = jnp.stack([x[0], x[2], x[4]])
    qd = jnp.stack([x[1], x[3], x[5]])
    alpha = x[2]
    N = jnp.stack([0.0 * alpha, p["k_alpha2"] * alpha**2 + p["k_alpha3"] * alpha**3,
                   0.0 * alpha])
    qdd = -_inv3(M) @ (D @ qd + K @ q + N)
    return jnp.stack([qd[0], qdd[0], qd[1], qdd[1], qd[2], qdd[2]])


def _force_input(x, U, p):
    """``B``: a generalised force F on (h, α, w) enters the accelerations as ``M⁻¹F``."""
    M, _, _ = flutter_matrices(U, p)
    Minv = _inv3(M)
    zero = jnp.zeros((1, 3), dtype=Minv.dtype)
    return jnp.concatenate([zero, Minv[0:1], zero, Minv[1:2], zero, Minv[2:3]], axis=0)


FLUTTER3DOF = System(
    name="flutter3dof",
    state_names=("h", "h_dot", "alpha", "alpha_dot", "w", "w_dot"),
    state_units=("m", "m/s", "rad", "rad/s", "s", ""),
    parameter="U",
    parameter_units="m/s",
    params=FLUTTER_PARAMS,
    param_units=FLUTTER_UNITS,
    rhs=flutter_rhs,
    observed=("h", "alpha"),
    mu_range=(12.0, 20.0),
    parameter_label="airspeed",
    default_plan=(
        (15.25, "stable"), (16.0, "stable"), (16.75, "stable"), (17.5, "stable"),
        (15.5, "unstable"), (16.25, "unstable"), (17.0, "unstable"), (17.75, "unstable"),
    ),
    coordinates=("h", "alpha", "w"),
    force_input=_force_input,
    description="3-DOF aeroelastic aerofoil (heave, pitch, aerodynamic lag state) of Lee, "
    "Barton & Renson, Section 4.2, eq. flutter2 with Table t1; subcritical Hopf at "
    "U = 18.27 m/s, fold of LCOs at 14.94 m/s.",
    uncertain=FLUTTER_UNCERTAIN,
)
