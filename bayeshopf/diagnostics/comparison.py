"""Pointwise log-likelihoods and model comparison (sub- against supercritical)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from bayeshopf.diagnostics import arviz_io


def pooled_log_likelihood(post) -> np.ndarray:
    """A fit's pointwise log-likelihood with the chains pooled, ``(n_draws, n_rec)``.

    ``post.log_likelihood`` is ``log p(y_i | y_{−i}, θ)`` per chain and draw
    (:attr:`bayeshopf.posterior.HybridPosterior.log_likelihood`); ``nan`` (a
    branch that does not exist in a draw) counts as ``−inf``.
    """
    ll = np.asarray(post.log_likelihood)
    ll = ll.reshape((-1, ll.shape[-1]))
    return np.where(np.isfinite(ll), ll, -np.inf)


#: Recordings closer in μ than this fraction of the μ span count as one airspeed.
SAME_MU_FRACTION = 0.01
#: Amplitude difference, in units of the larger spread over segments, that
#: :func:`compare_criticality` reports as two distinct orbits.
DISTINCT_ORBITS = 3.0


def same_mu_tolerance(mu, same_mu_fraction: float = SAME_MU_FRACTION) -> float:
    """Largest μ difference at which two recordings count as at one μ (a fraction of the span)."""
    return same_mu_fraction * max(float(np.ptp(np.asarray(mu, dtype=float))), 1e-12)


def coexisting_orbits(features,
                      same_mu_fraction: float = SAME_MU_FRACTION) -> list[dict]:
    """Pairs of recordings at one μ, and how far apart their amplitudes are.

    A supercritical Hopf bifurcation has one LCO per μ. Two recordings at the
    same μ whose amplitudes A_i, A_j differ by many times their repeatability
    (the spread s of the per-segment amplitudes) are two coexisting orbits,
    which only a fold (the subcritical case) gives. The measure is
    ``|A_i − A_j| / max(s_i, s_j)``; it needs no model and no branch labels.

    Args:
        features: The recordings' features.
        same_mu_fraction: Recordings closer in μ than this fraction of the μ
            span count as one μ.

    Returns:
        One dictionary per pair, ``{"recordings": (name_i, name_j), "mu": μ_i,
        "amplitudes": (A_i, A_j), "spreads": (s_i, s_j), "separation": ratio}``,
        largest separation first; ``inf`` where neither record has a spread
        (single segments).
    """
    mu = np.asarray(features.mu, dtype=float)
    tol = same_mu_tolerance(mu, same_mu_fraction)
    amp, sd = np.asarray(features.amplitude), np.asarray(features.amplitude_sd)
    pairs = []
    for i in range(mu.size):
        for j in range(i + 1, mu.size):
            if abs(mu[i] - mu[j]) > tol:
                continue
            spread = max(float(sd[i]), float(sd[j]))
            gap = abs(float(amp[i] - amp[j]))
            pairs.append({
                "recordings": (features.names[i], features.names[j]), "mu": float(mu[i]),
                "amplitudes": (float(amp[i]), float(amp[j])),
                "spreads": (float(sd[i]), float(sd[j])),
                "separation": gap / spread if spread > 0 else float("inf"),
            })
    return sorted(pairs, key=lambda p: -p["separation"])


def compare_criticality(fits: dict, refit: Callable | None = None,
                        k_thresh: float = 0.7) -> dict:
    """LOO comparison of fits keyed by criticality: PSIS, or exact where PSIS fails.

    Args:
        fits: Criticality → :class:`~bayeshopf.posterior.HybridPosterior` on the
            same features (anything with ``log_likelihood`` and ``features``).
        refit: Optional ``(criticality, i) ↦ log p(y_i | y_{−i}, θ_s^(−i))`` over the
            draws of a refit without recording i. When given, every recording
            whose Pareto k exceeds ``k_thresh`` in a model is refitted there
            (ArviZ ``reloo``) and its exact leave-one-out density replaces PSIS's.
        k_thresh: Pareto k above which PSIS is not trusted.

    Returns:
        ``{"loo": {name: {"elpd", "se", "p_loo", "pareto_k"}}, "compare": {name:
        {"rank", "elpd_loo", "elpd_diff", "dse", "weight"}}, "preferred": name,
        "elpd_preferred": name, "decided_by": "elpd" or "coexisting orbits",
        "elpd_diff": d, "dse": se_d, "z": d / se_d, "max_pareto_k": {name: k},
        "refitted": {name: [i...]}, "method", "coexisting": :func:`coexisting_orbits`,
        "statement": a paragraph}``; ``elpd_diff`` is the ELPD-preferred model's ELPD
        minus the other's (≥ 0). When two recordings at one μ are at least
        :data:`DISTINCT_ORBITS` spreads apart (:func:`coexisting_orbits`), the
        data hold a fold whatever the ELPD says: ``preferred`` is then
        ``"subcritical"`` (``decided_by`` says which rule chose), and the
        statement names the pair. ``elpd_preferred`` is the ELPD's choice.
    """
    lls = {name: pooled_log_likelihood(f) for name, f in fits.items()}
    held_out = None if refit is None else {
        name: (lambda i, name=name: refit(name, i)) for name in fits}
    table, loo = arviz_io.compare_with_loo(lls, held_out, k_thresh)
    preferred = min(table, key=lambda k: table[k]["rank"])
    other = max(table, key=lambda k: table[k]["rank"])
    diff, dse = table[other]["elpd_diff"], table[other]["dse"]
    z = diff / dse if dse > 0 else float("inf")
    max_k = {k: max(v["pareto_k"]) for k, v in loo.items()}
    refitted = {k: v["refitted"] for k, v in loo.items()}
    strength = "strongly" if z > 4 else "clearly" if z > 2 else "weakly"
    method = "PSIS-LOO" if refit is None else "LOO (PSIS, exact refits where Pareto k > " \
        f"{k_thresh:g})"
    statement = (
        f"{method} {strength} prefers the {preferred} model: ELPD "
        f"{loo[preferred]['elpd']:.1f} ± {loo[preferred]['se']:.1f} against "
        f"{loo[other]['elpd']:.1f} ± {loo[other]['se']:.1f} ({other}), a difference of "
        f"{diff:.1f} ± {dse:.1f} ({z:.1f} standard errors)"
    )
    if refit is not None:
        n_refits = sum(len(v) for v in refitted.values())
        statement += f", with {n_refits} exact refit{'s' * (n_refits != 1)}"
    elif max(max_k.values()) > k_thresh:
        bad = ", ".join(f"{k} {v:.2f}" for k, v in max_k.items() if v > k_thresh)
        statement += (f"; Pareto k above {k_thresh:g} ({bad}) marks recordings the model "
                      "depends on heavily, so the ELPD of that model is only approximate")
    coexisting = coexisting_orbits(next(iter(fits.values())).features)
    distinct = [p for p in coexisting if np.isfinite(p["separation"])
                and p["separation"] >= DISTINCT_ORBITS]
    elpd_preferred, decided_by = preferred, "elpd"
    if distinct and "subcritical" in fits:
        p = distinct[0]
        statement += (
            f". Without either model: {p['recordings'][0]} and {p['recordings'][1]} at "
            f"μ = {p['mu']:g} are two distinct orbits (amplitudes {p['amplitudes'][0]:.4g} "
            f"and {p['amplitudes'][1]:.4g}, {p['separation']:.0f} times the larger spread "
            "over segments); one LCO per μ, as in a supercritical Hopf bifurcation, cannot "
            "give them, a fold can")
        if preferred != "subcritical":
            statement += (", so the subcritical model is chosen: the supercritical one "
                          "matches its predictive density only by taking the two orbits "
                          "for scatter")
        preferred, decided_by = "subcritical", "coexisting orbits"
    return {"loo": loo, "compare": table, "preferred": preferred,
            "elpd_preferred": elpd_preferred, "decided_by": decided_by, "elpd_diff": diff,
            "dse": dse, "z": z, "max_pareto_k": max_k, "refitted": refitted,
            "method": method, "coexisting": coexisting, "statement": statement + "."}
