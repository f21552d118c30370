"""The discrepancy in μ at the Hopf point and the fold (bayeshopf.model.bifurcation_shift).

References written here from the module's equations: the noise-free
Gaussian-process conditional by NumPy's dense solve, the first-order shift's
standard deviation ``κ η G √(conditional variance)``, and the bounds the moved
points must respect (the recordings that lie on their branches).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from bayeshopf._x64 import ensure_x64
from bayeshopf.features.frame import PlanarFrame
from bayeshopf.model import bifurcation_shift as bs
from bayeshopf.model import collapsed as cm

ensure_x64()

MU = (15.2, 15.9, 16.7, 15.2, 15.9, 16.4)
SIGN = (1.0, 1.0, 1.0, -1.0, -1.0, -1.0)


def _spec() -> cm.CollapsedSpec:
    return cm.CollapsedSpec("subcritical", PlanarFrame(np.zeros(2), np.eye(2)), 2, 15.95,
                            1.5, 15.2, 16.4, 1.3, cm.hidden_layer(4),
                            discrepancy_scale=((0.0,) * 5, (0.0,) * 5))


def _theta(n: int, eta: float = 0.02, ell: float = 0.5) -> dict:
    mu0, fold, w = 17.0, 14.9, 0.3
    beta = -float(cm.unfolding(fold, mu0, w, fold))
    one = {"mu0": mu0, "mu_fold": fold, "w_unfold": w, "a2": 2.0 * np.sqrt(beta),
           "eta": eta, "ell": ell, "gap_fold": min(MU) - fold, "gap_hopf": mu0 - 16.4}
    return {k: np.full(n, v) for k, v in one.items()}


def _coordinates(spec, theta):
    """The recordings' and the endpoints' ``(μ̃, s²/mean s²)``, from the model's radii."""
    t = {k: v[0] for k, v in theta.items()}
    r = np.asarray(cm.radius(spec, jnp.asarray(MU), jnp.asarray(SIGN), t))
    s2 = r**2 / t["a2"]
    x = np.stack([(np.asarray(MU) - spec.mu_centre) / spec.mu_span, s2 / s2.mean()], axis=-1)
    ends = np.array([[(t["mu0"] - spec.mu_centre) / spec.mu_span, 0.0],
                     [(t["mu_fold"] - spec.mu_centre) / spec.mu_span, 0.5 / s2.mean()]])
    return x, ends


def _dense_conditional(x, ends, ell):
    def k(a, b):
        return np.exp(-0.5 * np.sum((a[:, None] - b[None]) ** 2, -1) / ell**2)

    return k(ends, ends) - k(ends, x) @ np.linalg.solve(k(x, x), k(x, ends))


def test_endpoint_factor_is_the_dense_conditional():
    spec, theta = _spec(), _theta(1)
    x, ends = _coordinates(spec, theta)
    F = np.asarray(bs.endpoint_factor(jnp.asarray(x), jnp.asarray(ends), 0.5))
    np.testing.assert_allclose(F @ F.T, _dense_conditional(x, ends, 0.5), atol=1e-9)
    assert np.diag(F @ F.T).min() > 1e-3          # the endpoints lie away from every recording


def test_the_conditional_vanishes_at_a_recording():
    x = np.array([[0.0, 1.0], [0.5, 0.2], [1.0, 1.5]])
    F = np.asarray(bs.endpoint_factor(jnp.asarray(x), jnp.asarray(x[1:2] + 1e-7), 0.4))
    assert abs(F[0, 0]) < 1e-4          # √ of the recordings' jitter; far away it is ~1


def test_kappa_zero_gives_the_models_own_points():
    theta = _theta(50)
    d = bs.shift_draws(_spec(), theta, MU, SIGN, 0.0, jax.random.PRNGKey(0))
    np.testing.assert_array_equal(d["mu0"], theta["mu0"])
    np.testing.assert_array_equal(d["mu_fold"], theta["mu_fold"])


@pytest.mark.parametrize(("eta", "floor", "scale"), [(0.002, 0.0, 0.002),
                                                      (0.0012, 0.0016, 0.002),
                                                      (0.0, 0.002, 0.002)])
def test_small_shifts_have_the_first_order_spread(eta, floor, scale):
    """``sd = κ √(η² + φ²) G √(conditional variance)`` where the shift is small
    against its distance (``scale``: √(η² + φ²), written out)."""
    spec, theta = _spec(), _theta(40_000, eta=eta)
    x, ends = _coordinates(spec, theta)
    var = np.diag(_dense_conditional(x, ends, 0.5))
    d = bs.shift_draws(spec, theta, MU, SIGN, 1.0, jax.random.PRNGKey(3), floor=floor)
    gap = 17.0 - 14.9
    for name, v in zip(("mu0", "mu_fold"), var, strict=True):
        want = scale * gap * np.sqrt(v)
        assert np.std(d[name]) == pytest.approx(want, rel=0.03)
        assert abs(np.mean(d[name]) - theta[name][0]) < 0.05 * want


def test_the_spread_grows_with_the_discrepancys_scale():
    spec = _spec()
    sds = [np.std(bs.shift_draws(spec, _theta(4000, eta=e), MU, SIGN, 2.0,
                                 jax.random.PRNGKey(1))["mu_fold"]) for e in (0.005, 0.05)]
    assert sds[1] > 5 * sds[0]


