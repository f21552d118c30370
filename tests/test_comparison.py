"""LOO comparison: PSIS, and ArviZ ``reloo``'s exact refits where PSIS fails."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import logsumexp

from bayeshopf.diagnostics import arviz_io


def _log_lik(seed: int = 0) -> np.ndarray:
    """1000 draws × 6 observations; observation 2's log-likelihood is heavy-tailed."""
    rng = np.random.default_rng(seed)
    ll = rng.normal(-1.0, 0.1, size=(1000, 6))
    ll[:, 2] = -5.0 + 6.0 * rng.standard_t(1.5, size=1000)
    return ll


def test_reloo_replaces_psis_only_where_pareto_k_is_large():
    ll = _log_lik()
    psis = arviz_io.loo(ll)
    bad = [i for i, k in enumerate(psis["pareto_k"]) if k > 0.7]
    assert bad == [2], psis["pareto_k"]
    calls = []
    exact = np.log(np.linspace(0.01, 0.02, 400))  # a refit's held-out likelihoods

    def held_out(i):
        calls.append(i)
        return exact

    res = arviz_io.loo(ll, held_out_log_lik=held_out)
    assert calls == [2] and res["refitted"] == [2]
    assert res["elpd_i"][2] == pytest.approx(logsumexp(exact) - np.log(exact.size))
    others = [i for i in range(6) if i != 2]
    assert np.allclose(np.array(res["elpd_i"])[others], np.array(psis["elpd_i"])[others])
    assert res["elpd"] == pytest.approx(sum(res["elpd_i"]))
    assert res["se"] == pytest.approx(np.sqrt(6 * np.var(res["elpd_i"])))
    assert res["pareto_k"] == psis["pareto_k"]  # the PSIS diagnostics are kept


def test_compare_uses_the_refitted_densities():
    ll_a, ll_b = _log_lik(0), _log_lik(1) - 0.5
    exact = np.full(100, -1.0)
    table, loos = arviz_io.compare_with_loo({"a": ll_a, "b": ll_b},
                                            held_out={"a": lambda i: exact, "b": lambda i: exact})
    assert loos["a"]["refitted"] == [2] and loos["b"]["refitted"] == [2]
    d = np.array(loos["a"]["elpd_i"]) - np.array(loos["b"]["elpd_i"])
    assert d[2] == pytest.approx(0.0)  # both refits give the same density there
    assert table["b"]["elpd_diff"] == pytest.approx(d.sum())
    assert table["b"]["dse"] == pytest.approx(np.sqrt(6 * np.var(d)))
    # without refits, the same table as arviz_io.compare
    assert arviz_io.compare_with_loo({"a": ll_a, "b": ll_b})[0] == arviz_io.compare(
        {"a": ll_a, "b": ll_b})


def _features(mu, amplitude, amplitude_sd):
    from types import SimpleNamespace

    n = len(mu)
    return SimpleNamespace(mu=np.asarray(mu, float), amplitude=np.asarray(amplitude, float),
                           amplitude_sd=np.asarray(amplitude_sd, float),
                           names=tuple(f"r{i}" for i in range(n)))


def test_coexisting_orbits_pairs_recordings_at_one_mu_by_their_separation():
    from bayeshopf.diagnostics.comparison import coexisting_orbits

    # μ span 2.4: 14.9 and 14.91 are one μ (within 1%), 15.6 and 15.7 are not
    f = _features([14.9, 15.6, 17.3, 14.91, 15.7], [0.10, 0.12, 0.15, 0.06, 0.05],
                  [0.002, 0.002, 0.002, 0.004, 0.002])
    pairs = coexisting_orbits(f)
    assert [p["recordings"] for p in pairs] == [("r0", "r3")]
    assert pairs[0]["separation"] == pytest.approx(0.04 / 0.004)
    assert pairs[0]["amplitudes"] == (0.10, 0.06) and pairs[0]["mu"] == 14.9
    # a wider tolerance also pairs 15.6 with 15.7; largest separation first
    wide = coexisting_orbits(f, same_mu_fraction=0.05)
    assert [p["recordings"] for p in wide] == [("r1", "r4"), ("r0", "r3")]
    assert wide[0]["separation"] == pytest.approx(0.07 / 0.002)
    # single-segment records have no spread: the separation is unbounded
    assert coexisting_orbits(_features([1.0, 1.0, 2.0], [0.1, 0.2, 0.3], [0, 0, 0]))[0][
        "separation"] == np.inf
    assert coexisting_orbits(_features([1.0, 2.0], [0.1, 0.2], [0.01, 0.01])) == []


