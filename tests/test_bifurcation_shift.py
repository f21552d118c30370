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


def test_small_shifts_have_the_first_order_spread():
    """``sd = κ η G √(conditional variance)`` where the shift is small against its distance."""
    spec, theta = _spec(), _theta(40_000, eta=0.002)
    x, ends = _coordinates(spec, theta)
    var = np.diag(_dense_conditional(x, ends, 0.5))
    d = bs.shift_draws(spec, theta, MU, SIGN, 1.0, jax.random.PRNGKey(3))
    gap = 17.0 - 14.9
    for name, v in zip(("mu0", "mu_fold"), var, strict=True):
        want = 0.002 * gap * np.sqrt(v)
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
