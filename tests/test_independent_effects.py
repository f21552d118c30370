"""Hidden effects written without the term library (tests/testbed/independent_effects.py).

Each effect is checked against a closed form worked out here (not its own
formula where another route exists): zero size is the nominal system bit for
bit; at a chosen size the change of the accelerations is ``M⁻¹F`` with ``F``
computed by hand at a few states; the linearisation at the equilibrium changes
exactly as the effect's slope at zero says (freeplay, friction) or not at all
(stall, cubic stiffness: the Hopf point stays); and the stable LCO and a
recording of it can be computed for each modified system.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from testbed import independent_effects as ie

from bayeshopf.simulators import (
    FLUTTER3DOF,
    SimulationError,
    eigenvalues,
    find_hopf,
    jacobian,
)
from bayeshopf.simulators.flutter import flutter_matrices

F = FLUTTER3DOF
P = dict(F.params)
HOPF = 18.274669458965345          # nominal, bayeshopf.simulators.flutter docstring: 18.2747


def _mass(params=None) -> np.ndarray:
    p = F.param_tree(params)
    return np.asarray(flutter_matrices(16.0, p)[0])


def _rhs(system, X, U) -> np.ndarray:
    f = jax.vmap(system.rhs, in_axes=(0, None, None))
    return np.asarray(f(jnp.asarray(X), jnp.asarray(U, dtype=jnp.float64),
                        system.param_tree()))


def _dacc(system, X, U) -> np.ndarray:
    """Change of (ḧ, α̈, ẅ) against the nominal system at states X."""
    return (_rhs(system, X, U) - _rhs(F, X, U))[:, [1, 3, 5]]


def _states(rng, n=8) -> np.ndarray:
    return rng.normal(size=(n, 6)) * np.array([0.03, 0.4, 0.1, 1.2, 0.01, 0.2])


def _spring(a: float) -> float:
    return P["k_alpha"] * a + P["k_alpha2"] * a**2 + P["k_alpha3"] * a**3


ZERO = {
    "freeplay": lambda: ie.pitch_freeplay(F, 0.0),
    "heave friction": lambda: ie.stribeck_friction(F, 0.0, coordinate="h"),
    "pitch friction": lambda: ie.stribeck_friction(F, 0.0, coordinate="alpha"),
    "stall": lambda: ie.stall_saturation(F, math.inf),
    "cubic": lambda: ie.pitch_cubic_stiffness(F, 0.0),
    "perturbation": lambda: ie.perturb_params(F, {"k_h": 0.0, "c0": 0.0}),
    "lagged moment": lambda: ie.lagged_pitch_moment(F, 0.0),
    "coulomb": lambda: ie.coulomb_friction(F, 0.0, coordinate="alpha"),
    **{f"library-like {k}": (lambda k=k: ie.LIBRARY_LIKE[k][0](F, 0.0))
       for k in ie.LIBRARY_LIKE},
}


@pytest.mark.parametrize("name", list(ZERO))
def test_zero_size_is_the_nominal_system_bit_for_bit(name):
    eff = ZERO[name]()
    X = np.vstack([np.zeros(6), _states(np.random.default_rng(1), 16)])
    for U in (13.0, 16.5, 19.0):
        assert np.array_equal(_rhs(eff, X, U), _rhs(F, X, U))
    assert np.array_equal(jacobian(eff, np.zeros(6), 16.5), jacobian(F, np.zeros(6), 16.5))


def test_freeplay_force_matches_the_dead_band_by_hand():
    # gap 0.01 rad, ramp 0.2: transition 0.008 … 0.012 rad
    eff = ie.pitch_freeplay(F, 0.01, ramp=0.2)
    X = _states(np.random.default_rng(2), 4)
    X[:, 2] = [0.005, -0.02, 0.01, 0.3]
    # inside: the spring is cut; outside: it sees α ∓ δ; at α = δ (t = 1/2) it sees
    # 2w(t³ − t⁴/2) = 0.004·(1/8 − 1/32) = 3.75e-4 rad
    F_alpha = [_spring(0.005), _spring(-0.02) - _spring(-0.01),
               _spring(0.01) - _spring(3.75e-4), _spring(0.3) - _spring(0.29)]
    want = np.linalg.solve(_mass(), np.array([[0.0, f, 0.0] for f in F_alpha]).T).T
    np.testing.assert_allclose(_dacc(eff, X, 16.0), want, rtol=1e-9, atol=1e-12)


def test_stribeck_friction_matches_the_law_by_hand():
    # F_c 0.4 N, F_s 0.6 N, v_s 0.05 m/s, v_r 0.005 m/s, viscous 2 N s/m
    eff = ie.stribeck_friction(F, 0.4, coordinate="h", static_ratio=1.5,
                               stribeck_velocity=0.05, viscous=2.0, regularisation=0.005)
    X = _states(np.random.default_rng(3), 4)
    X[:, 1] = [0.05, -0.005, 0.0, 2.0]
    F_h = [-0.4 * (1 + 0.5 / math.e) * 0.05 / math.sqrt(0.05**2 + 0.005**2) - 0.1,
           0.4 * (1 + 0.5 * math.exp(-0.01)) / math.sqrt(2) + 0.01,
           0.0,
           -0.4 * 2.0 / math.sqrt(4.0 + 0.005**2) - 4.0]          # Stribeck term e^-1600 = 0
    want = np.linalg.solve(_mass(), np.array([[f, 0.0, 0.0] for f in F_h]).T).T
    np.testing.assert_allclose(_dacc(eff, X, 16.0), want, rtol=1e-9, atol=1e-12)
    # on pitch, with the default velocities (v_s 0.15, v_r 0.015 rad/s): at α̇ = v_s
    eff = ie.stribeck_friction(F, 0.02, coordinate="alpha")
    X[:, 3] = 0.15
    f = -0.02 * (1 + 0.5 / math.e) * 0.15 / math.sqrt(0.15**2 + 0.015**2)
    want = np.linalg.solve(_mass(), np.array([0.0, f, 0.0]))
    np.testing.assert_allclose(_dacc(eff, X, 16.0), np.tile(want, (4, 1)), rtol=1e-9)


def test_library_like_forces_match_their_laws_by_hand():
    X = _states(np.random.default_rng(5), 4)
    X[:, 0] = [0.01, -0.02, 0.0, 0.03]           # h
    X[:, 1] = [0.3, -0.5, 0.0, 0.2]              # h_dot
    X[:, 2] = [0.05, -0.1, 0.02, 0.0]            # alpha
    X[:, 3] = [1.0, -0.7, 0.0, 2.0]              # alpha_dot
    h, hd, a, ad = X[:, 0], X[:, 1], X[:, 2], X[:, 3]
    cases = {                                     # name, size -> (F_h, F_alpha) by hand
        ("h_quadratic_stiffness", 2e4): (-2e4 * h * h, 0 * h),
        ("h_cubic_stiffness", 3e5): (-3e5 * h**3, 0 * h),
        ("h_quintic_stiffness", 5e8): (-5e8 * h**5, 0 * h),
        ("h_quadratic_damping", 4.0): (-4.0 * hd * np.abs(hd), 0 * h),
        ("alpha_cubic_damping", 0.1): (0 * h, -0.1 * ad**3),
        ("alpha_quintic_stiffness", 5e4): (0 * h, -5e4 * a**5),
        ("h_coulomb_friction", 0.2): (-0.2 * hd / np.sqrt(hd**2 + 0.005**2), 0 * h),
    }
    for (name, c), (fh, fa) in cases.items():
        build, unit, param = ie.LIBRARY_LIKE[name]
        eff = build(F, c)
        assert eff.params[param] == c and eff.param_units[param] == unit
        forces = np.stack([fh, fa, 0 * h], axis=1)
        want = np.linalg.solve(_mass(), forces.T).T
        np.testing.assert_allclose(_dacc(eff, X, 16.0), want, rtol=1e-9, atol=1e-12,
                                   err_msg=name)
    assert ie.LIBRARY_LIKE["h_cubic_stiffness"][1] == "N/m^3"
    assert ie.LIBRARY_LIKE["alpha_quadratic_damping"][1] == "N m/(rad/s)^2"


def test_lagged_moment_is_the_lift_lag_part_off_the_axis():
    """F_α = e·b·(L_c(x) − L_c(x with w = ẇ = 0)): the lift's lag part, by subtraction."""
    X = _states(np.random.default_rng(6), 6)
    p = F.param_tree()
    eff = ie.lagged_pitch_moment(F, 0.05)
    for U in (14.0, 17.0):
        X0 = X.copy()
        X0[:, 4:] = 0.0
        lag = np.array([float(ie.circulatory_lift(jnp.asarray(x), U, p)
                              - ie.circulatory_lift(jnp.asarray(x0), U, p))
                        for x, x0 in zip(X, X0, strict=True)])
        forces = np.stack([0 * lag, 0.05 * P["b"] * lag, 0 * lag], axis=1)
        want = np.linalg.solve(_mass(), forces.T).T
        np.testing.assert_allclose(_dacc(eff, X, U), want, rtol=1e-9, atol=1e-12)
    # linear: it moves the Hopf point (nose-up lag moment: earlier flutter)
    assert find_hopf(eff).mu < HOPF - 0.1


