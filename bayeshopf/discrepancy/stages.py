r"""One model's fit to the recordings, as the discrepancy report gives it.

A *stage* is a model (the nominal simulator, the calibrated one, one with a
term added) compared with the recordings: RMS orbit, amplitude and frequency
errors per channel (:func:`fit_errors`), its Hopf point and folds
(:func:`points`, :func:`diagram_points`), the :math:`\chi^2` of its whitened
residuals (:func:`fit_stage`) and where the mismatch sits
(:func:`~bayeshopf.discrepancy.locate.locate`, :func:`worst_words`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import stats

from bayeshopf.discrepancy.locate import locate
from bayeshopf.discrepancy.orbits import OrbitBatch
from bayeshopf.discrepancy.select import Fitter
from bayeshopf.errors import BayesHopfError
from bayeshopf.simulators.base import System
from bayeshopf.simulators.continuation import BifurcationDiagram, continue_from_hopf

__all__ = ["diagram_points", "fit_errors", "fit_stage", "fold", "points", "worst_words"]


def points(system: System) -> dict:
    """Hopf point and folds of ``system`` (``None`` with a note where not found)."""
    try:
        d = continue_from_hopf(system)
    except BayesHopfError as exc:
        return {"hopf": None, "fold": None, "note": str(exc), "diagram": None}
    return {"hopf": float(d.hopf.mu), "fold": fold(d), "folds": [float(f.mu) for f in d.folds],
            "diagram": d}


def fold(d: BifurcationDiagram) -> float | None:
    """The fold of the LCO branch at the lowest μ (the saddle-node where the stable LCOs end).

    Smoothed nonsmooth terms can add tiny folds near the Hopf point; the
    engineering quantity is the lowest airspeed with an LCO.
    """
    return min(float(f.mu) for f in d.folds) if d.folds else None


def fit_errors(fitter: Fitter, ob: OrbitBatch, loc: list[dict]) -> dict:
    """RMS orbit and amplitude errors per channel, mean frequency error, recordings lost.

    Args:
        fitter: The recordings' features.
        ob: The model's orbits at the recordings.
        loc: :func:`~bayeshopf.discrepancy.locate.locate`'s rows for them.
    """
    ok = ob.ok
    chans = fitter.mf.layout.channels
    out: dict[str, Any] = {"rms_orbit_error": {}, "amplitude_error": {}}
    for c in chans:
        vals = [r["channels"][c] for r in loc if r["channels"]]
        out["rms_orbit_error"][c] = float(np.sqrt(np.mean([v["rms_error"] ** 2 for v in vals])))\
            if vals else None
        out["amplitude_error"][c] = float(np.mean([abs(v["amplitude_error"]) for v in vals])) \
            if vals else None
    fe = [abs(r["frequency_error"]) for r in loc if r["frequency_error"] is not None]
    out["frequency_error"] = float(np.mean(fe)) if fe else None
    out["recordings_without_orbit"] = [fitter.mf.names[i] for i in np.nonzero(~ok)[0]]
    return out


def diagram_points(diagram: BifurcationDiagram) -> dict:
    """Hopf point, lowest fold and folds of a computed diagram (as :func:`points`)."""
    return {"hopf": float(diagram.hopf.mu), "fold": fold(diagram),
            "folds": [float(f.mu) for f in diagram.folds], "diagram": diagram}


def fit_stage(fitter: Fitter, ob: OrbitBatch, p_eff: float, pts: dict) -> tuple[dict, list[dict]]:
    r"""One model's fit: errors per channel (:func:`fit_errors`), χ², Hopf and fold; its mismatch.

    The :math:`\chi^2` is that of ``fitter``'s whitened residuals (the recordings'
    noise and the model-error floor of :mod:`~bayeshopf.discrepancy.select`),
    the same for every stage, with features − offsets − ``p_eff`` degrees of
    freedom.

    Args:
        fitter: The residuals' definition.
        ob: The model's orbits at the recordings.
        p_eff: Its effective number of fitted parameters.
        pts: Its Hopf point and folds (:func:`points`).

    Returns:
        ``(fit, located)``: the report's stage dict and
        :func:`~bayeshopf.discrepancy.locate.locate`'s rows.
    """
    mf = fitter.mf
    e = fitter.residuals(ob)
    loc = locate(mf.layout, mf.y, fitter.features(ob), e, fitter.offsets(ob), mf.names, mf.mu,
                 mf.branch, ob.ok)
    chi2 = float(np.sum(e**2))
    dof = float(mf.y.size - len(mf.layout.channels) - p_eff)
    out = fit_errors(fitter, ob, loc)
    out.update(hopf=pts["hopf"], fold=pts["fold"], folds=pts.get("folds"), chi2=chi2,
               dof=dof, p_value=float(stats.chi2.sf(chi2, dof)), p_eff=float(p_eff),
               note=pts.get("note"))
    return out, loc


def worst_words(loc: list[dict], system: System) -> str:
    """" The largest mismatch is in …" for the recording of largest χ² in ``loc`` ("" if none)."""
    p_unit = f" {system.parameter_units}" if system.parameter_units else ""
    worst = max((r for r in loc if r["channels"] or r["channel"] is None),
                key=lambda r: (r["channels"][r["channel"]]["chi2"] if r["channel"] else np.inf),
                default=None)
    if worst is None or worst["channel"] is None:
        return ""
    return (f" The largest mismatch is in {worst['channel']} at {system.parameter} = "
            f"{worst['mu']:g}{p_unit} ({worst['branch']} branch), amplitude error "
            f"{100 * worst['amplitude_error']:.1f}%, phase "
            f"{worst['phase_range'][0]:.0f}–{worst['phase_range'][1]:.0f}°"
            + (f", {worst['where']}" if worst["where"] else "") + ".")

