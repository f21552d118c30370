"""Evidence of the missing-physics models: the linearisation's charge, signs, duplicate terms.

Default run: the charge of :func:`bayeshopf.discrepancy.problem.polish` and
:func:`~bayeshopf.discrepancy.problem.charge` on residuals written here by
hand (a linear one, a curved one, one that loses its orbit at the linear
model's mode), against the charge worked out from its definition; the
half-normal prior of the dissipative terms (normalised by quadrature, its
evidence against an exact integral); a planted negative damping fitted;
the library's terms that are calibrated parameters (flutter3dof's pitch
stiffnesses, a Van der Pol copy with a cubic spring of its own). Slow: the
reliability study's set 1019 (k_h −3.5%, nothing else) analysed in full, its
refined terms' evidence nested on the parameters-only model (Savage–Dickey).
"""

from __future__ import annotations

from types import SimpleNamespace

import jax
import numpy as np
import pytest
from scipy import integrate, stats

jax.config.update("jax_enable_x64", True)

from bayeshopf.discrepancy.problem import BARRIER, charge, polish  # noqa: E402
from bayeshopf.discrepancy.terms import DISSIPATIVE, KINDS, library  # noqa: E402
from bayeshopf.simulators import (  # noqa: E402
    FLUTTER3DOF,
    VANDERPOL,
    UncertainParameter,
    simulate_recordings,
)

# ------------------------------------------------------------- the linearisation's charge


class _HandProblem:
    """One unknown x with a standard normal prior; data residuals written by hand.

    ``e(x)`` (a function of the scalar x returning the R×P residuals, or ``None``
    where the orbit is lost: every feature at BARRIER) and its derivative ``de``.
    What :func:`polish` reads of a Problem and its Fitter: ``solve``,
    ``jacobian``, the shapes, σ(τ) (1: no model error) and no offset columns.
    """

    def __init__(self, e, de, R=2, P=3):
        self.e, self.de, self.R, self.P = e, de, R, P
        self.terms, self.n, self.d = (), 1, 1
        ones = np.ones((R, P))
        self.fitter = SimpleNamespace(mf=SimpleNamespace(y=np.zeros((R, P))), mean_cols=[],
                                      sigma=ones, sigma_at=lambda tau: ones * np.ones_like(tau))
        self.solved = []

    def solve(self, x):
        x = float(np.asarray(x).ravel()[0])
        self.solved.append(x)
        e = self.e(x)
        ok = np.full(self.R, e is not None)
        e = np.full((self.R, self.P), BARRIER) if e is None else np.asarray(e, float)
        return SimpleNamespace(ok=ok), np.concatenate([e.ravel(), [x]])

    def jacobian(self, x):
        x = float(np.asarray(x).ravel()[0])
        return np.concatenate([np.asarray(self.de(x), float).ravel(), [1.0]])[:, None]


A0 = np.array([[1.0, -2.0, 0.5], [3.0, 0.25, -1.5]])      # e(0)
J0 = -0.5 * A0 + np.array([[0.1, -0.2, 0.05], [0.0, 0.15, -0.1]])   # de/dx: a step ≈ 1.7


def _polish_at_zero(prob):
    ob, E = prob.solve(np.zeros(1))
    return polish(prob, np.zeros(1), ob, E, prob.jacobian(np.zeros(1)), 0.01)


def test_a_step_that_loses_the_orbit_is_charged_at_most_the_linear_credit():
    # linear near 0, the orbit lost beyond |x| > 0.1; the linear model's mode is further out
    prob = _HandProblem(lambda x: A0 + J0 * x if abs(x) < 0.1 else None, lambda x: J0)
    a, j = A0.ravel(), J0.ravel()
    delta = -(j @ a) / (j @ j + 1.0)                       # mode of ‖a + j x‖² + x²
    assert abs(delta) > 0.1                                # so the re-shot step is lost
    chi2_x = a @ a                                         # at x = 0 (prior row 0)
    chi2_lin = float(np.sum((a + j * delta) ** 2) + delta**2)
    # the trial point's misfit is ~1e10·features: without a cap the charge would be that
    x, _, _, _, pen = _polish_at_zero(prob)
    assert x[0] == 0.0                                     # the lost step is not taken
    assert pen == pytest.approx(0.5 * (chi2_x - chi2_lin), rel=1e-12)
    assert prob.solved[-1] == pytest.approx(delta, rel=1e-12)   # the step was re-shot