def test_coloured_noise_has_the_correlation_scale_and_outliers_asked():
    from bayeshopf.simulators import simulate_recordings

    rs = simulate_recordings(F, [16.0], "stable", noise=0.0, duration_s=20.0, seed=3)
    before = {c: np.array(v) for c, v in rs[0].channels.items()}
    noisy = ie.coloured_noise(rs, 0.02, phi=0.9, outlier_rate=0.01, outlier_scale=6.0,
                              seed=4)
    for c, z in before.items():
        np.testing.assert_array_equal(rs[0].channels[c], z)       # inputs untouched
        e = (np.asarray(noisy[0].channels[c]) - z) / (0.02 * z.std())
        spikes = np.abs(e) > 5.0                  # AR(1) of unit variance: P(>5) ~ 6e-7
        assert 0.005 * e.size < spikes.sum() < 0.016 * e.size
        e = e[~spikes]
        assert 0.85 < e.std() < 1.15
        assert 0.86 < np.corrcoef(e[:-1], e[1:])[0, 1] < 0.94
    assert noisy[0].name == rs[0].name and noisy.planar == rs.planar


def test_viscous_part_and_cubic_stiffness_equal_the_simulators_own_parameters():
    """Two effects that the simulator can also express: c_h + c_v, and k_alpha3 + k3."""
    X = _states(np.random.default_rng(4), 16)
    visc = ie.stribeck_friction(F, 0.0, coordinate="h", viscous=3.0)
    np.testing.assert_allclose(_rhs(visc, X, 16.0), _rhs(F.with_params(c_h=P["c_h"] + 3.0),
                                                         X, 16.0), rtol=1e-12, atol=1e-12)
    cubic = ie.pitch_cubic_stiffness(F, 300.0)
    ref = F.with_params(k_alpha3=P["k_alpha3"] + 300.0)
    np.testing.assert_allclose(_rhs(cubic, X, 16.0), _rhs(ref, X, 16.0), rtol=1e-12,
                               atol=1e-12)


