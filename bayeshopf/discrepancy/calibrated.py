r"""The analysis with calibration: the report of the calibration, stage by stage.

Steps 3–6 of :mod:`bayeshopf.discrepancy.analysis` for a simulator that
declares uncertain parameters: the calibration's verdict copied whole, its
models, the parameters of the final model, and the fit in up to three stages
(:mod:`~bayeshopf.discrepancy.stages`): ``"before"`` (nominal),
``"calibrated"`` (the parameters' medians, no term) and, when the verdict is
``"term missing"``, ``"after"`` (the parameters and coefficients fitted with
the term, or pair of terms, that the verdict names). The mismatch that
remains with the final model is located beside the nominal one.
"""

from __future__ import annotations

from typing import Any

from bayeshopf.data.recording import RecordingSet
from bayeshopf.discrepancy import calibration
from bayeshopf.discrepancy.prepare import Prepared
from bayeshopf.discrepancy.records import KIND_TERM, CalibratedTermFit, CalibrationReport
from bayeshopf.discrepancy.select import ALPHA
from bayeshopf.discrepancy.stages import diagram_points, fit_stage, points, worst_words
from bayeshopf.discrepancy.terms import library_params
from bayeshopf.simulators.base import System

__all__ = ["with_calibration"]


def _named_model(rep: CalibrationReport) -> dict | None:
    """The model with terms that a calibration's verdict names, or ``None``.

    The verdict's ``model`` when it names a pair of terms fitted jointly
    (``"<term>+<term>"`` among ``rep.pairs``) or one term; otherwise the first
    of its ``terms``, or the most probable term. ``None`` unless the verdict is
    ``"term missing"``, or when the model has no orbits.

    Returns:
        ``{"name", "terms": [(Term, median, ci90)], "parameters", "orbits", "p_eff"}``.
    """
    v = rep.verdict
    if v.get("kind") != KIND_TERM or not rep.terms:
        return None
    model = v.get("model")
    pair = next((f for f in rep.pairs if model and f.name == model), None)
    if pair is not None:
        out = {"name": pair.name, "terms": list(zip(pair.terms, pair.medians, pair.ci90,
                                                    strict=True)),
               "parameters": pair.parameters, "orbits": pair.orbits, "p_eff": pair.p_eff}
    else:
        names = [model] + list(v.get("terms") or [])
        f = next((f for n in names for f in rep.terms if f.term.name == n), rep.terms[0])
        out = {"name": f.term.name, "terms": [(f.term, f.median, f.ci90)],
               "parameters": f.parameters, "orbits": f.orbits, "p_eff": f.p_eff}
    return out if out["orbits"] is not None else None