def test_the_model_error_is_inferred_from_what_the_model_achieves_not_what_it_promises():
    # the residuals cannot move (e(x) = A0 at every x) but the linearisation claims they
    # can (de = J0): at each model error τ the charged evidence is the Laplace evidence about
    # x as it stands, so τ's posterior is that of the misfit at x, not of the promise
    from bayeshopf.discrepancy.evidence import TAU, _model_error, laplace_evidence
    from bayeshopf.discrepancy.fitting import _charged

    prob = _HandProblem(lambda x: A0, lambda x: J0)
    ref = np.full((prob.R, prob.P), 30.0)
    prob.fitter.sigma_at = lambda tau: np.sqrt(1.0 + (tau * ref) ** 2)

    def evidence(x, E, G, ok, penalty):
        return _model_error(prob.fitter, E, G, ok, lambda Es, Gs: laplace_evidence(Es, Gs)[0],
                            penalty)[0]

    ob, E = prob.solve(np.zeros(1))
    G = prob.jacobian(np.zeros(1))
    promised = evidence(np.zeros(1), E, G, ob.ok, None)
    _, _, _, _, charged, pen = _charged(prob, np.zeros(1), ob, E, G, evidence, refined=False)
    as_it_stands = _model_error(
        prob.fitter, E, G, ob.ok,
        lambda Es, Gs: np.array([-0.5 * float(Et @ Et) - 0.5 * np.linalg.slogdet(Gt.T @ Gt)[1]
                                 for Et, Gt in zip(Es, Gs, strict=True)]))[0]
    assert charged.median == pytest.approx(as_it_stands.median, rel=1e-9)
    assert charged.log_z == pytest.approx(as_it_stands.log_z, rel=1e-9)
    assert promised.median < 0.5 * charged.median          # the promise asked for less error
    assert pen == pytest.approx(promised.log_z - charged.log_z, rel=1e-12) and pen > 0
    assert TAU[0] < charged.median < TAU[-1]


def test_a_linear_residual_is_charged_nothing():
    prob = _HandProblem(lambda x: A0 + J0 * x, lambda x: J0)
    ob, E = prob.solve(np.zeros(1))
    c = charge(prob, np.zeros(1), ob, E, prob.jacobian(np.zeros(1)), 0.01)
    assert c.nats == pytest.approx(0.0, abs=1e-12)
    assert c.shot == pytest.approx(c.linear, rel=1e-12)


def test_a_curved_residual_is_charged_what_the_linear_model_overpromised():
    # e(x) = a + j x + k x²: re-shot at the linear mode, worse than promised, better than x
    k = 0.1 * A0
    prob = _HandProblem(lambda x: A0 + J0 * x + k * x**2, lambda x: J0 + 2 * k * x)
    a, j, kk = A0.ravel(), J0.ravel(), k.ravel()

    def chi2(x):
        return float(np.sum((a + j * x + kk * x**2) ** 2) + x**2)

    delta = -(j @ a) / (j @ j + 1.0)
    lin = float(np.sum((a + j * delta) ** 2) + delta**2)
    assert lin < chi2(delta) < chi2(0.0)                   # the case this test is about
    ob, E = prob.solve(np.zeros(1))
    c = charge(prob, np.zeros(1), ob, E, prob.jacobian(np.zeros(1)), 0.01)
    assert c.nats == pytest.approx(0.5 * (chi2(delta) - lin), rel=1e-10)
    # polish takes that step (it lowers the misfit) and charges the next linearisation there
    x, _, _, _, pen = _polish_at_zero(prob)
    x1 = delta
    j1 = j + 2 * kk * x1
    e1 = a + j * x1 + kk * x1**2
    d1 = -(j1 @ e1 + x1) / (j1 @ j1 + 1.0)
    lin1 = float(np.sum((e1 + j1 * d1) ** 2) + (x1 + d1) ** 2)
    assert x[0] == pytest.approx(x1, rel=1e-12)
    assert pen == pytest.approx(0.5 * max(0.0, min(chi2(x1 + d1), chi2(x1)) - lin1),
                                rel=1e-8, abs=1e-12)


# ---------------------------------------------------------------- dissipative terms


def test_dissipative_terms_have_a_normalised_half_normal_prior():
    lib = library(FLUTTER3DOF, {"h": 0.02, "alpha": 0.06}, 2.4)
    for t in lib.terms:
        assert t.positive == (t.kind in DISSIPATIVE or t.kind == "freeplay"), t.name
        lo = 0.0 if t.positive else -np.inf
        s = t.scale                                    # c = s u, integrated in u
        mass, _ = integrate.quad(lambda u, t=t, s=s: s * np.exp(t.log_prior(s * u)),
                                 max(lo, -40.0), 40.0, epsabs=0, epsrel=1e-10)
        assert mass == pytest.approx(1.0, rel=1e-8), t.name
        if t.positive:
            assert t.log_prior(-1e-3 * t.scale) == -np.inf
            assert t.log_prior(0.3 * t.scale) == pytest.approx(
                np.log(2) + stats.norm.logpdf(0.3 * t.scale, 0, t.scale), rel=1e-12)
    assert set(DISSIPATIVE) < set(KINDS)
    assert {t.kind for t in lib.terms if t.positive} == {*DISSIPATIVE, "freeplay"}