def test_circulatory_lift_is_the_simulators_circulatory_force():
    """L_c against the matrices of flutter_matrices, less their structural and
    non-circulatory parts: heave row = k_h h + c_h ḣ + πρb²U α̇ + L_c, pitch row =
    k_α α + c_α α̇ + (1/2 − a)πρb³U α̇ − b(a + 1/2) L_c (elastic axis at a = −0.3 so that
    the pitch row carries the lift too)."""
    X = _states(np.random.default_rng(5), 6)
    for a in (-0.5, -0.3):
        sysa = F.with_params(a=a)
        p = sysa.param_tree()
        for U in (13.0, 17.0):
            _, D, K = (np.asarray(m) for m in flutter_matrices(U, p))
            b, rho = P["b"], P["rho"]
            for x in X:
                q, qd = x[[0, 2, 4]], x[[1, 3, 5]]
                row = D @ qd + K @ q
                lc = float(ie.circulatory_lift(jnp.asarray(x), U, p))
                heave = P["k_h"] * x[0] + P["c_h"] * x[1] + math.pi * rho * b**2 * U * x[3]
                pitch = (P["k_alpha"] * x[2] + P["c_alpha"] * x[3]
                         + (0.5 - a) * math.pi * rho * b**3 * U * x[3])
                assert row[0] == pytest.approx(heave + lc, rel=1e-12, abs=1e-12)
                assert row[1] == pytest.approx(pitch - b * (a + 0.5) * lc, rel=1e-12,
                                               abs=1e-12)


