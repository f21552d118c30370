"""Newton's method for periodic orbits: a converging solve finishes, a hopeless one stops early.

Reference: the nominal continuation of flutter3dof (its orbits and its fold,
found by arclength continuation, which shares nothing with the batched Newton
solver but the integrator).
"""

import numpy as np
import pytest

from bayeshopf._x64 import ensure_x64

ensure_x64()

from bayeshopf.discrepancy import orbits  # noqa: E402
from bayeshopf.simulators import FLUTTER3DOF  # noqa: E402
from bayeshopf.simulators.continuation import bifurcation_diagram  # noqa: E402


@pytest.fixture(scope="module")
def diagram():
    return bifurcation_diagram(FLUTTER3DOF)


@pytest.fixture
def shots(monkeypatch):
    """The batched shots of every solve: the number of orbits each shoots."""
    count = []
    batched_call = orbits._batched_call

    def counting(system, name, arrays, *a):
        if name == "shoot":
            count.append(len(arrays[0]))
        return batched_call(system, name, arrays, *a)
    monkeypatch.setattr(orbits, "_batched_call", counting)
    return count


def _start(diagram, mus, branch):
    orbs = [diagram.orbit_at(m, branch) for m in mus]
    return (np.stack([np.asarray(o.x0) for o in orbs]), np.array([o.period for o in orbs]),
            np.array([o.mu for o in orbs]))


def test_orbits_at_a_new_airspeed_are_found_where_continuation_has_them(diagram, shots):
    x0, T, _ = _start(diagram, [15.6, 16.4], "unstable")
    mu = np.array([15.8, 16.6])
    ob = orbits.solve_orbits(FLUTTER3DOF, FLUTTER3DOF.params, x0, T, mu, [False, False])
    assert ob.ok.all()
    for i, m in enumerate(mu):
        ref = diagram.orbit_at(float(m), "unstable")
        np.testing.assert_allclose(ob.period[i], ref.period, rtol=1e-7)
        # the same closed curve: the continuation's start point lies on the solved orbit
        gap = np.min(np.linalg.norm(ob.states[i] - np.asarray(ref.x0), axis=1))
        assert gap < 0.1 * np.max(np.abs(ob.states[i]))
    assert len(shots) < 20


def test_an_orbit_beyond_the_fold_is_lost_without_iterating_to_the_limit(diagram, shots):
    fold = min(f.mu for f in diagram.folds)
    x0, T, _ = _start(diagram, [fold + 0.3, 16.0], "unstable")
    mu = np.array([fold - 1.0, 16.0])          # no unstable orbit below the fold
    ob = orbits.solve_orbits(FLUTTER3DOF, FLUTTER3DOF.params, x0, T, mu, [False, False],
                             max_iter=40)
    assert ob.ok.tolist() == [False, True]
    assert np.isnan(ob.states[0]).all() and np.isfinite(ob.states[1]).all()
    # Newton's steps stopped shrinking: stopped long before max_iter shots
    assert len(shots) <= 15


def test_an_orbit_is_shot_only_while_it_iterates(diagram, shots):
    # a start on the orbit converges at once; one further along the branch takes several
    # steps. Solved together, each is what it is alone, and no orbit is shot once done
    # (nor is a shot taken when every orbit is done)
    x0, T, _ = _start(diagram, [15.0, 15.6], "unstable")
    mu = np.array([15.0, 16.2])
    together = orbits.solve_orbits(FLUTTER3DOF, FLUTTER3DOF.params, x0, T, mu, [False, False])
    rows_together = sum(shots)
    alone, rows_alone = [], []
    for i in range(2):
        shots.clear()
        alone.append(orbits.solve_orbits(FLUTTER3DOF, FLUTTER3DOF.params, x0[i:i + 1],
                                         T[i:i + 1], mu[i:i + 1], [False]))
        rows_alone.append(sum(shots))
    assert together.ok.all() and rows_alone[0] < rows_alone[1]
    assert rows_together == sum(rows_alone)
    for i in range(2):
        np.testing.assert_allclose(together.period[i], alone[i].period[0], rtol=1e-12)
        np.testing.assert_allclose(together.x0[i], alone[i].x0[0], rtol=1e-10, atol=1e-14)
