"""Multi-start combination: draw counts, stacking weights, the mixture, the log-likelihood."""

from types import SimpleNamespace

import jax
import numpy as np
import pytest
from scipy.stats import norm

from bayeshopf.diagnostics.comparison import pointwise_log_likelihood
from bayeshopf.inference.multistart import draw_counts, mix, stacking_weights
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


def test_pointwise_log_likelihood_of_the_hybrid_model_matches_scipy():
    """The log-likelihoods stacking uses: one per draw and recording, summed over coefficients."""
    rng = np.random.default_rng(1)
    n_draws, n_rec, n_h = 3, 4, 2
    n_c = 2 * n_h + 1
    feats = SimpleNamespace(coeffs=rng.normal(size=(n_rec, n_c)),
                            coeffs_sd=rng.uniform(0.01, 0.1, size=(n_rec, n_c)))
    samples = {"coeffs_hat": rng.normal(size=(n_draws, n_rec, n_c)),
               "sigma": rng.uniform(0.1, 0.5, size=(n_draws, n_h + 1))}
    ll = pointwise_log_likelihood(samples, feats)
    # per coefficient [σ0, σ1, σ2, σ1, σ2] (cos kθ and sin kθ share σ_k)
    per = samples["sigma"][:, [0, 1, 2, 1, 2]]
    scale = np.sqrt(per[:, None, :] ** 2 + feats.coeffs_sd[None] ** 2)
    ref = norm.logpdf(feats.coeffs[None], loc=samples["coeffs_hat"], scale=scale).sum(-1)
    assert ll.shape == (n_draws, n_rec)
    np.testing.assert_allclose(ll, ref, rtol=1e-12)
