"""Importance sampling from the Laplace approximation (bayeshopf.inference.importance).

Each check is against a reference the sampler does not compute: closed-form
moments, SciPy's quantiles of a skewed density, and NUTS on the same model.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from bayeshopf.inference import importance


def _gaussian_potential(m, P):
    def potential(x):
        d = np.asarray(x) - m
        return 0.5 * np.einsum("ki,ij,kj->k", d, P, d)

    return potential


def test_a_gaussian_posterior_is_reproduced_with_a_small_pareto_k():
    m = np.array([1.0, -2.0, 0.5])
    A = np.array([[1.0, 0.3, 0.0], [0.3, 0.5, -0.1], [0.0, -0.1, 2.0]])
    cov = A @ A.T
    x, check = importance.importance_draws(_gaussian_potential(m, np.linalg.inv(cov)), m, cov,
                                           4000, np.random.default_rng(1))
    assert x is not None and x.shape == (4000, 3)
    # Student-t proposals with heavier tails than the Gaussian: bounded weights
    assert check["pareto_k"] < 0.5 and check["ess"] > 4000
    se = np.sqrt(np.diag(cov) / min(check["ess"], 4000))
    assert np.all(np.abs(x.mean(0) - m) < 4 * se)
    np.testing.assert_allclose(np.cov(x.T), cov, atol=0.1 * np.max(np.diag(cov)))


def test_a_skewed_posterior_has_scipys_quantiles():
    # y_i = log g_i with g_i ~ Gamma(a_i): p(y) ∝ exp(a y − e^y), mode log a, curvature a;
    # observed through a rotation, so the proposal must adapt its covariance
    a = np.array([1.5, 3.0, 6.0])
    R = np.linalg.qr(np.random.default_rng(0).standard_normal((3, 3)))[0]

    def potential(x):
        y = np.asarray(x) @ R            # x = R y
        return np.sum(np.exp(y) - a * y, axis=1)

    x0 = R @ np.log(a)
    cov = R @ np.diag(1 / a) @ R.T
    x, check = importance.importance_draws(potential, x0, cov, 4000, np.random.default_rng(2))
    assert x is not None and check["pareto_k"] <= importance.K_MAX
    y = x @ R
    n_eff = min(check["ess"], 4000)
    for i, ai in enumerate(a):
        for p in (0.05, 0.5, 0.95):
            q = np.log(stats.gamma.ppf(p, ai))
            dens = stats.gamma.pdf(np.exp(q), ai) * np.exp(q)      # of y = log g
            se = np.sqrt(p * (1 - p) / n_eff) / dens
            assert abs(np.quantile(y[:, i], p) - q) < 4 * se, (ai, p)


def test_pareto_k_of_a_fixed_proposal_follows_the_weights_tail():
    # t_4 proposals against a Student-t posterior with ν = 0.2: w ~ |x|^3.8 where
    # P(|x| > t) ~ t^-4, so the weights' Pareto shape is 3.8/4 = 0.95; against a
    # Gaussian posterior the weights are bounded (shape below 0)
    nu = 0.2

    def heavy(x):
        return (1 + nu) / 2 * np.log1p(np.asarray(x)[:, 0] ** 2 / nu)

    def gauss(x):
        return 0.5 * np.asarray(x)[:, 0] ** 2

    for seed in range(5):
        rng = np.random.default_rng(seed)
        k_heavy = importance._round(heavy, np.zeros(1), np.eye(1), 2, rng)[2]
        k_gauss = importance._round(gauss, np.zeros(1), np.eye(1), 2, rng)[2]
        assert importance.K_MAX < k_heavy < 1.2 and k_gauss < 0.0, (seed, k_heavy, k_gauss)


def test_non_finite_potentials_get_no_weight():
    m, cov = np.zeros(2), np.eye(2)
    gauss = _gaussian_potential(m, np.eye(2))

    def potential(x):
        u = gauss(x)
        return np.where(np.asarray(x)[:, 0] > 1.0, np.nan, u)    # a half-plane the model lacks

    x, check = importance.importance_draws(potential, m, cov, 2000, np.random.default_rng(4))
    assert x is not None and np.all(x[:, 0] <= 1.0)


@pytest.fixture(scope="module")
def demo_importance(fast_demo_fit):
    from bayeshopf.posterior import fit_hybrid

    fit, rs, _ = fast_demo_fit          # the default: importance sampling
    settings = dataclasses.replace(fit.settings, inference="nuts")
    return fit, fit_hybrid(rs, "subcritical", seed=0, settings=settings, progress=False)


def test_importance_on_the_demo_agrees_with_nuts(demo_importance):
    from bayeshopf.inference.svi import interval_agreement

    fit, nuts_fit = demo_importance
    assert fit.run.method == "importance"
    s = fit.settings
    assert fit.run.chains["mu0"].shape == (1, s.num_chains * s.num_samples)
    chk = fit.diagnostics["posterior"]
    assert chk["method"] == "importance" and chk["pareto_k"] <= importance.K_MAX
    agree = interval_agreement(nuts_fit.run.samples, fit.run.samples)
    assert set(agree) == {"mu0", "a2", "mu_fold"}
    assert all(v["agree"] for v in agree.values()), agree


def test_a_fit_that_misses_the_orbits_says_to_compare_with_nuts(demo_importance):
    """With a relative model error above the limit, a fit by importance sampling warns that
    its draws about the MAP may miss posterior mass, and says how to compare with NUTS; the
    same fit by NUTS does not."""
    from dataclasses import replace

    from bayeshopf.diagnostics.fit_checks import SIGMA_REL_MAX, diagnose

    fit, nuts_fit = demo_importance

    def warned(post):
        chains = {**post.run.chains, "sigma_rel": post.run.chains["sigma_rel"] + SIGMA_REL_MAX}
        return [w for w in diagnose(replace(post, run=replace(post.run, chains=chains)))[
            "warnings"] if w.startswith("posterior: importance sampling")]

    assert not [w for w in diagnose(fit)["warnings"] if w.startswith("posterior: importance")]
    (w,) = warned(fit)
    assert "--nuts-check" in w
    assert warned(nuts_fit) == []


def test_importance_without_the_discrepancy_says_to_compare_with_nuts(demo_importance):
    """Without the discrepancy importance sampling can miss μ0's upper tail (docs/inference.md):
    such a fit says so in a ``posterior:`` warning; the same draws of a model with the
    discrepancy, and NUTS's, do not."""
    from dataclasses import replace

    from bayeshopf.diagnostics.fit_checks import diagnose

    fit, nuts_fit = demo_importance

    def lines(post, discrepancy):
        if not discrepancy:        # the same draws read as a model without it
            post = replace(post, spec=replace(post.spec, discrepancy_scale=None))
        return [w for w in diagnose(post)["warnings"] if "without the discrepancy" in w]

    (w,) = lines(fit, False)
    assert w.startswith("posterior: importance sampling") and "--inference nuts" in w
    assert lines(fit, True) == [] and lines(nuts_fit, False) == []


