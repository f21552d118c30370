"""Simulated systems: Hopf points, continued periodic orbits and recordings, each
checked against an independent reference (scipy's solve_ivp, closed forms, the
values the paper and the authors' code report)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from bayeshopf.cli.main import main
from bayeshopf.data.io import load_recordings
from bayeshopf.simulators import (
    FLUTTER3DOF,
    VANDERPOL,
    SimulationError,
    System,
    bifurcation_diagram,
    eigenvalues,
    get_system,
    orbit_at,
    simulate_recordings,
)
from bayeshopf.simulators.flutter import flutter_matrices


@pytest.fixture(scope="module")
def vdp():
    return bifurcation_diagram(VANDERPOL)


@pytest.fixture(scope="module")
def flutter():
    return bifurcation_diagram(FLUTTER3DOF)


def _vdp_numpy(mu):
    """Paper eq. vdp written again in numpy (independent of the JAX right-hand side)."""
    return lambda t, z: [z[1], 2 * mu * z[1] - z[0] ** 2 * z[1] - z[0]]


def _flutter_numpy(U):
    """q̈ = −M⁻¹(D q̇ + K q + N(α)) in numpy, with M, D, K evaluated once at U."""
    p = FLUTTER3DOF.param_tree()
    M, D, K = (np.asarray(a) for a in flutter_matrices(U, p))
    Minv = np.linalg.inv(M)
    k2, k3 = FLUTTER3DOF.params["k_alpha2"], FLUTTER3DOF.params["k_alpha3"]

    def f(t, x):
        q, qd = x[[0, 2, 4]], x[[1, 3, 5]]
        qdd = -Minv @ (D @ qd + K @ q + np.array([0.0, k2 * q[1] ** 2 + k3 * q[1] ** 3, 0.0]))
        return np.array([qd[0], qdd[0], qd[1], qdd[1], qd[2], qdd[2]])

    return f


def _settle(f, x0, t_burn, t_keep):
    """solve_ivp (DOP853) for ``t_burn``, then a dense solution over the next ``t_keep``."""
    x1 = solve_ivp(f, (0.0, t_burn), x0, method="DOP853", rtol=1e-11, atol=1e-13).y[:, -1]
    return solve_ivp(f, (0.0, t_keep), x1, method="DOP853", rtol=1e-11, atol=1e-13,
                     dense_output=True)


def _upward_crossings(sol, i, t_end):
    t = np.linspace(0.0, t_end, 20001)
    z = sol.sol(t)[i]
    idx = np.nonzero((z[:-1] < 0) & (z[1:] >= 0))[0]
    return np.array([brentq(lambda s: sol.sol(s)[i], t[k], t[k + 1], xtol=1e-13) for k in idx])


# ----------------------------------------------------------------------------- Van der Pol


def test_vanderpol_hopf_and_branch(vdp):
    assert abs(vdp.hopf.mu) < 1e-10
    assert vdp.hopf.omega == pytest.approx(1.0, rel=1e-10)
    assert vdp.criticality == "supercritical"
    assert [b.kind for b in vdp.branches] == ["stable"]
    assert vdp.folds == ()
    with pytest.raises(SimulationError, match="no unstable branch"):
        vdp.branch("unstable")


@pytest.mark.parametrize("mu", [0.2, 0.6, 1.0])
def test_vanderpol_cycle_matches_solve_ivp(vdp, mu):
    orbit = orbit_at(vdp, mu, "stable")
    assert orbit.stable
    # long integration from a point off the cycle: it must settle on the same cycle
    sol = _settle(_vdp_numpy(mu), 1.05 * orbit.x0, 80.0, 3 * orbit.period)
    tc = _upward_crossings(sol, 0, 3 * orbit.period)
    period = np.diff(tc).mean()
    assert period == pytest.approx(orbit.period, rel=1e-7)
    z1 = sol.sol(np.linspace(0.0, 3 * orbit.period, 60001))[0]
    assert np.ptp(z1) == pytest.approx(orbit.amplitude["z1"], rel=1e-6)


def test_parameter_copies_share_one_solver_and_keep_their_own_parameters(vdp):
    """``System.with_params`` copies reuse the traced solver, which takes the parameters
    as arguments: with c = 4 every orbit is the nominal one scaled by 1/√c = 1/2
    (z → z/√c maps Van der Pol's equation with c onto the one with c = 1)."""
    from bayeshopf.simulators.periodic import kernels, periodic_orbit

    scaled = VANDERPOL.with_params(c=4.0)
    assert kernels(scaled) is kernels(VANDERPOL)
    a = orbit_at(vdp, 0.3, "stable")
    b = periodic_orbit(scaled, 0.3, 0.6 * a.x0, 1.02 * a.period)   # Newton from a guess
    assert b.period == pytest.approx(a.period, rel=1e-8)
    # peak-to-peak over the sampled orbit: the samples fall at other phases
    assert b.amplitude["z1"] == pytest.approx(a.amplitude["z1"] / 2, rel=1e-6)


@pytest.mark.parametrize("mu", [0.01, 0.02, 0.03, 0.04, 0.05])
def test_vanderpol_small_mu_closed_form(vdp, mu):
    # z1 = r cos θ, z2 = −r sin θ and averaging over θ turn ż2 = 2μ z2 − z1² z2 − z1 into
    # ṙ = μ r − r³ ⟨sin²θ cos²θ⟩·r⁰ = μ r − r³/8, so r = 2√(2μ) and peak-to-peak 4√(2μ).
    # The first correction is O(μ²) (about 2e-2 μ², 5e-5 at μ = 0.05): rtol 1e-4.
    # Lindstedt's series gives the period 2π (1 + μ²/4 + O(μ⁴)).
    orbit = orbit_at(vdp, mu, "stable")
    assert orbit.amplitude["z1"] == pytest.approx(4.0 * np.sqrt(2.0 * mu), rel=1e-4)
    assert orbit.period == pytest.approx(2 * np.pi * (1 + mu**2 / 4), rel=1e-6)


# ----------------------------------------------------------------------------- shooting kernel


def _nf_rhs(x, mu, p):
    """Hopf normal form r' = μ r − r³, θ' = ω in Cartesian coordinates."""
    g = mu - (x[0] ** 2 + x[1] ** 2)
    return jnp.stack([g * x[0] - p["omega"] * x[1], g * x[1] + p["omega"] * x[0]])


NORMAL_FORM = System(name="normal_form", state_names=("u1", "u2"), state_units=("", ""),
                     parameter="mu", parameter_units="", params={"omega": 2.0}, rhs=_nf_rhs,
                     observed=("u1", "u2"), mu_range=(-0.5, 0.5))


def _nf_flow(x0, t, mu, omega=2.0):
    """The closed-form flow: r(t)² = μ r0² / (r0² + (μ − r0²) e^{−2μt}), θ(t) = θ0 + ωt.

    Written with analytic operations only, so the complex step differentiates it.
    """
    r2 = x0[0] * x0[0] + x0[1] * x0[1]
    scale = np.sqrt(mu / (r2 + (mu - r2) * np.exp(-2 * mu * t)))
    c, s = np.cos(omega * t), np.sin(omega * t)
    return np.array([c * x0[0] - s * x0[1], s * x0[0] + c * x0[1]]) * scale


def _complex_step(f, z, h=1e-30):
    """Jacobian of a real-analytic ``f`` at ``z`` by the complex step (exact to rounding)."""
    z = np.asarray(z, dtype=complex)
    return np.stack([f(z + 1j * h * e).imag / h for e in np.eye(z.size)], axis=-1)


@pytest.mark.parametrize("mu_sensitivity", [True, False])
def test_shooting_kernel_matches_the_closed_form_flow(mu_sensitivity):
    """The one shooting kernel, with and without dφ/dμ, one orbit and a batch, against the
    normal form's closed-form flow and its complex-step derivatives, off the cycle."""
    from bayeshopf.simulators.periodic import kernels, param_tree, split_shot

    # the simulators' tolerances, and the discrepancy's (discrepancy/orbits.py)
    rtol, atol = (1e-10, 1e-12) if mu_sensitivity else (1e-9, 1e-12)
    tol = 100 * rtol            # global error of one period, and of the dense output
    k = kernels(NORMAL_FORM, rtol, atol, max_steps=4096, mu_sensitivity=mu_sensitivity)
    assert k is kernels(NORMAL_FORM, rtol, atol, max_steps=4096, mu_sensitivity=mu_sensitivity)
    x0s, Ts, mus = np.array([[0.4, -0.2], [0.9, 0.3]]), np.array([2.5, 1.7]), np.array([0.3, 0.1])
    p = param_tree(NORMAL_FORM)
    batch = split_shot(np.asarray(k.shoot_batch(jnp.asarray(x0s), jnp.asarray(Ts),
                                                jnp.asarray(mus), p)), 2)
    for i, (x0, T, mu) in enumerate(zip(x0s, Ts, mus, strict=True)):
        one = split_shot(np.asarray(k.shoot(jnp.asarray(x0), T, mu, p)), 2)
        x1 = _nf_flow(x0, T, mu)
        mono = _complex_step(lambda z, T=T, mu=mu: _nf_flow(z, T, mu), x0)
        dmu = _complex_step(lambda m, x0=x0, T=T: _nf_flow(x0, T, m[0]), [mu])[:, 0]
        for s in (one, batch._replace(**{f: getattr(batch, f)[i] for f in batch._fields})):
            assert bool(s.ok)
            np.testing.assert_allclose(s.x1, x1, rtol=0, atol=tol)
            np.testing.assert_allclose(s.monodromy, mono, rtol=0, atol=tol)
            np.testing.assert_allclose(s.f1, np.asarray(_nf_rhs(x1, mu, p)), rtol=0, atol=tol)
            np.testing.assert_allclose(s.dx_dmu, dmu if mu_sensitivity else 0.0, rtol=0,
                                       atol=tol)
        ts = np.arange(8) / 8
        got = np.asarray(k.sample(jnp.asarray(x0), T, mu, p, 8))
        np.testing.assert_allclose(got, np.stack([_nf_flow(x0, t * T, mu) for t in ts]),
                                   rtol=0, atol=tol)


def test_periodic_orbit_of_the_normal_form():
    """Radius √μ, period 2π/ω, Floquet multipliers 1 and e^{−2μ·2π/ω} (the radial one)."""
    from bayeshopf.simulators import periodic_orbit

    mu = 0.3
    orbit = periodic_orbit(NORMAL_FORM, mu, [0.5, 0.1], 3.0)
    assert orbit.period == pytest.approx(np.pi, rel=1e-9)
    # the samples carry the dense output's error: 100 times the solver's rtol (1e-10)
    np.testing.assert_allclose(np.hypot(*orbit.states.T), np.sqrt(mu), rtol=1e-8)
    np.testing.assert_allclose(np.sort(np.abs(orbit.floquet)),
                               [np.exp(-2 * mu * np.pi), 1.0], rtol=1e-8)
    assert orbit.stable


# ----------------------------------------------------------------------------- flutter


def test_flutter_hopf_point(flutter):
    h = flutter.hopf
    assert 18.27 <= h.mu <= 18.28
    assert h.frequency_hz == pytest.approx(2.466, abs=2e-3)
    ev = eigenvalues(FLUTTER3DOF, h.mu)
    assert abs(ev[0].real) < 1e-9 and abs(abs(ev[0].imag) - h.omega) < 1e-9
    assert h.crossing_speed > 0
    # independent check of the linearisation: eigenvalues of the first-order matrix
    # assembled in numpy from M, D, K on each side of the Hopf point
    p = FLUTTER3DOF.param_tree()

    def max_re(U):
        M, D, K = (np.asarray(a) for a in flutter_matrices(U, p))
        A = np.block([[np.zeros((3, 3)), np.eye(3)],
                      [-np.linalg.solve(M, K), -np.linalg.solve(M, D)]])
        return np.linalg.eigvals(A).real.max()

    assert max_re(h.mu - 0.01) < 0 < max_re(h.mu + 0.01)


def test_flutter_fold_and_stability(flutter):
    assert flutter.criticality == "subcritical"
    assert len(flutter.folds) == 1
    assert flutter.folds[0].mu == pytest.approx(14.94, abs=0.05)
    unstable, stable = flutter.branch("unstable"), flutter.branch("stable")
    lo, hi = unstable.mu_span
    assert lo == pytest.approx(flutter.folds[0].mu, abs=1e-9)
    assert hi == pytest.approx(flutter.hopf.mu, abs=1e-3)
    # Floquet: every orbit away from the fold unstable/stable as labelled
    far = np.abs(unstable.mu - lo) > 0.01
    assert not unstable.stable[far].any()
    assert np.all(np.abs(unstable.floquet[far, 0]) > 1.0)
    far = np.abs(stable.mu - lo) > 0.01
    assert stable.stable[far].all()
    # heave peak-to-peak reported from the authors' code (reference notes): 1 %
    assert stable.orbit(15.0).amplitude["h"] == pytest.approx(0.0411, rel=0.01)
    assert stable.orbit(18.0).amplitude["h"] == pytest.approx(0.0682, rel=0.01)


@pytest.mark.parametrize("mu, branch", [(16.5, "unstable"), (17.0, "stable")])
def test_flutter_orbit_closes_under_solve_ivp(flutter, mu, branch):
    orbit = orbit_at(flutter, mu, branch)
    assert orbit.stable == (branch == "stable")
    f = _flutter_numpy(mu)
    sol = solve_ivp(f, (0.0, orbit.period), orbit.x0, method="DOP853", rtol=1e-12, atol=1e-14,
                    t_eval=orbit.t)
    scale = np.abs(orbit.states).max(axis=0)
    end = solve_ivp(f, (0.0, orbit.period), orbit.x0, method="DOP853", rtol=1e-12,
                    atol=1e-14).y[:, -1]
    assert np.all(np.abs(end - orbit.x0) < 1e-7 * scale)
    assert np.all(np.abs(sol.y.T - orbit.states) < 1e-7 * scale)


@pytest.mark.parametrize("mu, branch", [(16.3, "unstable"), (17.7, "stable")])
def test_branch_guess_is_near_the_orbit_newton_finds_there(flutter, mu, branch):
    # the start the discrepancy analysis solves its batch of orbits from
    b = flutter.branch(branch)
    x0, period, ptp = b.guess(mu)
    orbit = b.orbit(mu)
    scale = np.abs(orbit.states).max(axis=0)
    # interpolated between continuation points (the nearest point alone is off by more)
    assert np.all(np.abs(x0 - orbit.x0) < 2e-3 * scale)
    assert period == pytest.approx(orbit.period, rel=1e-5)
    assert ptp == pytest.approx(orbit.amplitude["h"], rel=5e-4)
    # at a continuation point, that point itself
    i = len(b.mu) // 2
    x_i, T_i, _ = b.guess(b.mu[i])
    assert np.array_equal(x_i, b.x0[i]) and T_i == b.period[i]
    with pytest.raises(SimulationError, match=r"no LCO at U = 19 m/s; it exists for 14\.9"):
        flutter.branch("unstable").guess(19.0)


def test_orbit_outside_branch_is_one_line_error(flutter):
    with pytest.raises(SimulationError, match=r"no LCO at U = 19 m/s; it exists for 14\.9"):
        orbit_at(flutter, 19.0, "unstable")


# ----------------------------------------------------------------------------- systems


def test_registry():
    assert get_system("flutter3dof") is FLUTTER3DOF
    assert get_system("bayeshopf.simulators.vanderpol:VANDERPOL") is VANDERPOL
    for bad, msg in [("nosuch", "unknown system 'nosuch'"),
                     ("nosuch_pkg.mod:x", "cannot be imported"),
                     ("bayeshopf.simulators.vanderpol:NOPE", "has no attribute"),
                     ("bayeshopf.simulators.vanderpol:vanderpol_rhs", "takes arguments")]:
        with pytest.raises(SimulationError, match=msg):
            get_system(bad)


USER_MODULE = """
import jax.numpy as jnp
from bayeshopf.simulators import System

def rhs(x, mu, p):
    # Cartesian Hopf normal form: r' = (mu + a r^2 - r^4) r, theta' = omega
    g = mu + p["a"] * (x[0] ** 2 + x[1] ** 2) - (x[0] ** 2 + x[1] ** 2) ** 2
    return jnp.stack([g * x[0] - p["omega"] * x[1], g * x[1] + p["omega"] * x[0]])

def make():
    return System(name="user_nf", state_names=("u1", "u2"), state_units=("mm", "mm"),
                  parameter="mu", parameter_units="", params={"a": 1.0, "omega": 3.0},
                  rhs=rhs, observed=("u1", "u2"), mu_range=(-0.5, 0.3))
"""


def test_user_system_from_module_matches_closed_form(tmp_path, monkeypatch):
    # r^2 = (a ± sqrt(a^2 + 4 mu)) / 2, fold at mu = -a^2/4, period 2 pi / omega
    (tmp_path / "my_nf_system.py").write_text(USER_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    system = get_system("my_nf_system:make")
    d = bifurcation_diagram(system)
    assert abs(d.hopf.mu) < 1e-10 and d.hopf.omega == pytest.approx(3.0)
    assert d.criticality == "subcritical"
    assert [b.kind for b in d.branches] == ["unstable", "stable"]
    assert d.folds[0].mu == pytest.approx(-0.25, abs=1e-8)
    for mu, sign, kind in [(-0.2, -1, "unstable"), (-0.1, -1, "unstable"), (-0.2, 1, "stable"),
                           (0.2, 1, "stable")]:
        orbit = d.orbit_at(mu, kind)
        r = np.sqrt((1 + sign * np.sqrt(1 + 4 * mu)) / 2)
        assert orbit.amplitude["u1"] == pytest.approx(2 * r, rel=1e-8)
        assert orbit.period == pytest.approx(2 * np.pi / 3, rel=1e-9)
        assert orbit.stable == (kind == "stable")


def test_extra_force_enters_through_inverse_mass():
    k3 = 1000.0
    stiffer = FLUTTER3DOF.with_extra_force(
        lambda x, U, p: jnp.stack([0.0 * x[2], -p["k_extra"] * x[2] ** 3, 0.0 * x[2]]),
        name="flutter_cubic", params={"k_extra": k3}, param_units={"k_extra": "N m/rad^3"})
    x = jnp.array([0.01, 0.1, 0.05, 0.2, 0.003, 0.01])
    p0, p1 = FLUTTER3DOF.param_tree(), stiffer.param_tree()
    d = np.asarray(stiffer.rhs(x, 16.0, p1) - FLUTTER3DOF.rhs(x, 16.0, p0))
    M = np.asarray(flutter_matrices(16.0, p0)[0])
    acc = np.linalg.solve(M, [0.0, -k3 * 0.05**3, 0.0])
    np.testing.assert_allclose(d[[1, 3, 5]], acc, rtol=1e-12, atol=1e-15)
    assert np.all(d[[0, 2, 4]] == 0)
    with pytest.raises(SimulationError, match="unknown parameter"):
        FLUTTER3DOF.with_params(nope=1.0)


# ----------------------------------------------------------------------------- recordings


def test_recordings_noise_offsets_and_phase(flutter):
    kw = dict(mu=[16.0, 16.0], branch=["stable", "unstable"], duration_s=4.0,
              sample_rate_hz=400.0, seed=3, diagram=flutter)
    clean = simulate_recordings(FLUTTER3DOF, noise=0.0, **kw)
    noisy = simulate_recordings(FLUTTER3DOF, noise=0.05, offsets={"h": 0.002}, **kw)
    assert clean.planar == ("h", "alpha") and clean.mu_units == "m/s"
    for c, n in zip(clean, noisy, strict=True):
        assert set(c.channels) == {"h", "alpha"}
        orbit = flutter.orbit_at(c.mu, c.branch)
        # the clean signal is the continued orbit: its peak-to-peak and period
        assert np.ptp(c.channel("h")) == pytest.approx(orbit.amplitude["h"], rel=2e-3)
        lag = int(round(orbit.period * 400.0 * 5))
        t_shift = lag / 400.0 - 5 * orbit.period
        slope = np.gradient(c.channel("h"), c.t)
        resid = c.channel("h")[lag:] - c.channel("h")[:-lag] - slope[:-lag] * t_shift
        assert np.abs(resid).max() < 0.02 * orbit.amplitude["h"]
        # noise: relative RMS 5 % of the centred signal, offsets added as given
        for ch, off in (("h", 0.002), ("alpha", 0.0)):
            e = n.channel(ch) - c.channel(ch) - off
            assert abs(e.mean()) < 0.01 * np.std(c.channel(ch))
            assert np.std(e) == pytest.approx(0.05 * np.std(c.channel(ch)), rel=0.1)
    # a random phase per recording: two recordings of one orbit start at different points
    twice = simulate_recordings(FLUTTER3DOF, [16.0, 16.0], "stable", noise=0.0, duration_s=1.0,
                                sample_rate_hz=400.0, seed=3, diagram=flutter)
    a, b = (r.channel("h") for r in twice)
    assert np.ptp(a) == pytest.approx(np.ptp(b), rel=1e-3)
    assert np.abs(a - b).max() > 0.1 * np.ptp(a)
    assert twice.names == ["stable_U16", "stable_U16_2"]


def test_recordings_bad_input(flutter):
    with pytest.raises(SimulationError, match="one branch per mu"):
        simulate_recordings(FLUTTER3DOF, [15.5, 16.0], ["stable"] * 3, diagram=flutter)
    with pytest.raises(SimulationError, match="no LCO at U = 14"):
        simulate_recordings(FLUTTER3DOF, [14.0], "stable", diagram=flutter)
    with pytest.raises(SimulationError, match="offset for 'w'"):
        simulate_recordings(FLUTTER3DOF, [16.0], offsets={"w": 1.0}, diagram=flutter)


# ----------------------------------------------------------------------------- CLI


def _digest(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def test_cli_simulate_writes_readable_folder(tmp_path, flutter, capsys):
    args = ["simulate", "flutter3dof", "--mu", "15.5", "16.5", "--branch", "stable", "unstable",
            "--duration", "2", "--rate", "200", "--offset", "h=0.001", "--seed", "7"]
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    assert "fold of LCOs at U = 14.9" in capsys.readouterr().out
    rs = load_recordings(tmp_path / "a")
    assert len(rs) == 2 and rs.planar == ("h", "alpha")
    assert list(rs.mus) == [15.5, 16.5] and list(rs.is_unstable) == [False, True]
    assert all(set(r.channels) == {"h", "alpha"} for r in rs)
    assert rs[0].units["h"] == "m" and rs[0].units["alpha"] == "rad"
    assert rs[0].t.size == 400
    assert (tmp_path / "a" / "simulation.json").is_file()
    # same seed -> identical files; another seed -> different recordings
    assert main([*args, "--out", str(tmp_path / "b")]) == 0
    assert _digest(tmp_path / "a") == _digest(tmp_path / "b")
    args[-1] = "8"
    assert main([*args, "--out", str(tmp_path / "c")]) == 0
    assert _digest(tmp_path / "a")["stable_U15_5.csv"] != _digest(tmp_path / "c")[
        "stable_U15_5.csv"]
    # non-empty output folder: refused without --force, replaced with it
    capsys.readouterr()
    assert main([*args, "--out", str(tmp_path / "a")]) == 2
    assert "not empty" in capsys.readouterr().err
    assert main([*args, "--out", str(tmp_path / "a"), "--force"]) == 0
    assert _digest(tmp_path / "a") == _digest(tmp_path / "c")


def test_cli_simulate_vanderpol_default_plan(tmp_path, vdp):
    assert main(["simulate", "vanderpol", "--out", str(tmp_path / "v"), "--duration", "20",
                 "--rate", "20"]) == 0
    rs = load_recordings(tmp_path / "v")
    assert len(rs) == 6 and not rs.is_unstable.any()
    assert rs.mus.min() > 0 and rs.mus.max() <= 1
    assert set(rs[0].channels) == {"z1", "z2"}


@pytest.mark.parametrize("argv, words", [
    (["nosuch"], "unknown system 'nosuch'"),
    (["flutter3dof", "--mu", "19", "--branch", "unstable"], "no LCO at U = 19"),
    (["flutter3dof", "--mu", "15.5", "16", "--branch", "stable", "unstable", "stable"],
     "one branch per mu"),
    (["vanderpol", "--mu", "0.5", "--branch", "unstable"], "no unstable branch"),
    (["flutter3dof", "--mu", "16", "--branch", "sideways"], "'stable' or 'unstable'"),
    (["flutter3dof", "--mu", "16", "--offset", "h:1"], "CHANNEL=VALUE"),
])
def test_cli_simulate_bad_input_one_line(tmp_path, capsys, argv, words, flutter, vdp):
    out = tmp_path / "out"
    assert main(["simulate", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err and "Traceback" not in err
    assert not out.exists()
