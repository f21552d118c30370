"""Pointwise log-likelihoods and model comparison (sub- against supercritical)."""

from __future__ import annotations

import numpy as np
from scipy.stats import norm

from bayeshopf.diagnostics import arviz_io
from bayeshopf.features.orbits import OrbitFeatures
from bayeshopf.model.probabilistic import harmonic_scatter


def pointwise_log_likelihood(samples: dict, features: OrbitFeatures) -> np.ndarray:
    """``log p(Φ(R_i) | θ_s)`` per draw s and recording i, shape ``(n_draws, n_rec)``.

    The likelihood of the model: ``Φ(R_i) ~ N(Φ(R̂_i), √(σ_k² + s_i²))``, summed
    over the coefficients of recording i.
    """
    per_coeff = np.asarray(harmonic_scatter(np.asarray(samples["sigma"])))
    scale = np.sqrt(per_coeff[:, None, :] ** 2 + features.coeffs_sd[None] ** 2)
    lp = norm.logpdf(features.coeffs[None], loc=np.asarray(samples["coeffs_hat"]), scale=scale)
    return lp.sum(axis=-1)


def compare_criticality(fits: dict) -> dict:
    """PSIS-LOO comparison of fits keyed by criticality.

    Returns:
        ``{"loo": {name: {"elpd", "se", "p_loo", "pareto_k"}}, "compare": {name:
        {"rank", "elpd_loo", "elpd_diff", "dse", "weight"}}, "preferred": name,
        "elpd_diff": d, "dse": se_d, "z": d / se_d, "max_pareto_k": {name: k},
        "statement": one sentence}``; ``elpd_diff`` is the preferred model's
        ELPD minus the other's (≥ 0).
    """
    lls = {name: pointwise_log_likelihood(f.samples, f.features) for name, f in fits.items()}
    table = arviz_io.compare(lls)
    preferred = min(table, key=lambda k: table[k]["rank"])
    other = max(table, key=lambda k: table[k]["rank"])
    loo = {k: arviz_io.loo(v) for k, v in lls.items()}
    diff, dse = table[other]["elpd_diff"], table[other]["dse"]
    z = diff / dse if dse > 0 else float("inf")
    max_k = {k: max(v["pareto_k"]) for k, v in loo.items()}
    strength = "strongly" if z > 4 else "clearly" if z > 2 else "weakly"
    statement = (
        f"PSIS-LOO {strength} prefers the {preferred} model: ELPD "
        f"{loo[preferred]['elpd']:.1f} ± {loo[preferred]['se']:.1f} against "
        f"{loo[other]['elpd']:.1f} ± {loo[other]['se']:.1f} ({other}), a difference of "
        f"{diff:.1f} ± {dse:.1f} ({z:.1f} standard errors)"
    )
    if max(max_k.values()) > 0.7:
        bad = ", ".join(f"{k} {v:.2f}" for k, v in max_k.items() if v > 0.7)
        statement += (f"; Pareto k above 0.7 ({bad}) marks recordings the model depends on "
                      "heavily, so the ELPD of that model is only approximate")
    return {"loo": loo, "compare": table, "preferred": preferred, "elpd_diff": diff,
            "dse": dse, "z": z, "max_pareto_k": max_k, "statement": statement + "."}
