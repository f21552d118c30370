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
        ``{"loo": {name: {...}}, "compare": {...}, "preferred": name}``.
    """
    lls = {name: pointwise_log_likelihood(f.samples, f.features) for name, f in fits.items()}
    table = arviz_io.compare(lls)
    preferred = min(table, key=lambda k: table[k]["rank"])
    return {"loo": {k: arviz_io.loo(v) for k, v in lls.items()}, "compare": table,
            "preferred": preferred}
