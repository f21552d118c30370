"""Multi-start combination: draw counts, stacking weights, the mixture, the log-likelihood."""

import jax
import numpy as np
import numpyro
import numpyro.distributions as dist
import pytest
from scipy.stats import norm

from bayeshopf.inference.multistart import (
    draw_counts,
    mix,
    pointwise_log_likelihood,
    stacking_weights,
)
from bayeshopf.inference.results import SviResult


@pytest.mark.parametrize("weights", [[0.5, 0.5], [0.125, 0.875, 0.0], [1e-9, 0.3, 0.7 - 1e-9]])
def test_draw_counts_sum_and_proportions(weights):
    n = 401
    c = draw_counts(np.array(weights), n)
    assert c.sum() == n
    assert np.all(np.abs(c - np.array(weights) * n) < 1.0)


def test_stacking_gives_a_clearly_worse_approximation_no_weight():
    rng = np.random.default_rng(0)
    good = rng.normal(-1.0, 0.1, size=(500, 8))
    bad = good - 30.0  # every observation 30 nats less likely
    w = stacking_weights([bad, good])
    assert w.shape == (2,) and np.isclose(w.sum(), 1.0)
    assert w[1] > 0.99
    assert np.array_equal(stacking_weights([good]), np.ones(1))


def _component(value, n):
    return SviResult(samples={"mu0": np.full(n, value), "x": np.full((n, 2), value)},
                     guide_params={"v": np.array(value)}, losses=np.zeros(3), guide="lowrank")


def test_mixture_draws_follow_the_weights_and_are_shuffled():
    parts = [_component(0.0, 400), _component(1.0, 400), _component(2.0, 400)]
    out = mix(parts, np.array([0.25, 0.75, 0.0]), jax.random.PRNGKey(0))
    mu0 = out.samples["mu0"]
    assert mu0.shape == (400,) and out.samples["x"].shape == (400, 2)
    assert np.sum(mu0 == 0.0) == 100 and np.sum(mu0 == 1.0) == 300
    assert not np.any(mu0 == 2.0)
    assert np.array_equal(out.samples["x"][:, 0], mu0)  # sites stay paired draw by draw
    assert 0.0 < np.mean(mu0[:100] == 0.0) < 1.0  # shuffled: a leading subset mixes both
    assert float(out.guide_params["v"]) == 1.0  # guide of the heaviest component


def test_pointwise_log_likelihood_matches_scipy():
    def model(y=None):
        m = numpyro.sample("m", dist.Normal(0.0, 1.0))
        s = numpyro.sample("s", dist.HalfNormal(1.0))
        with numpyro.plate("obs", 3):
            numpyro.sample("y", dist.Normal(m, s), obs=y)

    y = np.array([0.1, -0.4, 1.2])
    samples = {"m": np.array([0.0, 0.5]), "s": np.array([1.0, 0.3])}
    ll = pointwise_log_likelihood(model, {"y": y}, samples, obs_name="y")
    ref = norm.logpdf(y[None], loc=samples["m"][:, None], scale=samples["s"][:, None])
    np.testing.assert_allclose(ll, ref, rtol=1e-12)