def test_pair_evidence_with_one_half_normal_coefficient_is_the_exact_integral():
    # y = A z + g1 ζ1 + g2 ζ2 + ε; ζ2 ≥ 0 half-normal (a damping), the rest standard normal
    from bayeshopf.discrepancy.evidence import _gauss_evidence

    rng = np.random.default_rng(4)
    n, d = 25, 3
    A, g1, g2 = rng.normal(size=(n, d)), rng.normal(size=n), rng.normal(size=n)
    y = A @ rng.normal(size=d) + 0.7 * g1 + 0.1 * g2 + rng.normal(size=n)
    M = np.column_stack([A, g1, g2])
    E = np.concatenate([y, np.zeros(d + 2)])
    G = np.vstack([-M, np.eye(d + 2)])
    S = A @ A.T + np.outer(g1, g1) + np.eye(n)             # y | ζ2 ~ N(g2 ζ2, S)
    like = stats.multivariate_normal(np.zeros(n), S)
    shift = like.logpdf(y)

    def f(z2):
        return 2 * stats.norm.pdf(z2) * np.exp(like.logpdf(y - g2 * z2) - shift)

    val, _ = integrate.quad(f, 0.0, 40.0, epsabs=0, epsrel=1e-12, limit=200)
    exact = np.log(val) + shift
    ours = _gauss_evidence(E, G, np.zeros(d + 2), [d + 1]) - 0.5 * n * np.log(2 * np.pi)
    assert ours == pytest.approx(exact, abs=1e-8)
    # and not the full normal's: the bound matters by more than the tolerance
    assert abs(_gauss_evidence(E, G, np.zeros(d + 2), []) - 0.5 * n * np.log(2 * np.pi)
               - exact) > 0.05


def test_a_planted_negative_damping_is_not_named_as_a_negative_coefficient():
    # Van der Pol with a cubic damping of negative coefficient (energy fed in at large
    # amplitude, a larger cycle): the damping term may only shrink towards 0
    from bayeshopf.discrepancy import simulate_with_effect
    from bayeshopf.discrepancy.prepare import prepare

    c_true = -0.05
    mus, brs = [0.3, 0.6, 0.9], ["stable"] * 3
    rs, _ = simulate_with_effect(VANDERPOL, "z1_cubic_damping", c_true, mus, brs,
                                 duration_s=60.0, noise=0.01, seed=2)
    fitter, _, _ = prepare(rs, VANDERPOL)
    term = fitter.lib["z1_cubic_damping"]
    assert term.positive
    fit = fitter.fit(term)
    assert fit.mode >= 0.0 and fit.ci90[0] >= 0.0 and np.all(fit.grid >= 0.0), fit
    # the data ask for c < 0: the half-normal posterior sits against the bound, far below
    # the truth's magnitude
    assert fit.median < 0.2 * abs(c_true), fit


# ------------------------------------------------------------ terms that are parameters


def test_terms_that_are_calibrated_parameters_are_left_out():
    amp = {"h": 0.02, "alpha": 0.06}
    lib = library(FLUTTER3DOF, amp, 2.4,
                  parameters=[u.name for u in FLUTTER3DOF.uncertain])
    assert set(lib.skipped) == {"alpha_quadratic_stiffness", "alpha_cubic_stiffness"}
    assert lib.skipped["alpha_cubic_stiffness"].startswith(
        "the same force as parameter k_alpha3")
    assert lib.skipped["alpha_quadratic_stiffness"].startswith(
        "the same force as parameter k_alpha2")
    assert {"h_quadratic_stiffness", "h_cubic_stiffness", "alpha_quintic_stiffness",
            "alpha_cubic_damping"} <= set(lib.names)
    assert {(t.name, par) for t, par in lib.duplicates} == {
        ("alpha_quadratic_stiffness", "k_alpha2"), ("alpha_cubic_stiffness", "k_alpha3")}
    # the verdict names k_alpha3 off with the term it equals
    from bayeshopf.discrepancy.records import ParameterPosterior
    from bayeshopf.discrepancy.verdict import _pct

    k3 = FLUTTER3DOF.params["k_alpha3"]
    p = ParameterPosterior("k_alpha3", "N m/rad^3", "lognormal", 0.2, k3, 0.92 * k3,
                           (0.91 * k3, 0.93 * k3), z=-0.4, z_sd=0.01)
    assert _pct(p, lib).endswith("; equivalently: cubic stiffness in pitch)"), _pct(p, lib)
    assert "equivalently" not in _pct(p, library(FLUTTER3DOF, amp, 2.4))
    # not calibrated (or not declared uncertain): the terms stay
    assert len(library(FLUTTER3DOF, amp, 2.4).terms) == 2 * len(KINDS)
    other = [u.name for u in FLUTTER3DOF.uncertain if u.name not in ("k_alpha2", "k_alpha3")]
    assert library(FLUTTER3DOF, amp, 2.4, parameters=other).skipped == {}


