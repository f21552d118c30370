"""Exact derivatives of periodic orbits in the simulator's parameters (implicit function theorem).

Reference: central differences of orbits re-solved by Newton's method at each
perturbed parameter value (:func:`bayeshopf.discrepancy.orbits.track`), which
share nothing with the implicit solve but the integrator.
"""

import numpy as np
import pytest

from bayeshopf._x64 import ensure_x64

ensure_x64()

from bayeshopf.discrepancy.orbits import sensitivities, track  # noqa: E402
from bayeshopf.discrepancy.prepare import prepare  # noqa: E402
from bayeshopf.discrepancy.problem import Problem  # noqa: E402
from bayeshopf.simulators import FLUTTER3DOF, simulate_recordings  # noqa: E402


@pytest.fixture(scope="module")
def problem():
    rs = simulate_recordings(FLUTTER3DOF, [16.0, 17.0], ["stable", "unstable"], noise=0.01,
                             duration_s=4.0, sample_rate_hz=250.0, seed=1)
    unc = FLUTTER3DOF.uncertain
    fitter, _, _ = prepare(rs, FLUTTER3DOF, parameters=[u.name for u in unc])
    term = fitter.lib["h_cubic_stiffness"]
    return Problem(fitter, unc, term, [(np.zeros(len(unc) + 1), fitter.base)])


def test_jacobian_matches_central_differences_of_re_solved_orbits(problem):
    x = np.zeros(problem.n)
    x[0], x[4], x[-1] = 0.4, -0.3, 0.5         # k_h, c0 and the term away from nominal
    G = problem.jacobian(x)
    ob, _ = problem.solve(x)
    assert ob.ok.all()
    R, P = problem.fitter.mf.y.shape
    h = 1e-4
    for j in range(problem.n):
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        obp = track(problem.fitter.system, problem.params(x), problem.params(xp), ob,
                    problem.fitter.stable)
        obm = track(problem.fitter.system, problem.params(x), problem.params(xm), ob,
                    problem.fitter.stable)
        ref = (problem._E(xp, obp) - problem._E(xm, obm))[: R * P] / (2 * h)
        scale = np.max(np.abs(ref))
        assert scale > 1.0                       # every unknown moves the features
        np.testing.assert_allclose(G[: R * P, j], ref, atol=1e-3 * scale,
                                   err_msg=problem._column_params(j))
    np.testing.assert_array_equal(G[R * P:], np.eye(problem.n))


@pytest.fixture
def tight(monkeypatch):
    """The orbits solved and differentiated at tolerances far below the analysis's own, so
    that the central differences of re-solved periods resolve their small derivatives."""
    import bayeshopf.discrepancy.orbits as orbits

    monkeypatch.setattr(orbits, "_RTOL", 1e-10)
    monkeypatch.setattr(orbits, "_ATOL", 1e-13)
    monkeypatch.setattr(orbits, "TOL", 1e-10)
    orbits._flow_jacobian.cache_clear()
    yield
    orbits._flow_jacobian.cache_clear()


def test_periods_derivative_matches_re_solved_orbits(problem, tight):
    x = np.zeros(problem.n)
    ob, _ = problem.solve(x)
    p0 = problem.params(x)
    dS, dT = sensitivities(problem.fitter.system, p0, ob, ["k_alpha", "dc_h_cubic_stiffness"])
    for c, name in enumerate(["k_alpha", "dc_h_cubic_stiffness"]):
        step = 1e-4 * max(abs(p0[name]), 1.0)
        plus = track(problem.fitter.system, p0, {**p0, name: p0[name] + step}, ob,
                     problem.fitter.stable)
        minus = track(problem.fitter.system, p0, {**p0, name: p0[name] - step}, ob,
                      problem.fitter.stable)
        ref = (plus.period - minus.period) / (2 * step)
        np.testing.assert_allclose(dT[:, c], ref, rtol=1e-4, atol=1e-12 * ob.period.max())
    with pytest.raises(KeyError, match="parameters of the system expected"):
        sensitivities(problem.fitter.system, p0, ob, ["no_such_parameter"])


def test_a_tracked_step_starts_from_the_orbits_moved_along_their_derivatives(problem):
    # where a Jacobian was formed, the next point's orbits are guessed to first order: the
    # guess's error falls with the square of the step (the start's with the step), and
    # tracking from it finds the same orbits
    x0 = np.zeros(problem.n)
    problem.jacobian(x0)
    ob0, _ = problem.solve(x0)
    errors = []
    for step in (0.2, 0.1):
        x = x0.copy()
        x[0] = step                                  # k_h
        guess = problem._predict(x0, ob0, x)
        plain = track(problem.fitter.system, problem.params(x0), problem.params(x), ob0,
                      problem.fitter.stable)
        guided = track(problem.fitter.system, problem.params(x0), problem.params(x), ob0,
                       problem.fitter.stable, guess=guess)
        assert plain.ok.all() and guided.ok.all()
        np.testing.assert_allclose(guided.period, plain.period, rtol=1e-6)
        errors.append((np.abs(ob0.period - plain.period), np.abs(guess[1] - plain.period)))
    (start_2, guess_2), (start_1, guess_1) = errors
    assert np.all(guess_1 < 0.1 * start_1)
    np.testing.assert_allclose(start_2 / start_1, 2.0, rtol=0.1)      # first order
    np.testing.assert_allclose(guess_2 / guess_1, 4.0, rtol=0.1)      # second order
    x[-1] = 0.1                                  # the term too: the same orbits found
    guided = track(problem.fitter.system, problem.params(x0), problem.params(x), ob0,
                   problem.fitter.stable, guess=problem._predict(x0, ob0, x))
    plain = track(problem.fitter.system, problem.params(x0), problem.params(x), ob0,
                  problem.fitter.stable)
    np.testing.assert_allclose(guided.period, plain.period, rtol=1e-6)
    # a point that moves an unknown without known derivatives gets no guess
    have = problem.tangents[-1][1][2]
    have[0] = False
    assert problem._predict(x0, ob0, x) is None
    have[0] = True