def with_calibration(recordings: RecordingSet, system: System, prepared: Prepared, *, K: int,
                     kinds: tuple[str, ...], progress: bool
                     ) -> tuple[dict, tuple[CalibratedTermFit, ...], dict, CalibrationReport]:
    """The uncertain parameters calibrated first (module docstring).

    Returns:
        ``(data, fits, extras, calibration_report)``: the report's ``verdict``,
        ``parameters``, ``models``, ``mismatch``, ``fit``, ``final_model`` and
        ``calibration``; the terms fitted with the parameters, most probable
        first; the arrays for the figures; the
        :class:`~bayeshopf.discrepancy.calibration.CalibrationReport`.
    """
    fitter, diagram, _ = prepared
    mf, lib, L = fitter.mf, fitter.lib, fitter.system
    rep = calibration.calibrate(recordings, system, kinds=kinds, K=K, progress=progress,
                          prepared=prepared)
    cal = rep.calibration
    verdict = dict(rep.verdict)

    before_pts = diagram_points(diagram)
    fit_before, loc0 = fit_stage(fitter, fitter.base, 0.0, before_pts)
    cal_values = cal.values()
    # on the library system with no term (the calibrated simulator itself), whose
    # continuation programs the final model's diagram below then reuses
    cal_pts = points(L.with_params(**library_params(lib), **cal_values))
    fit_cal, loc_cal = fit_stage(fitter, cal.orbits, cal.p_eff, cal_pts)
    fit_cal["parameters"] = cal_values
    stages = {"before": fit_before, "calibrated": fit_cal}
    extras: dict[str, Any] = {
        "features": mf, "fitter": fitter, "base": fitter.base, "before": before_pts,
        "before_label": "simulator, nominal", "e0": fitter.residuals(fitter.base),
        "calibration": rep, "calibrated": cal_pts}
    named = _named_model(rep)
    if named is not None:
        params = {p.name: p.median for p in named["parameters"]}
        coefs = {t.param: m for t, m, _ in named["terms"]}
        after_pts = points(L.with_params(**library_params(lib), **params, **coefs))
        fit_after, loc_final = fit_stage(fitter, named["orbits"], named["p_eff"], after_pts)
        fit_after.update(term=named["name"],
                         terms=[{"name": t.name, "median": m, "ci90": list(ci), "units": t.units}
                                for t, m, ci in named["terms"]], parameters=params)
        if len(named["terms"]) == 1:
            fit_after.update(coefficient=named["terms"][0][1],
                             coefficient_ci90=list(named["terms"][0][2]))
        stages["after"] = fit_after
        stage, label = "after", f"calibrated + {named['name']}"
        final_params = named["parameters"]
        extras.update(after=after_pts, after_orbits=named["orbits"],
                      after_label="simulator calibrated + "
                      + " and ".join(t.plain for t, _, _ in named["terms"]),
                      intermediate={"label": "simulator calibrated", "diagram":
                                    cal_pts.get("diagram"), "orbits": cal.orbits})
    else:
        stage, label, final_params, loc_final = "calibrated", "calibrated", cal.parameters, loc_cal
        extras.update(after=cal_pts, after_orbits=cal.orbits, after_label="simulator calibrated")
    final = stages[stage]

    # ------------------------------------------------ what remains, where
    chi0, dof0 = fit_before["chi2"], int(round(fit_before["dof"]))
    # the calibration's inferred model error decides whether a mismatch remains
    me = rep.verdict["model_error"]["final"]
    sig_final = bool(rep.verdict["remaining"]["significant"])
    n_sig = sum(bool(r["significant"]) for r in loc_final)
    err = (f"model error {100 * me['median']:.2g}% of the orbit amplitude (90% "
           f"{100 * me['ci90'][0]:.2g}–{100 * me['ci90'][1]:.2g}%)")
    if sig_final:
        remaining = (f"A smaller mismatch remains with the {label} simulator: {err}; "
                     f"significant at the recordings' noise in {n_sig} of {len(loc_final)} "
                     "recordings." + worst_words(loc_final, system))
    else:
        remaining = (f"With the {label} simulator what remains is within the recordings' "
                     f"noise ({err}).")

    models = [
        {"name": "none", "label": "none (nominal parameters)",
         "probability": float(rep.probabilities["none"]),
         "log_evidence": float(rep.log_z["none"]), "chi2": float(rep.chi2_nominal),
         "coefficient": None},
        {"name": "parameters", "label": "parameters calibrated",
         "probability": float(rep.probabilities["parameters"]),
         "log_evidence": float(rep.log_z["parameters"]), "chi2": float(cal.chi2),
         "coefficient": None, "parameters_off": list(cal.off)}]
    if rep.unexplained is not None:
        models.append({
            "name": "unexplained", "label": "parameters calibrated + smooth discrepancy",
            "probability": float(rep.probabilities["unexplained"]),
            "log_evidence": float(rep.log_z["unexplained"]), "chi2": float(cal.chi2),
            "coefficient": None, "discrepancy": rep.unexplained.to_json()})
    n_fixed = len(models)
    for f in rep.terms:
        models.append({
            "name": f.term.name, "label": f.term.name,
            "probability": float(rep.probabilities[f.term.name]), "log_evidence": f.log_z,
            "chi2": f.chi2, "coefficient": {"median": f.median, "ci90": list(f.ci90),
                                            "units": f.term.units,
                                            "prior_scale": f.term.scale},
            "refined": f.refined, "separability": f.separability, "evidence": f.evidence,
            "parameters_off": [p.name for p in f.parameters if p.off],
            "recordings_without_orbit": [mf.names[i] for i in f.lost]})
    for f in rep.pairs:                          # two terms fitted jointly
        models.append({
            "name": f.name, "label": f.name, "probability": float(rep.probabilities[f.name]),
            "log_evidence": f.log_z, "chi2": f.chi2, "coefficient": None,
            "coefficients": [{"name": t.name, "median": m, "ci90": list(ci), "units": t.units}
                             for t, m, ci in zip(f.terms, f.medians, f.ci90, strict=True)],
            "refined": f.refined, "evidence": f.evidence,
            "parameters_off": [p.name for p in f.parameters if p.off]})
    models[n_fixed:] = sorted(models[n_fixed:], key=lambda m: -m["probability"])
    data = {
        "verdict": verdict,
        "parameters": {"model": label, "table": [p.to_json() for p in final_params]},
        "models": models,
        "mismatch": {"significant": bool(fit_before["p_value"] < ALPHA), "chi2": chi0,
                     "dof": dof0, "p_value": fit_before["p_value"], "by_recording": loc0,
                     "after": {"model": label, "stage": stage, "significant": bool(sig_final),
                               "chi2": final["chi2"], "dof": final["dof"],
                               "p_value": final["p_value"], "sentence": remaining,
                               "by_recording": loc_final}},
        "fit": stages,
        "final_model": {"stage": stage, "label": label},
        "calibration": rep.to_json(),
    }
    return data, rep.terms, extras, rep