def test_evidence_with_unbounded_separation_is_written_as_strict_json(tmp_path):
    """An inf separation (single-segment records) becomes null in summary.json, not an error."""
    import json

    from bayeshopf.fit_folder import _write_json

    path = tmp_path / "summary.json"
    _write_json({"coexisting": [{"separation": float("inf"), "amplitudes": (0.1, 0.2)}],
                 "z": float("nan"), "n": 3}, path)
    assert json.loads(path.read_text()) == {
        "coexisting": [{"separation": None, "amplitudes": [0.1, 0.2]}], "z": None, "n": 3}


def _fake_fit(pred_a0, sigma0, features, n_draws=200, seed=0):
    """A fit-like record whose draws predict a0 = pred_a0 (per recording) with scatter σ_0."""
    from types import SimpleNamespace

    from scipy.stats import norm

    rng = np.random.default_rng(seed)
    pred = np.asarray(pred_a0)[None] + 1e-3 * rng.standard_normal((n_draws, len(pred_a0)))
    ll = norm.logpdf(features.coeffs[:, 0][None], pred, sigma0)
    return SimpleNamespace(log_likelihood=ll[None], features=features)


def test_coexisting_orbits_overrule_an_elpd_that_prefers_one_lco_per_mu():
    """Two orbits at one μ overrule the ELPD's supercritical choice; the statement says so."""
    from types import SimpleNamespace

    from bayeshopf.diagnostics.comparison import compare_criticality

    mu = np.array([1.0, 1.0, 1.5, 2.0])
    a0 = np.array([1.0, 0.6, 1.1, 1.2])
    coeffs = np.zeros((4, 5))
    coeffs[:, 0] = a0
    features = SimpleNamespace(mu=mu, coeffs=coeffs, amplitude=2 * a0,
                               amplitude_sd=np.full(4, 0.01), names=("s1", "u1", "s15", "s2"))
    # the subcritical draws miss recording 3 badly; the supercritical ones are vague everywhere
    sub = _fake_fit([1.0, 0.6, 1.1, 1.6], 0.02, features)
    sup = _fake_fit([0.8, 0.8, 1.1, 1.2], 0.25, features)
    ev = compare_criticality({"subcritical": sub, "supercritical": sup})
    assert ev["elpd_preferred"] == "supercritical"
    assert ev["preferred"] == "subcritical" and ev["decided_by"] == "coexisting orbits"
    assert ev["coexisting"][0]["recordings"] == ("s1", "u1")
    assert ev["coexisting"][0]["separation"] == pytest.approx(0.8 / 0.01)
    assert "so the subcritical model is chosen" in ev["statement"]
    # without the pair (the unstable orbit moved to its own μ) the ELPD decides
    features.mu = np.array([1.0, 1.25, 1.5, 2.0])
    ev = compare_criticality({"subcritical": sub, "supercritical": sup})
    assert ev["preferred"] == ev["elpd_preferred"] == "supercritical"
    assert ev["decided_by"] == "elpd" and ev["coexisting"] == []


def test_pooled_log_likelihood_pools_chains_and_counts_a_missing_branch_as_impossible():
    from types import SimpleNamespace

    from bayeshopf.diagnostics.comparison import pooled_log_likelihood

    ll = np.arange(2 * 3 * 4, dtype=float).reshape(2, 3, 4)
    ll[1, 2, 3] = np.nan
    out = pooled_log_likelihood(SimpleNamespace(log_likelihood=ll))
    assert out.shape == (6, 4)
    np.testing.assert_array_equal(out[:3], ll[0])
    assert out[5, 3] == -np.inf and np.isfinite(np.delete(out.ravel(), 23)).all()