def test_stall_saturates_the_steady_lift_curve():
    U, a_s = 16.0, 0.15
    q = P["rho"] * U**2 * P["b"]                     # 2q·b per unit span / 2
    slope = 2 * math.pi * P["c0"] * q                # steady lift per radian (N/rad)
    ch = P["c0"] - P["c1"] - P["c3"]
    eff = ie.stall_saturation(F, a_s)
    # steady states: ḣ = α̇ = ẇ = 0, w = bα/(c2c4U) → lift = slope·α, saturated to
    # slope·α_s·tanh(α/α_s); a heave-velocity state: α_e = ĉ ḣ/(c0 U)
    rows, F_h = [], []
    for alpha in (0.05, -0.2, 0.4, 1e-3):      # 1e-3: |α_e/α_s| < 0.01, the series branch
        w = P["b"] * alpha / (P["c2"] * P["c4"] * U)
        rows.append([0.01, 0.0, alpha, 0.0, w, 0.0])
        F_h.append(slope * (alpha - a_s * math.tanh(alpha / a_s)))
    hd = 0.8
    rows.append([0.0, hd, 0.0, 0.0, 0.0, 0.0])
    ae = ch * hd / (P["c0"] * U)
    F_h.append(slope * (ae - a_s * math.tanh(ae / a_s)))
    X = np.array(rows)
    want = np.linalg.solve(_mass(), np.array([[f, 0.0, 0.0] for f in F_h]).T).T
    np.testing.assert_allclose(_dacc(eff, X, U), want, rtol=1e-9, atol=1e-12)
    # elastic axis behind the quarter chord (a = −0.3): the lift change also pitches,
    # F_α = −b(a + 1/2)·F_h
    base = F.with_params(a=-0.3)
    eff = ie.stall_saturation(base, a_s)
    d = (_rhs(eff, X[:4], U) - _rhs(base, X[:4], U))[:, [1, 3, 5]]
    M = np.asarray(flutter_matrices(U, base.param_tree())[0])
    Fg = np.array([[f, -P["b"] * 0.2 * f, 0.0] for f in F_h[:4]])
    np.testing.assert_allclose(d, np.linalg.solve(M, Fg.T).T, rtol=1e-9, atol=1e-12)


def test_perturbed_parameters_change_the_stiffness_by_the_amount_asked():
    pert = ie.perturb_params(F, {"k_h": 0.03, "c0": -0.05})
    assert pert.params["k_h"] == pytest.approx(1.03 * P["k_h"], rel=1e-15)
    assert pert.params["c0"] == pytest.approx(0.95 * P["c0"], rel=1e-15)
    assert {k: v for k, v in pert.params.items() if k not in ("k_h", "c0")} == \
        {k: v for k, v in P.items() if k not in ("k_h", "c0")}
    X = np.zeros((2, 6))
    X[:, 0] = [0.02, -0.05]                           # heave displacement only
    want = np.linalg.solve(_mass(), np.array([[-0.03 * P["k_h"] * h, 0, 0] for h in X[:, 0]]).T).T
    np.testing.assert_allclose(_dacc(pert, X, 16.0), want, rtol=1e-9)
    with pytest.raises(SimulationError, match="perturb.*k_x"):
        ie.perturb_params(F, {"k_x": 0.1})


