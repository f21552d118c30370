"""The demo system's continuation results shipped with the package (bayeshopf.simulators.stored,
written by bayeshopf.simulators.ship)."""

from dataclasses import replace

import numpy as np
import pytest

from bayeshopf.simulators import VANDERPOL, continue_from_hopf, get_system, ship
from bayeshopf.simulators import stored as st
from bayeshopf.simulators.recordings import N_ORBIT

#: Rounding: the stored arrays may come from another process on another machine, and two
#: runs differ at the ODE solver's tolerance (its rtol is 1e-10 a step)
RTOL = 1e-9
#: The states sampled along an orbit carry the solver's global error as well, which another
#: CPU's rounding moves by more than the end points
ORBIT_RTOL = 1e-8


@pytest.fixture(scope="module")
def flutter():
    return get_system("flutter3dof")


def test_the_shipped_file_is_current(flutter):
    assert st.stored_diagram(flutter) is not None, (
        "bayeshopf/simulators/stored/flutter3dof.npz is missing or stale (its key is of other "
        "sources or parameters): run `python -m bayeshopf.simulators.ship` and commit it")


def test_the_stored_diagram_and_orbits_are_a_fresh_continuations(flutter):
    got = st.stored_diagram(flutter)
    points = ship.orbits_to_store(flutter)
    assert {n for _, _, n in points} == {N_ORBIT, None}
    stored_orbits = [got.orbit_at(mu, branch, n_points=n) for mu, branch, n in points]
    for (mu, branch, _), s in zip(points, stored_orbits, strict=True):   # looked up, not solved
        assert got.branch(branch).solved[(mu, s.states.shape[0])] is s
    fresh = continue_from_hopf(flutter)                 # computed, never looked up
    assert all(not b.solved for b in fresh.branches)
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
    with pytest.raises(ValueError, match="not a module-level function"):
        ship.write_stored(closure)
    # an orbit of the shipped system that was not stored
    branch = st.stored_diagram(flutter).branch("stable")
    assert (16.123, N_ORBIT) not in branch.solved


def test_what_is_written_is_what_is_read(tmp_path, monkeypatch):
    # a system without stored orbits: its diagram alone, written and read back as it was
    path = ship.write_stored(VANDERPOL, tmp_path)
    assert path == tmp_path / "vanderpol.npz"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["vanderpol.npz"]   # nothing left over
    assert st.stored_diagram(VANDERPOL) is None                # not in the package's folder
    monkeypatch.setattr(st, "FOLDER", tmp_path)
    got = st.stored_diagram(VANDERPOL)
    fresh = continue_from_hopf(VANDERPOL)
    assert got.hopf.mu == fresh.hopf.mu and got.n_steps == fresh.n_steps
    for a, b in zip(got.branches, fresh.branches, strict=True):
        assert a.kind == b.kind and not a.solved
        for name in ("mu", "period", "x0", "orbits", "floquet", "stable"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