def test_a_failed_check_runs_nuts_and_says_why(demo_importance, monkeypatch):
    from bayeshopf.inference import nuts
    from bayeshopf.inference.settings import model_arguments

    fit, _ = demo_importance
    called = {}

    def fake_nuts(inputs, map_point, settings, key, progress, laplace=None):
        called["laplace"] = laplace       # the covariance importance sampling computed
        return {"mu0": np.zeros((2, 3))}, 0, {"draws_per_chain": 3}

    monkeypatch.setattr(importance, "K_MAX", -1.0)
    monkeypatch.setattr(nuts, "run_nuts", fake_nuts)
    inputs = model_arguments(fit.spec, fit.features)
    method, chains, _, sampler = importance.run_importance(
        inputs, fit.map_point, fit.settings, jnp.array([0, 7], dtype=jnp.uint32), False)
    assert called and method == "nuts" and chains["mu0"].shape == (2, 3)
    cov, ok = called["laplace"]
    assert ok and cov.shape[0] == cov.shape[1] and np.all(np.linalg.eigvalsh(cov) > 0)
    assert sampler["importance"]["fallback"].startswith("Pareto k̂")


def test_a_saved_importance_fit_reads_back_with_its_method_and_draws(demo_importance, tmp_path):
    import bayeshopf as bh
    from bayeshopf.diagnostics.checks import Status
    from bayeshopf.fit_folder import save_hybrid

    fit, _ = demo_importance
    save_hybrid(fit, tmp_path / "fit")
    back = bh.load_fit(tmp_path / "fit")
    assert back.posterior.run.method == "importance"
    np.testing.assert_allclose(np.sort(back.posterior.run.samples["mu0"]),
                               np.sort(fit.run.samples["mu0"]))
    assert back.diagnostics.sampler.status == Status.OK