def _vdp_with_spring(rhs_extra):
    """Van der Pol with a parameter k3 in ``ż2 += rhs_extra(z1, z2, k3)``, declared uncertain."""
    def rhs(x, mu, p):
        base = VANDERPOL.rhs(x, mu, p)
        return base.at[1].add(rhs_extra(x[0], x[1], p["k3"]))

    return VANDERPOL.replace(
        name="vanderpol_k3", rhs=rhs, params={**VANDERPOL.params, "k3": 0.4},
        param_units={**VANDERPOL.param_units, "k3": ""},
        uncertain=(UncertainParameter("c"), UncertainParameter("omega"),
                   UncertainParameter("k3")))


def test_the_test_is_numerical_not_by_name():
    amp = {"z1": 1.5}
    # no parameter multiplies z1³ (c multiplies z1² ż1, omega² z1): nothing is left out
    vdp = VANDERPOL.replace(uncertain=(UncertainParameter("c"), UncertainParameter("omega")))
    lib = library(vdp, amp, 0.16, parameters=["c", "omega"])
    assert not any("same force" in r for r in lib.skipped.values()), lib.skipped
    assert "z1_cubic_stiffness" in lib.names
    # a spring −(k3/3)·z1³ written with a factor: the cubic stiffness is that parameter
    sys3 = _vdp_with_spring(lambda z1, z2, k3: -(k3 / 3.0) * z1**3)
    lib = library(sys3, amp, 0.16, parameters=["c", "omega", "k3"])
    assert lib.skipped.get("z1_cubic_stiffness", "").startswith(
        "the same force as parameter k3"), lib.skipped
    assert "z1_quadratic_stiffness" in lib.names and "z1_quintic_stiffness" in lib.names
    # k3 also in a velocity-dependent force: no longer the same force as any term
    sys4 = _vdp_with_spring(lambda z1, z2, k3: -k3 * (z1**3 + 0.1 * z1**2 * z2))
    lib = library(sys4, amp, 0.16, parameters=["c", "omega", "k3"])
    assert "z1_cubic_stiffness" in lib.names, lib.skipped


# ------------------------------------------------------------------- set 1019 (slow)

#: The reliability study's set 1019 (bench_discrepancy_reliability: class "parameters off",
#: its first draw): k_h changed by this relative amount, nothing else.
SET_1019 = {"k_h": -0.034847865580791414}
PLAN_1019 = [(15.5, "stable"), (16.0, "stable"), (16.5, "stable"), (17.0, "stable"),
             (15.5, "unstable"), (16.0, "unstable"), (16.5, "unstable"), (17.0, "unstable")]


@pytest.mark.slow  # a full calibrated analysis of 8 recordings of 10 s (two minutes alone)
def test_set_1019_parameters_only_is_parameters_off():
    from bayeshopf.discrepancy.calibration import calibrate

    truth = FLUTTER3DOF.with_params(**{k: FLUTTER3DOF.params[k] * (1 + r)
                                       for k, r in SET_1019.items()})
    truth = truth.replace(default_plan=tuple(PLAN_1019))
    rs = simulate_recordings(truth, [m for m, _ in PLAN_1019], [b for _, b in PLAN_1019],
                             duration_s=10.0, noise=0.015,
                             offsets={"h": 0.001, "alpha": -0.004}, seed=1019)
    rep = calibrate(rs, FLUTTER3DOF)
    v = rep.verdict
    assert v["kind"] == "parameters off", v
    assert v["terms"] == [], v
    assert "k_h" in v["parameters"], v
    # the calibration fits, and its evidence is not wrecked by the linearisation's charge
    assert rep.log_z["parameters"] > rep.log_z["none"], rep.log_z
    assert "alpha_cubic_stiffness" not in rep.log_z and "alpha_quadratic_stiffness" \
        not in rep.log_z
    # the refined terms sit at 0 within their posterior: their evidence is nested on M_P
    # (Savage–Dickey), and none is favoured over the parameters alone
    sd = [f for f in rep.terms if f.evidence == "savage-dickey vs parameters"]
    assert sd, [(f.term.name, f.evidence) for f in rep.terms]
    assert all(f.log_z < rep.log_z["parameters"] for f in sd), [(f.term.name, f.log_z)
                                                                for f in sd]
    assert v["bayes_factors"]["log_bayes_factor"]["term missing"]["parameters off"] < 0
