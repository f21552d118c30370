"""The demo system's continuation results shipped with the package (bayeshopf.simulators.stored)."""

from dataclasses import replace

import numpy as np
import pytest

from bayeshopf.simulators import continue_from_hopf, get_system
from bayeshopf.simulators import stored as st
from bayeshopf.simulators.recordings import N_ORBIT
from bayeshopf.simulators.truth import FLUTTER_HELD_OUT, FLUTTER_PLAN

#: Rounding: the arrays were computed in another process by the same code, and two runs
#: differ at the ODE solver's tolerance (4e-12 m in the peak-to-peak of the smallest orbit,
#: 5e-5 m, at the Hopf point)
RTOL = 1e-9
#: The states sampled along an orbit carry the solver's global error (its rtol is 1e-10
#: a step), and another CPU's rounding moves them: by up to 2.6e-9 of the orbit's size
#: between the file written on one machine and a fresh continuation on another, where
#: μ, the periods and the initial states agreed to 1e-13
ORBIT_RTOL = 1e-8


@pytest.fixture(scope="module")
def flutter():
    return get_system("flutter3dof")


def test_the_shipped_file_is_current(flutter):
    assert st.stored_diagram(flutter) is not None, (
        "bayeshopf/simulators/stored/flutter3dof.npz is missing or stale (its key is of other "
        "sources or parameters): run `python -m bayeshopf.simulators.stored` and commit it")


def test_the_stored_diagram_and_orbits_are_a_fresh_continuations(flutter, monkeypatch):
    got = st.stored_diagram(flutter)
    points = [(m, b, n) for m, b in (*FLUTTER_PLAN, *FLUTTER_HELD_OUT) for n in (N_ORBIT, None)]
    stored_orbits = [got.orbit_at(mu, branch, n_points=n) for mu, branch, n in points]
    for (mu, branch, _), s in zip(points, stored_orbits, strict=True):   # looked up, not solved
        assert st.stored_orbit(flutter, got.branch(branch), mu, s.states.shape[0]) is not None
    monkeypatch.setattr(st, "_stored", lambda system: None)    # from here on, computed
    fresh = continue_from_hopf(flutter)
    assert got.criticality == fresh.criticality and got.n_steps == fresh.n_steps
    np.testing.assert_allclose(got.hopf.mu, fresh.hopf.mu, rtol=RTOL)
    np.testing.assert_allclose(got.hopf.eigenvector, fresh.hopf.eigenvector, rtol=RTOL)
    assert [f.mu for f in got.folds] == pytest.approx([f.mu for f in fresh.folds], rel=RTOL)
    assert len(got.branches) == len(fresh.branches)
    for a, b in zip(got.branches, fresh.branches, strict=True):
        assert a.kind == b.kind
        for name in ("mu", "period", "x0", "orbits", "floquet"):
            tol = ORBIT_RTOL if name == "orbits" else RTOL
            np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=tol,
                                       atol=tol * np.abs(getattr(b, name)).max())
        np.testing.assert_array_equal(a.stable, b.stable)
        for c in flutter.observed:
            np.testing.assert_allclose(a.amplitude[c], b.amplitude[c], rtol=ORBIT_RTOL,
                                       atol=ORBIT_RTOL * b.amplitude[c].max())
    # the demo's orbits: looked up on the stored diagram, computed by Newton on the fresh one
    for (mu, branch, n), s in zip(points, stored_orbits, strict=True):
        f = fresh.orbit_at(mu, branch, n_points=n)
        scale = np.abs(f.states).max(axis=0)
        np.testing.assert_allclose(s.states, f.states, rtol=0, atol=ORBIT_RTOL * scale.max())
        assert s.period == pytest.approx(f.period, rel=RTOL) and s.stable == f.stable


def test_nothing_is_looked_up_for_another_system(flutter):
    # another parameter value: another key, so the shipped file is not this system's
    params = dict(flutter.params)
    name = next(iter(params))
    other = replace(flutter, params={**params, name: params[name] * 1.01})
    assert st.system_key(other) not in (None, st.system_key(flutter))
    assert st.stored_diagram(other) is None
    # a right-hand side made at run time (a planted effect's closure): never looked up
    closure = replace(flutter, rhs=lambda x, mu, p: flutter.rhs(x, mu, p))
    assert st.system_key(closure) is None and st.stored_diagram(closure) is None
    # an orbit of the shipped system that was not stored
    branch = st.stored_diagram(flutter).branch("stable")
    assert st.stored_orbit(flutter, branch, 16.123, N_ORBIT) is None