def test_linearisation_changes_only_for_freeplay_and_friction():
    """Stall and cubic stiffness are O(|x|³) at rest: same Jacobian, same Hopf point.

    Freeplay cuts the pitch spring inside the gap (Jacobian + M⁻¹e_α k_α), friction is
    a damper of rate F_s/v_r at zero velocity (Jacobian − M⁻¹e_h F_s/v_r in ḣ): both
    move the linear Hopf point however small they are.
    """
    x0, U = np.zeros(6), 16.0
    J0 = jacobian(F, x0, U)
    Minv = np.linalg.inv(_mass())
    for eff in (ie.stall_saturation(F, 0.15), ie.pitch_cubic_stiffness(F, 300.0)):
        assert np.array_equal(jacobian(eff, x0, U), J0)
        assert find_hopf(eff).mu == pytest.approx(HOPF, abs=1e-8)
    dJ = jacobian(ie.pitch_freeplay(F, 0.002), x0, U) - J0
    want = np.zeros((6, 6))
    want[[1, 3, 5], 2] = Minv[:, 1] * P["k_alpha"]
    np.testing.assert_allclose(dJ, want, rtol=1e-9, atol=1e-9)
    fric = ie.stribeck_friction(F, 0.2, coordinate="h")       # F_s 0.3 N, v_r 0.005 m/s
    dJ = jacobian(fric, x0, U) - J0
    want = np.zeros((6, 6))
    want[[1, 3, 5], 1] = -Minv[:, 0] * 0.3 / 0.005
    np.testing.assert_allclose(dJ, want, rtol=1e-9, atol=1e-9)
    # past the nominal Hopf point the nominal equilibrium is unstable, the one with friction not
    assert np.max(eigenvalues(F, 18.6).real) > 0
    assert np.max(eigenvalues(fric, 18.6).real) < 0


# ------------------------------------------------------------------ orbits (compiled once)

MU = 16.5
#: Effects at moderate size and the stable-LCO change they must give at U = 16.5
#: (sign and a lower bound well above the solver's error; benchmarks/independent_effects.md).
ORBIT_CASES = {
    "freeplay": (lambda: ie.pitch_freeplay(F, 0.002), +1),
    "heave friction": (lambda: ie.stribeck_friction(F, 0.5, coordinate="h"), -1),
    "stall": (lambda: ie.stall_saturation(F, 0.15), -1),
    "cubic": (lambda: ie.pitch_cubic_stiffness(F, 300.0), -1),
}


@pytest.fixture(scope="module")
def nominal():
    """The nominal stable LCO at U = 16.5, settled from a pitch of 0.08 rad (outside the
    unstable LCO, 0.038 rad half-amplitude: the subcritical system goes to the stable one)."""
    return ie.stable_orbit(F, MU, np.array([0.0, 0.0, 0.08, 0.0, 0.0, 0.0]), 0.414)


@pytest.mark.parametrize("name", list(ORBIT_CASES))
def test_stable_lco_changes_and_can_be_recorded(nominal, name):
    build, sign = ORBIT_CASES[name]
    eff = build()
    orbit = ie.stable_orbit(eff, MU, nominal.x0, nominal.period)
    assert orbit.stable
    change = {c: orbit.amplitude[c] / nominal.amplitude[c] - 1 for c in F.observed}
    assert all(sign * v > 0.02 for v in change.values()), change
    rs = ie.blind_recordings(eff, F.name, ie.OrbitSet(eff, {(MU, "stable"): orbit}), [MU],
                             ["stable"], duration_s=4.0, noise=0.01, seed=3)
    (rec,) = rs.recordings
    assert "ie_" not in rec.source and rs.extra["simulated"] == F.name
    # the recording is the orbit: RMS about the mean within 1% (noise adds 0.005%, the
    # 9.7 periods' truncation less than 1%); the nominal orbit's differs by > 2%
    i = {c: F.state_names.index(c) for c in F.observed}
    for c in F.observed:
        rms = np.std(rec.channels[c])
        assert rms == pytest.approx(np.std(orbit.states[:, i[c]]), rel=0.01)
    assert any(abs(np.std(rec.channels[c]) / np.std(nominal.states[:, i[c]]) - 1) > 0.02
               for c in F.observed)
