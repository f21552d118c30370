r"""The analysis without calibration: every parameter nominal, each library term alone.

Steps 3–6 of :mod:`bayeshopf.discrepancy.analysis` for
``calibrate=False``: every term's coefficient posterior and the posterior
probability of each single-term model
(:mod:`~bayeshopf.discrepancy.select`); the most probable term at its
posterior median added to the simulator, its Hopf point and fold recomputed;
the fit before and after with the difference in expected log predictive
density (PSIS-LOO over recordings, :mod:`bayeshopf.diagnostics.arviz_io`);
the verdict ``"none"``, ``"named"`` or ``"unexplained"``.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy import stats
from tqdm.auto import tqdm

from bayeshopf.diagnostics import arviz_io
from bayeshopf.discrepancy.locate import locate
from bayeshopf.discrepancy.prepare import Prepared
from bayeshopf.discrepancy.select import ALPHA, TIE_FACTOR, null_log_z, probabilities
from bayeshopf.discrepancy.stages import diagram_points, fit_errors, points, worst_words
from bayeshopf.discrepancy.terms import library_params
from bayeshopf.simulators.base import System

__all__ = ["single_terms"]

#: Posterior draws of the coefficient for the ELPD of the model with the term.
N_DRAWS = 400


def _fmt(x: float, sig: int = 3) -> str:
    return f"{x:.{sig}g}"


def _loglik(e: np.ndarray) -> np.ndarray:
    return -0.5 * np.sum(e**2, axis=1)


def single_terms(system: System, prepared: Prepared, *, seed: int, progress: bool,
                 point_intervals: bool) -> tuple[dict, list, dict]:
    """Every parameter nominal, each library term alone (module docstring).

    Args:
        system: The simulator.
        prepared: :func:`~bayeshopf.discrepancy.prepare.prepare`'s result for it.
        seed: Seed of the coefficient's posterior draws.
        progress: Show a progress bar over the terms.
        point_intervals: Also continue the simulator with the term at the ends
            of its coefficient's 90% interval (90% intervals of the Hopf point
            and fold).

    Returns:
        ``(data, fits, extras)``: the report's ``verdict``, ``candidates``,
        ``mismatch`` and ``fit``; the term fits, most probable first; the arrays
        for the figures.
    """
    fitter, diagram, _ = prepared
    mf, lib, L, base = fitter.mf, fitter.lib, fitter.system, fitter.base
    channels = mf.layout.channels
    lz0, e0 = null_log_z(fitter)
    fits = []
    for term in tqdm(lib.terms, desc="terms", disable=not progress, leave=False):
        fits.append(fitter.fit(term))
    p_none, probs = probabilities(lz0, fits)
    order = np.argsort(-probs)
    fits = [fits[i] for i in order]
    probs = probs[order]
    best = fits[0]

    R, P = mf.y.shape
    n_off = len(channels)
    dof0 = R * P - n_off
    chi0 = float(np.sum(e0**2))
    p_before = float(stats.chi2.sf(chi0, dof0))
    chi1 = best.chi2
    p_after = float(stats.chi2.sf(chi1, dof0 - 1))
    sig_before = p_before < ALPHA
    sig_after = p_after < ALPHA

    ysim0 = fitter.features(base)
    loc0 = locate(mf.layout, mf.y, ysim0, e0, fitter.offsets(base), mf.names, mf.mu, mf.branch,
                  base.ok)
    ysim1 = fitter.features(best.orbits)
    loc1 = locate(mf.layout, mf.y, ysim1, best.e_mode, fitter.offsets(best.orbits), mf.names,
                  mf.mu, mf.branch, best.orbits.ok)

    # ---------------------------------------------------------------- verdict
    names_ = [f.term.name for f in fits]
    t = best.term
    u = f" {t.units}" if t.units else ""
    coef = (f"{_fmt(best.median)}{u} (90% interval {_fmt(best.ci90[0])} to "
            f"{_fmt(best.ci90[1])})")
    tie = len(fits) > 1 and probs[1] * TIE_FACTOR >= probs[0]
    best_is_none = p_none >= probs[0]
    # ------------------------------------------------- model: the term added
    after_pts = {"hopf": None, "fold": None, "diagram": None}
    before_pts = diagram_points(diagram)
    if not best_is_none:
        after_pts = points(L.with_params(**library_params(lib), **{t.param: best.median}))
        if point_intervals:
            ends = [points(L.with_params(**library_params(lib), **{t.param: c}))
                    for c in best.ci90]
            for k in ("hopf", "fold"):
                v = [e[k] for e in ends]
                if all(x is not None for x in v) and after_pts[k] is not None:
                    after_pts[f"{k}_ci90"] = sorted(v)
    # ------------------------------------------------------------- ELPD
    draws = best.draws(N_DRAWS, seed)
    ll_after = np.stack([_loglik(best.e_mode + best.jac * (c - best.mode)) for c in draws])
    ll_before = np.tile(_loglik(e0), (N_DRAWS, 1))
    try:
        with warnings.catch_warnings():  # the model without a term has one point: k is nan
            warnings.simplefilter("ignore", RuntimeWarning)
            cmp = arviz_io.compare({"before": ll_before, "after": ll_after})
        elpd_diff = cmp["after"]["elpd_loo"] - cmp["before"]["elpd_loo"]
        elpd_se = max(cmp["before"]["dse"], cmp["after"]["dse"])
    except Exception:  # noqa: BLE001 - arviz may refuse degenerate inputs; report without it
        elpd_diff, elpd_se = None, None

    fit_before = fit_errors(fitter, base, loc0)
    fit_after = fit_errors(fitter, best.orbits, loc1)
    fit_before.update(hopf=before_pts["hopf"], fold=before_pts["fold"],
                      folds=before_pts["folds"], chi2=chi0, dof=dof0,
                      p_value=p_before)
    fit_after.update(term=t.name, coefficient=best.median, hopf=after_pts["hopf"],
                     fold=after_pts["fold"], folds=after_pts.get("folds"),
                     hopf_ci90=after_pts.get("hopf_ci90"),
                     fold_ci90=after_pts.get("fold_ci90"), chi2=chi1, dof=dof0 - 1, p_value=p_after,
                     elpd_difference=elpd_diff, elpd_difference_se=elpd_se,
                     note=after_pts.get("note"))

    amp_b = np.mean([v for v in fit_before["amplitude_error"].values() if v is not None])
    amp_a = np.mean([v for v in fit_after["amplitude_error"].values() if v is not None])
    p_unit = f" {system.parameter_units}" if system.parameter_units else ""

    def fold_words():
        fb, fa = before_pts["fold"], after_pts["fold"]
        if fb is not None and fa is not None:
            return f"brings the fold from {fb:.2f} to {fa:.2f}{p_unit} and "
        return ""

    where = worst_words(loc0, system)
    if best_is_none and not sig_before:
        kind, terms = "none", []
        sentence = ("The simulator matches the recordings within their noise: no missing "
                    f"physics is detected (probability {p_none:.2f} that nothing is missing).")
    elif best_is_none or sig_after:
        kind, terms = "unexplained", []
        sentence = ("The simulator and the recordings disagree beyond noise "
                    f"(chi² {chi0:.0f} for {dof0} features), and no single library term "
                    f"explains it: the best, {t.plain}, leaves chi² {chi1:.0f}." + where)
    else:
        kind = "named"
        terms = names_[:2] if tie else names_[:1]
        if tie:
            t2 = fits[1]
            sentence = (f"The simulator lacks {t.plain} or {t2.term.plain}: the two explain the "
                        f"data equally (probabilities {probs[0]:.2f} and {probs[1]:.2f}); "
                        f"{t.plain}: {coef}. Adding it {fold_words()}cuts the amplitude error "
                        f"from {100 * amp_b:.1f}% to {100 * amp_a:.1f}%.")
        else:
            sentence = (f"The simulator lacks {t.plain}: {coef}. Adding it {fold_words()}cuts "
                        f"the amplitude error from {100 * amp_b:.1f}% to {100 * amp_a:.1f}%.")

    cands = [{"name": "none", "probability": p_none, "coefficient": None}]
    for f, p in zip(fits, probs, strict=True):
        cands.append({"name": f.term.name, "probability": float(p),
                      "coefficient": {"median": f.median, "ci90": list(f.ci90),
                                      "units": f.term.units, "prior_scale": f.term.scale},
                      "chi2": f.chi2, "log_evidence": f.log_z,
                      "recordings_without_orbit": [mf.names[i] for i in f.lost]})
    cands.sort(key=lambda d: -d["probability"])
    data = {
        "verdict": {"kind": kind, "terms": terms, "sentence": sentence},
        "candidates": cands,
        "mismatch": {"significant": bool(sig_before), "chi2": chi0, "dof": dof0,
                     "p_value": p_before, "by_recording": loc0,
                     "after": {"significant": bool(sig_after), "by_recording": loc1}},
        "fit": {"before": fit_before, "after": fit_after},
    }
    extras = {"features": mf, "fitter": fitter, "base": base, "before": before_pts,
              "after": after_pts, "e0": e0, "probabilities": probs,
              "after_orbits": best.orbits, "after_label": f"simulator + {t.plain}"}
    return data, fits, extras