def test_moved_points_stay_beyond_the_recordings_that_bound_them():
    spec = _spec()
    d = bs.shift_draws(spec, _theta(4000, eta=0.3), MU, SIGN, 8.0, jax.random.PRNGKey(2))
    assert np.all(d["mu_fold"] < min(MU)) and np.all(d["mu0"] > spec.mu_unstable_max)
    assert np.all(np.isfinite(d["mu0"])) and np.all(np.isfinite(d["mu_fold"]))


def test_needs_the_discrepancy():
    spec = dataclasses.replace(_spec(), discrepancy_scale=None)
    with pytest.raises(ValueError, match="model discrepancy"):
        bs.shift_draws(spec, _theta(3), MU, SIGN, 1.0, jax.random.PRNGKey(0))


# ------------------------------------------------------------------ along the branches
def _knots(theta, rig, kappa, seed=0, floor=0.0):
    return bs.branch_knots(_spec(), theta, rig, MU, SIGN, kappa, jax.random.PRNGKey(seed),
                           floor=floor)


def test_the_rigs_branches_pass_through_the_recordings_and_end_at_its_points():
    theta = _theta(300, eta=0.1)
    rig = bs.shift_draws(_spec(), theta, MU, SIGN, 2.0, jax.random.PRNGKey(5))
    knots = _knots(theta, rig, 2.0)
    for b in (1.0, -1.0):
        model, moved = knots[b]
        assert np.all(np.diff(moved, axis=1) >= 0)
        at = np.array([m for m, s in zip(MU, SIGN, strict=True) if s == b])
        np.testing.assert_allclose(bs.model_mu(at, model, moved), np.broadcast_to(at, (300, 3)),
                                   rtol=0, atol=1e-12)
        # the fold: where both branches start, in the rig and in the model
        for s in range(0, 300, 37):
            assert bs.model_mu([rig["mu_fold"][s]], model[s:s + 1], moved[s:s + 1])[0, 0] == \
                pytest.approx(theta["mu_fold"][s], abs=1e-9)
    model, moved = knots[-1.0]
    np.testing.assert_allclose(moved[:, -1], rig["mu0"], atol=1e-12)
    np.testing.assert_allclose(model[:, -1], theta["mu0"], atol=1e-12)
    assert np.all(moved >= rig["mu_fold"][:, None]) and np.all(moved <= rig["mu0"][:, None])
    # beyond the rig's Hopf point the unstable branch is the model's beyond its own
    assert np.all(bs.model_mu([30.0], model, moved)[:, 0] > theta["mu0"])


def test_kappa_zero_leaves_the_branches_where_the_model_has_them():
    theta = _theta(20)
    knots = _knots(theta, {"mu0": theta["mu0"], "mu_fold": theta["mu_fold"]}, 0.0)
    mu = np.linspace(14.0, 20.0, 37)
    for b in (1.0, -1.0):
        np.testing.assert_allclose(bs.model_mu(mu, *knots[b]), np.broadcast_to(mu, (20, 37)),
                                   atol=1e-12)


def _dense_move(spec, theta, grid_mu, grid_sign, ends_move, ell, scale):
    """Mean and sd of the move at points of the branches, by NumPy's dense solve."""
    x, ends = _coordinates(spec, theta)
    t = {k: v[0] for k, v in theta.items()}
    r = np.asarray(cm.radius(spec, jnp.asarray(grid_mu), jnp.asarray(grid_sign), t))
    r_rec = np.asarray(cm.radius(spec, jnp.asarray(MU), jnp.asarray(SIGN), t))
    xg = np.stack([(grid_mu - spec.mu_centre) / spec.mu_span, r**2 / np.mean(r_rec**2)], -1)

    def k(a, b):
        return np.exp(-0.5 * np.sum((a[:, None] - b[None]) ** 2, -1) / ell**2)

    xc = np.concatenate([x, ends])
    w = np.linalg.solve(k(xc, xc), k(xc, xg))
    mean = w.T @ np.concatenate([np.zeros(len(MU)), ends_move])
    var = np.diag(k(xg, xg) - k(xg, xc) @ w)
    return mean, scale * np.sqrt(var)


@pytest.mark.parametrize(("eta", "floor"), [(0.01, 0.0), (0.006, 0.008)])
def test_the_moves_along_the_branches_are_the_conditional_given_the_ends(eta, floor):
    """Mean and sd at each point against the dense conditional given the recordings and
    the ends, at the scale ``√(η² + φ²) G`` (0.01 G in both cases)."""
    spec, n = _spec(), 20_000
    theta = _theta(n, eta=eta)
    ends_move = np.array([0.05, -0.04])
    rig = {"mu0": theta["mu0"] + ends_move[0], "mu_fold": theta["mu_fold"] + ends_move[1]}
    for b in (-1.0, 1.0):
        model, moved = _knots(theta, rig, 1.0, seed=4, floor=floor)[b]
        order = np.argsort(model, axis=1)                  # back to the model's order
        model = np.take_along_axis(model, order, 1)
        move = np.take_along_axis(moved, order, 1) - model
        np.testing.assert_allclose(model, model[:1].repeat(n, 0))     # one grid for all draws
        inner = ~np.isin(model[0], list(MU) + [17.0, 14.9])
        mean, sd = _dense_move(spec, theta, model[0, inner], b, ends_move, 0.5,
                               0.01 * (17.0 - 14.9))
        got = move[:, inner]
        ok = sd > 1e-3 * 0.01 * 2.1                        # where the process is not pinned
        assert ok.sum() >= 10
        se = sd / np.sqrt(n)
        assert np.all(np.abs(got.mean(0) - mean) < 5 * se + 1e-9)
        np.testing.assert_allclose(got.std(0)[ok], sd[ok], rtol=0.03)
