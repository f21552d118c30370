r"""The whole analysis: compare, locate, name, model, show the improvement, give a verdict.

:func:`analyse` takes recordings and a simulator and returns a
:class:`DiscrepancyReport`:

1. **Compare.** Features of every recording (frequency, Fourier coefficients
   per channel, :mod:`~bayeshopf.discrepancy.features`) against those of the
   simulator's periodic orbit at the recording's μ on its branch, with sensor
   offsets marginalised; the simulator's Hopf point and fold; optionally the
   Bayesian hybrid fit of the recordings on the collapsed core
   (:func:`bayeshopf.posterior.fit_hybrid`, subcritical, default
   :class:`~bayeshopf.inference.collapsed.CollapsedSettings` unless others are
   given), reported with its settings and convergence (:func:`hybrid_summary`).
2. **Locate** (:mod:`~bayeshopf.discrepancy.locate`).
3. **Name.** The posterior of every library term's coefficient and the
   posterior probability of each single-term model
   (:mod:`~bayeshopf.discrepancy.select`).
4. **Model.** The most probable term at its posterior median is added to the
   simulator, its orbits, Hopf point and fold recomputed.
5. **Improvement.** RMS orbit error per channel, amplitude and frequency
   errors, Hopf and fold before and after, and the difference in expected log
   predictive density (PSIS-LOO over recordings, through
   :mod:`bayeshopf.diagnostics.arviz_io`) with its standard error.
6. **Verdict.** ``"none"`` when "nothing missing" is the most probable model
   and the misfit is within noise; ``"named"`` when the best term leaves no
   significant misfit (two terms are named when the runner-up's probability is
   within a factor :data:`TIE_FACTOR` of the best's: the data cannot tell them
   apart); ``"unexplained"`` otherwise — the mismatch is still located, and
   the best partial candidate mentioned, never forced.

A misfit is *significant* when its :math:`\chi^2` exceeds the 99.9% quantile of
the :math:`\chi^2` distribution with as many degrees of freedom as features
(less the offsets and the fitted coefficient).

**With calibration** (the default for a simulator that declares uncertain
parameters, ``System.uncertain``): steps 3–6 are those of
:func:`bayeshopf.discrepancy.calibration.calibrate`, run on the same prepared
features and nominal orbits. It calibrates the uncertain parameters as
nuisance parameters, fits the library's terms jointly with them and gives the
verdict ``"none"``, ``"parameters off"``, ``"term missing"`` or
``"unexplained"``, copied whole into the report with the calibration itself
(``"calibration"``), its models (``"models"``: none, parameters calibrated,
each term and pair of terms with probability, log evidence and coefficient)
and the parameters of the final model (``"parameters"``). The fit is
reported in up to three stages, each with the errors per channel, the Hopf
point and fold of a continuation of the model at its posterior medians, and
the :math:`\chi^2` of the residuals whitened by the recordings' noise and the
model-error floor (the same whitening for every stage; the calibration's own
:math:`\chi^2` in ``"calibration"`` may whiten with an inferred model error)
with features − offsets − the effective number of fitted parameters as
degrees of freedom: ``"before"`` (nominal), ``"calibrated"`` (the parameters'
medians, no term) and, when the verdict is ``"term missing"``, ``"after"``
(the medians of the parameters fitted with the term, or the pair of terms,
that the verdict names, and the coefficients' medians, at the orbits of that
fit). The *final model* is the last of these; the mismatch that remains with
it is located (``mismatch.after``) beside the nominal one
(``mismatch.by_recording``). ``calibrate=False`` gives the analysis above.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from bayeshopf._x64 import ensure_x64
from bayeshopf.data.recording import RecordingSet
from bayeshopf.discrepancy.features import DEFAULT_K, measure
from bayeshopf.discrepancy.locate import locate
from bayeshopf.discrepancy.orbits import OrbitBatch, solve_orbits
from bayeshopf.discrepancy.select import Fitter, TermFit, null_log_z, probabilities
from bayeshopf.discrepancy.terms import KINDS, library, library_params, library_system
from bayeshopf.errors import BayesHopfError
from bayeshopf.simulators.base import System
from bayeshopf.simulators.registry import get_system

__all__ = ["DiscrepancyReport", "TIE_FACTOR", "analyse", "hybrid_summary", "stage_rows"]

#: Two terms are reported together when their probabilities are within this factor.
TIE_FACTOR = 5.0
#: Significance level of a misfit.
ALPHA = 1e-3
N_DRAWS = 400


@dataclass(frozen=True)
class DiscrepancyReport:
    """Result of :func:`analyse` (immutable).

    Attributes:
        data: The report as JSON-serialisable dict (``report.json``).
        system: The simulator.
        fits: Posterior of every term, most probable first
            (:class:`~bayeshopf.discrepancy.select.TermFit`, or
            :class:`~bayeshopf.discrepancy.calibration.CalibratedTermFit` with
            calibration).
        extras: Arrays for the figures (orbits, diagrams, features).
        calibration: The
            :class:`~bayeshopf.discrepancy.calibration.CalibrationReport`
            (``None`` without calibration).
    """

    data: dict
    system: System = field(repr=False)
    fits: tuple[TermFit, ...] = field(repr=False, default=())
    extras: dict = field(repr=False, default_factory=dict)
    calibration: Any = field(repr=False, default=None)

    def to_json(self) -> dict:
        """The ``report.json`` structure."""
        return self.data

    @property
    def verdict(self) -> dict:
        """``{"kind", "terms", "sentence"}`` (with calibration, the calibration's verdict)."""
        return self.data["verdict"]

    def to_markdown(self) -> str:
        """``report.md``."""
        return _markdown_calibrated(self.data) if "calibration" in self.data \
            else _markdown(self.data)


def _fmt(x: float, sig: int = 3) -> str:
    return f"{x:.{sig}g}"


def _base_warm_starts(system: System, rs: RecordingSet):
    """Warm starts on the simulator's branches; ``None`` where the branch has no orbit."""
    from bayeshopf.simulators.continuation import bifurcation_diagram

    diagram = bifurcation_diagram(system)
    x0, T, note = [], [], []
    for r in rs:
        try:
            o = diagram.orbit_at(r.mu, r.branch)
            x0.append(o.x0)
            T.append(o.period)
            note.append("")
        except BayesHopfError as exc:
            b = diagram.branch(r.branch)
            i = int(np.argmin(np.abs(b.mu - r.mu)))
            x0.append(b.x0[i])
            T.append(b.period[i])
            note.append(str(exc))
    return diagram, np.stack(x0), np.array(T), note


def prepare(recordings: RecordingSet, system: System, K: int = DEFAULT_K, kinds=KINDS
            ) -> tuple[Fitter, Any, list[str]]:
    """What every analysis starts from: features, library system and the nominal orbits.

    The observed channels are measured with the planar reference first; the
    library is sized by their median amplitudes and frequency; the library
    system's orbits at the recordings, every coefficient 0, are shot from the
    nominal diagram's warm starts.

    Returns:
        ``(fitter, diagram, notes)``: the :class:`~bayeshopf.discrepancy.select.Fitter`,
        the nominal bifurcation diagram, and the warm starts' notes.
    """
    obs = system.observed
    ref = recordings.planar[0] if recordings.planar[0] in obs else obs[0]
    channels = (ref,) + tuple(c for c in obs if c != ref)
    mf = measure(recordings, channels, K=K)
    amp = dict(zip(channels, np.median(mf.amplitude, axis=0), strict=True))
    lib = library(system, amp, float(np.median(mf.y[:, 0])), kinds=kinds)
    L = library_system(system, lib)
    diagram, x0, T, notes = _base_warm_starts(system, recordings)
    stable = np.array([b == "stable" for b in mf.branch])
    base = solve_orbits(L, {**L.params, **library_params(lib)}, x0, T, mf.mu, stable)
    return Fitter(L, lib, mf, base), diagram, [n for n in notes if n]


def _points(system: System) -> dict:
    """Hopf point and folds of ``system`` (``None`` with a note where not found)."""
    from bayeshopf.simulators.continuation import continue_from_hopf

    try:
        d = continue_from_hopf(system)
    except BayesHopfError as exc:
        return {"hopf": None, "fold": None, "note": str(exc), "diagram": None}
    return {"hopf": float(d.hopf.mu), "fold": _fold(d), "folds": [float(f.mu) for f in d.folds],
            "diagram": d}


def _fold(d) -> float | None:
    """The fold of the LCO branch at the lowest μ (the saddle-node where the stable LCOs end).

    Smoothed nonsmooth terms can add tiny folds near the Hopf point; the
    engineering quantity is the lowest airspeed with an LCO.
    """
    return min(float(f.mu) for f in d.folds) if d.folds else None


def _fit_errors(fitter: Fitter, ob: OrbitBatch, loc: list[dict]) -> dict:
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


def _loglik(e: np.ndarray) -> np.ndarray:
    return -0.5 * np.sum(e**2, axis=1)


def analyse(recordings: RecordingSet, system: System | str, *, seed: int = 0,
            hybrid: bool = True, progress: bool = False, K: int = DEFAULT_K,
            kinds: tuple[str, ...] = KINDS, hybrid_settings=None,
            point_intervals: bool = True, calibrate: bool | None = None) -> DiscrepancyReport:
    """Compare recordings with a simulator, locate and name what it lacks (module docstring).

    Args:
        recordings: Stable and unstable LCO recordings (μ and branch labelled).
        system: The simulator, or its name for :func:`~bayeshopf.simulators.get_system`.
        seed: Seed of the posterior draws (and of the hybrid fit).
        hybrid: Also fit the Bayesian hybrid model to the recordings
            (:func:`bayeshopf.posterior.fit_hybrid`, subcritical) and report its
            Hopf and fold intervals, settings and convergence under ``"hybrid"``
            (:func:`hybrid_summary`; a minute or two at default settings).
        progress: Show progress bars.
        K: Harmonics per channel.
        kinds: Kinds of term in the library.
        hybrid_settings: :class:`~bayeshopf.inference.collapsed.CollapsedSettings`
            of the hybrid fit; default ``CollapsedSettings()`` (the documented
            defaults, full-length chains).
        point_intervals: Without calibration: also continue the simulator with the
            term at the ends of its coefficient's 90% interval, for 90% intervals
            of its Hopf point and fold (two more continuations; the points are
            monotone in one coefficient over so short an interval). With
            calibration the points are those of the posterior medians only.
        calibrate: Calibrate the simulator's uncertain parameters first and compare
            "nothing wrong", "parameters off" and "a term missing"
            (:func:`bayeshopf.discrepancy.calibration.calibrate`; module
            docstring, "With calibration"). ``None``: when the system declares
            uncertain parameters (``system.uncertain``); ``False``: every
            parameter nominal, single terms only.

    Raises:
        BayesHopfError: Bad recordings, an unknown simulator, one without
            extra-force input, or ``calibrate=True`` for a system that declares no
            uncertain parameters.
        TypeError: ``hybrid_settings`` that are not a ``CollapsedSettings``.
    """
    ensure_x64()
    if hybrid:
        from bayeshopf.inference.collapsed import CollapsedSettings

        if hybrid_settings is None:
            hybrid_settings = CollapsedSettings()
        elif not isinstance(hybrid_settings, CollapsedSettings):
            raise TypeError("hybrid_settings must be a bayeshopf.inference.collapsed."
                            f"CollapsedSettings; got {type(hybrid_settings).__name__}")

    t0 = time.perf_counter()
    system = get_system(system)
    if calibrate is None:
        calibrate = bool(system.uncertain)
    elif calibrate and not system.uncertain:
        from bayeshopf.discrepancy.calibration import CalibrationError

        raise CalibrationError(f"{system.name}: calibrate=True needs uncertain parameters "
                               "(System.uncertain); it declares none (use calibrate=False)")
    prepared = prepare(recordings, system, K, kinds)
    fitter = prepared[0]
    cal_report = None
    if calibrate:
        data, fits, extras, cal_report = _with_calibration(recordings, system, prepared, K=K,
                                                           kinds=kinds, progress=progress)
    else:
        data, fits, extras = _single_terms(system, prepared, seed=seed, progress=progress,
                                           point_intervals=point_intervals)
    hyb = None
    hybrid_fit = None
    if hybrid:
        from bayeshopf.posterior import fit_hybrid

        hybrid_fit = fit_hybrid(recordings, "subcritical", seed=seed, settings=hybrid_settings,
                                progress=progress)
        hyb = hybrid_summary(hybrid_fit)
    lib = fitter.lib
    settings = {"harmonics": K, "seed": seed, "hybrid": hybrid}
    if calibrate:
        settings["calibration"] = True
    data.update({
        "hybrid": hyb,
        "simulator": system.name,
        "library": {"terms": list(lib.names), "skipped": dict(lib.skipped),
                    "typical_amplitude": dict(lib.amplitude)},
        "settings": settings,
        "notes": [n for n in prepared[2] if n],
        "runtime_s": time.perf_counter() - t0,
    })
    extras["hybrid"] = hybrid_fit
    return DiscrepancyReport(data=data, system=system, fits=tuple(fits), extras=extras,
                             calibration=cal_report)


def _worst_words(loc: list[dict], system: System) -> str:
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


def _single_terms(system: System, prepared, *, seed: int, progress: bool,
                  point_intervals: bool) -> tuple[dict, list, dict]:
    """Every parameter nominal, each library term alone (module docstring, steps 1–6).

    Returns:
        ``(data, fits, extras)``: the report's ``verdict``, ``candidates``,
        ``mismatch`` and ``fit``; the term fits, most probable first; the arrays
        for the figures.
    """
    from tqdm.auto import tqdm

    from bayeshopf.diagnostics import arviz_io

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
    before_pts = _diagram_points(diagram)
    if not best_is_none:
        after_pts = _points(L.with_params(**library_params(lib), **{t.param: best.median}))
        if point_intervals:
            ends = [_points(L.with_params(**library_params(lib), **{t.param: c}))
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

    fit_before = _fit_errors(fitter, base, loc0)
    fit_after = _fit_errors(fitter, best.orbits, loc1)
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

    where = _worst_words(loc0, system)
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
              "after_orbits": best.orbits, "after_label": f"simulator + {t.name}"}
    return data, fits, extras


def _diagram_points(diagram) -> dict:
    """Hopf point, lowest fold and folds of a computed diagram (as :func:`_points`)."""
    return {"hopf": float(diagram.hopf.mu), "fold": _fold(diagram),
            "folds": [float(f.mu) for f in diagram.folds], "diagram": diagram}


def _stage(fitter: Fitter, ob: OrbitBatch, p_eff: float, pts: dict) -> tuple[dict, list[dict]]:
    r"""One model's fit: errors per channel (:func:`_fit_errors`), χ², Hopf and fold; its mismatch.

    The :math:`\chi^2` is that of ``fitter``'s whitened residuals (the recordings'
    noise and the model-error floor of :mod:`~bayeshopf.discrepancy.select`),
    the same for every stage, with features − offsets − ``p_eff`` degrees of
    freedom.

    Args:
        fitter: The residuals' definition.
        ob: The model's orbits at the recordings.
        p_eff: Its effective number of fitted parameters.
        pts: Its Hopf point and folds (:func:`_points`).

    Returns:
        ``(fit, located)``: the report's stage dict and :func:`locate`'s rows.
    """
    mf = fitter.mf
    e = fitter.residuals(ob)
    loc = locate(mf.layout, mf.y, fitter.features(ob), e, fitter.offsets(ob), mf.names, mf.mu,
                 mf.branch, ob.ok)
    chi2 = float(np.sum(e**2))
    dof = float(mf.y.size - len(mf.layout.channels) - p_eff)
    out = _fit_errors(fitter, ob, loc)
    out.update(hopf=pts["hopf"], fold=pts["fold"], folds=pts.get("folds"), chi2=chi2,
               dof=dof, p_value=float(stats.chi2.sf(chi2, dof)), p_eff=float(p_eff),
               note=pts.get("note"))
    return out, loc


def _named_model(rep) -> dict | None:
    """The model with terms that a calibration's verdict names, or ``None``.

    The verdict's ``model`` when it names a pair of terms fitted jointly
    (``"<term>+<term>"`` among ``rep.pairs``) or one term; otherwise the first
    of its ``terms``, or the most probable term. ``None`` unless the verdict is
    ``"term missing"``, or when the model has no orbits.

    Returns:
        ``{"name", "terms": [(Term, median, ci90)], "parameters", "orbits", "p_eff"}``.
    """
    from bayeshopf.discrepancy.calibration import KIND_TERM

    v = rep.verdict
    if v.get("kind") != KIND_TERM or not rep.terms:
        return None
    model = v.get("model")
    pair = next((f for f in getattr(rep, "pairs", ()) if model and f.name == model), None)
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


def _with_calibration(recordings: RecordingSet, system: System, prepared, *, K: int,
                      kinds: tuple[str, ...], progress: bool) -> tuple[dict, tuple, dict, Any]:
    """The uncertain parameters calibrated first (module docstring, "With calibration").

    Returns:
        ``(data, fits, extras, calibration_report)``: the report's ``verdict``,
        ``parameters``, ``models``, ``mismatch``, ``fit``, ``final_model`` and
        ``calibration``; the terms fitted with the parameters, most probable
        first; the arrays for the figures; the
        :class:`~bayeshopf.discrepancy.calibration.CalibrationReport`.
    """
    from bayeshopf.discrepancy.calibration import calibrate as run_calibration

    fitter, diagram, _ = prepared
    mf, lib, L = fitter.mf, fitter.lib, fitter.system
    rep = run_calibration(recordings, system, kinds=kinds, K=K, progress=progress,
                          prepared=prepared)
    cal = rep.calibration
    verdict = dict(rep.verdict)

    before_pts = _diagram_points(diagram)
    fit_before, loc0 = _stage(fitter, fitter.base, 0.0, before_pts)
    cal_values = cal.values()
    cal_pts = _points(system.with_params(**cal_values))
    fit_cal, loc_cal = _stage(fitter, cal.orbits, cal.p_eff, cal_pts)
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
        after_pts = _points(L.with_params(**library_params(lib), **params, **coefs))
        fit_after, loc_final = _stage(fitter, named["orbits"], named["p_eff"], after_pts)
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
                      after_label=f"simulator calibrated + {named['name']}",
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
                     "recordings." + _worst_words(loc_final, system))
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
    for f in rep.terms:
        models.append({
            "name": f.term.name, "label": f.term.name,
            "probability": float(rep.probabilities[f.term.name]), "log_evidence": f.log_z,
            "chi2": f.chi2, "coefficient": {"median": f.median, "ci90": list(f.ci90),
                                            "units": f.term.units,
                                            "prior_scale": f.term.scale},
            "refined": f.refined, "separability": f.separability,
            "parameters_off": [p.name for p in f.parameters if p.off],
            "recordings_without_orbit": [mf.names[i] for i in f.lost]})
    for f in getattr(rep, "pairs", ()):                          # two terms fitted jointly
        models.append({
            "name": f.name, "label": f.name, "probability": float(rep.probabilities[f.name]),
            "log_evidence": f.log_z, "chi2": f.chi2, "coefficient": None,
            "coefficients": [{"name": t.name, "median": m, "ci90": list(ci), "units": t.units}
                             for t, m, ci in zip(f.terms, f.medians, f.ci90, strict=True)],
            "refined": f.refined, "parameters_off": [p.name for p in f.parameters if p.off]})
    models[2:] = sorted(models[2:], key=lambda m: -m["probability"])
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


def _interval(iv) -> dict | None:
    return None if iv is None else {"median": float(iv.median),
                                    "ci90": [float(iv.lo), float(iv.hi)]}


def hybrid_summary(post) -> dict:
    """The report's ``"hybrid"`` entry for a :class:`~bayeshopf.posterior.HybridPosterior`.

    * ``hopf``, ``fold``: median and 90% interval of ``mu0`` and ``mu_fold``
      (``None`` where the model has no such site);
    * ``settings``: the :class:`~bayeshopf.inference.collapsed.CollapsedSettings`
      used, as a dict; ``seed``;
    * ``convergence``: compact form of ``post.diagnostics``: the method, the MAP's
      gradient norm and whether it converged; for NUTS the chains, divergences,
      the largest R̂ and smallest bulk ESS over the checked sites with the
      thresholds, and R̂/ESS per site; for SVI whether the ELBO reached a
      plateau; ``ok`` when every check passed;
    * ``warnings``: every warning line of the diagnostics (convergence and fit);
    * ``seconds``: wall time per stage.
    """
    import dataclasses

    diag = post.diagnostics or {}
    mp = diag.get("map", {})
    po = diag.get("posterior", {})
    conv: dict[str, Any] = {"method": po.get("method"),
                            "map_grad_norm": mp.get("grad_norm"),
                            "map_converged": bool(mp.get("converged", False))}
    ok = conv["map_converged"]
    if po.get("method") == "nuts":
        sites = po.get("sites", {})
        r = [v["r_hat"] for v in sites.values()]
        e = [v["ess_bulk"] for v in sites.values()]
        conv.update(chains=po.get("chains"), divergences=int(po.get("divergences", 0)),
                    r_hat=max(r) if r else None, ess_bulk=min(e) if e else None,
                    r_hat_limit=po.get("r_hat_max"), ess_limit=po.get("ess_min"),
                    sites={k: {"r_hat": float(v["r_hat"]), "ess_bulk": float(v["ess_bulk"])}
                           for k, v in sites.items()})
        # a single chain has no R̂: not checked, so not passed
        ok = ok and bool(sites) and all(v["ok"] for v in sites.values()) \
            and conv["divergences"] == 0
    elif po.get("method") == "svi":
        pl = po.get("elbo_plateau", {})
        conv.update(elbo_plateau=bool(pl.get("plateau", False)), steps=po.get("steps"))
        ok = ok and conv["elbo_plateau"]
    conv["ok"] = bool(ok)
    return {"hopf": _interval(post.interval("mu0")), "fold": _interval(post.interval("mu_fold")),
            "settings": dataclasses.asdict(post.settings), "seed": int(post.seed),
            "convergence": conv, "warnings": list(diag.get("warnings", [])),
            "seconds": {k: float(v) for k, v in post.timings.items()}}


def _hybrid_markdown(h: dict) -> list[str]:
    lines = ["", "## Bayesian hybrid fit of the recordings", ""]
    for k in ("hopf", "fold"):
        if h.get(k):
            lines.append(f"* {k}: {h[k]['median']:.3f} (90% {h[k]['ci90'][0]:.3f} – "
                         f"{h[k]['ci90'][1]:.3f})")
    s, c = h.get("settings") or {}, h.get("convergence") or {}
    if c.get("method") == "nuts":
        lines.append(f"* NUTS, {s.get('num_chains')} chains × {s.get('num_samples')} draws "
                     f"({s.get('num_warmup')} warm-up): largest R̂ {c['r_hat']:.3f} "
                     f"(limit {c['r_hat_limit']}), smallest bulk ESS {c['ess_bulk']:.0f} "
                     f"(limit {c['ess_limit']}), {c['divergences']} divergences"
                     if c.get("r_hat") is not None else
                     f"* NUTS, {s.get('num_chains')} chain(s): R̂ not computed")
    elif c.get("method") == "svi":
        lines.append(f"* SVI, {s.get('svi_steps')} steps: ELBO "
                     + ("at a plateau" if c.get("elbo_plateau") else "still falling"))
    if c:
        lines.append(f"* converged: {'yes' if c.get('ok') else '**no**'}")
    for w in h.get("warnings", []):
        lines.append(f"* warning: {w}")
    return lines


def _markdown(d: dict) -> str:
    v = d["verdict"]
    lines = [f"# Discrepancy analysis: {d['simulator']}", "", f"**Verdict ({v['kind']}).** "
             f"{v['sentence']}", "", "## Candidates (most probable first)", "",
             "| model | probability | coefficient median | 90% interval | units |",
             "|---|---:|---:|---|---|"]
    for c in d["candidates"][:8]:
        co = c["coefficient"]
        if co is None:
            lines.append(f"| none | {c['probability']:.3g} | | | |")
        else:
            lines.append(f"| {c['name']} | {c['probability']:.3g} | {co['median']:.4g} | "
                         f"{co['ci90'][0]:.4g} – {co['ci90'][1]:.4g} | {co['units']} |")
    fb, fa = d["fit"]["before"], d["fit"]["after"]

    def g(x, pct=False):
        if x is None:
            return "–"
        return f"{100 * x:.2f}%" if pct else f"{x:.4g}"

    def ci(v):
        return "" if not v else f" (90% {v[0]:.4g} – {v[1]:.4g})"

    lines += ["", f"## Fit before and after adding {fa['term']}", "",
              "| quantity | before | after |", "|---|---:|---:|"]
    for c in fb["rms_orbit_error"]:
        lines.append(f"| RMS orbit error {c} | {g(fb['rms_orbit_error'][c], True)} | "
                     f"{g(fa['rms_orbit_error'][c], True)} |")
        lines.append(f"| amplitude error {c} | {g(fb['amplitude_error'][c], True)} | "
                     f"{g(fa['amplitude_error'][c], True)} |")
    lines += [f"| frequency error | {g(fb['frequency_error'], True)} | "
              f"{g(fa['frequency_error'], True)} |",
              f"| Hopf point | {g(fb['hopf'])} | {g(fa['hopf'])}{ci(fa.get('hopf_ci90'))} |",
              f"| fold | {g(fb['fold'])} | {g(fa['fold'])}{ci(fa.get('fold_ci90'))} |",
              f"| chi² / features | {fb['chi2']:.1f} / {fb['dof']} | {fa['chi2']:.1f} / "
              f"{fa['dof']} |"]
    if fa.get("elpd_difference") is not None:
        lines.append(f"| ELPD after − before | | {fa['elpd_difference']:.1f} ± "
                     f"{fa['elpd_difference_se']:.1f} |")
    if d.get("hybrid"):
        lines += _hybrid_markdown(d["hybrid"])
    lines += ["", "## Where the simulator disagrees (before)", ""]
    lines += _mismatch_table(d["mismatch"]["by_recording"])
    if d["notes"]:
        lines += ["", "## Notes", ""] + [f"* {n}" for n in d["notes"]]
    return "\n".join(lines) + "\n"


def _mismatch_table(rows: list[dict]) -> list[str]:
    """Markdown table of :func:`locate`'s rows."""
    lines = ["| recording | μ | branch | worst channel | amplitude error | frequency error | "
             "phase range (°) | where | phase to reference: simulated − measured (°) | "
             "significant |", "|---|---:|---|---|---:|---:|---|---|---|---|"]
    for r in rows:
        if r["channel"] is None:
            lines.append(f"| {r['file']} | {r['mu']:g} | {r['branch']} | – | – | – | – | "
                         f"{r['where']} | – | yes |")
            continue
        lines.append(f"| {r['file']} | {r['mu']:g} | {r['branch']} | {r['channel']} | "
                     f"{100 * r['amplitude_error']:.2f}% | {100 * r['frequency_error']:.3f}% | "
                     f"{r['phase_range'][0]:.0f}–{r['phase_range'][1]:.0f} | {r['where']} | "
                     + ", ".join(f"{c} {v['phase_to_reference_deg']['error']:+.1f}"
                                 for c, v in r["channels"].items()
                                 if v.get("phase_to_reference_deg")) + " | "
                     f"{'yes' if r['significant'] else 'no'} |")
    return lines


#: Column titles of the fit stages with calibration.
STAGE_TITLES = {"before": "nominal", "calibrated": "calibrated", "after": "calibrated + term"}


def _pct_or_dash(x, digits: int = 2) -> str:
    return "–" if x is None else f"{100 * x:.{digits}f}%"


def _num_or_dash(x) -> str:
    return "–" if x is None else f"{x:.4g}"


def stage_rows(d: dict) -> tuple[list[str], list[tuple[str, list[str]]]]:
    """The fit stages of a calibrated report as a table: titles and ``(quantity, cells)`` rows.

    Args:
        d: ``report.json`` of an analysis with calibration.

    Returns:
        The stage titles (``nominal``, ``calibrated``, ``calibrated + <term>``
        where a term was added) and, per quantity, one formatted cell per stage:
        amplitude and RMS orbit error per channel, frequency error, Hopf point,
        fold, χ² / degrees of freedom and recordings without an orbit.
    """
    fit = d["fit"]
    keys = [k for k in STAGE_TITLES if k in fit]
    titles = [STAGE_TITLES[k] if k != "after" else f"calibrated + {fit['after']['term']}"
              for k in keys]
    st = [fit[k] for k in keys]
    rows = []
    for c in st[0]["amplitude_error"]:
        rows.append((f"amplitude error {c}", [_pct_or_dash(s["amplitude_error"][c]) for s in st]))
    for c in st[0]["rms_orbit_error"]:
        rows.append((f"RMS orbit error {c}", [_pct_or_dash(s["rms_orbit_error"][c]) for s in st]))
    rows += [("frequency error", [_pct_or_dash(s["frequency_error"], 3) for s in st]),
             ("Hopf point", [_num_or_dash(s["hopf"]) for s in st]),
             ("fold", [_num_or_dash(s["fold"]) for s in st]),
             ("chi² / dof", [f"{s['chi2']:.4g} / {s['dof']:.4g}" for s in st]),
             ("recordings without orbit",
              [str(len(s["recordings_without_orbit"])) for s in st])]
    return titles, rows


def _markdown_calibrated(d: dict) -> str:
    """``report.md`` of an analysis with calibration."""
    v = d["verdict"]
    prob = f", probability {v['probability']:.2f}" if v.get("probability") is not None else ""
    lines = [f"# Discrepancy analysis: {d['simulator']}", "",
             f"**Verdict ({v['kind']}{prob}).** {v['sentence']}", "",
             f"## Uncertain parameters ({d['parameters']['model']})", "",
             "| parameter | units | nominal | median | 90% interval | shift | off |",
             "|---|---|---:|---:|---|---:|---|"]
    for p in d["parameters"]["table"]:
        lines.append(f"| {p['name']} | {p['units']} | {p['nominal']:.5g} | {p['median']:.5g} | "
                     f"{p['ci90'][0]:.5g} – {p['ci90'][1]:.5g} | {100 * p['shift']:+.2f}% | "
                     f"{'**yes**' if p['off'] else 'no'} |")
    lines += ["", "## Models (most probable terms)", "",
              "| model | probability | log evidence | coefficient median | 90% interval | "
              "units |",
              "|---|---:|---:|---:|---|---|"]
    for m in d["models"][:7]:
        co = m["coefficient"]
        if m.get("coefficients"):
            cs = m["coefficients"]
            lines.append(f"| {m['label']}{'' if m['refined'] else ' (screened)'} | "
                         f"{m['probability']:.3g} | {m['log_evidence']:.1f} | "
                         + "; ".join(f"{c['median']:.4g}" for c in cs) + " | "
                         + "; ".join(f"{c['ci90'][0]:.4g} – {c['ci90'][1]:.4g}" for c in cs)
                         + " | " + "; ".join(c["units"] for c in cs) + " |")
        elif co is None:
            lines.append(f"| {m['label']} | {m['probability']:.3g} | "
                         f"{m['log_evidence']:.1f} | | | |")
        else:
            lines.append(f"| {m['label']}{'' if m['refined'] else ' (screened)'} | "
                         f"{m['probability']:.3g} | {m['log_evidence']:.1f} | {co['median']:.4g} | "
                         f"{co['ci90'][0]:.4g} – {co['ci90'][1]:.4g} | {co['units']} |")
    titles, rows = stage_rows(d)
    lines += ["", "## Fit: " + ", ".join(titles), "",
              "| quantity | " + " | ".join(titles) + " |",
              "|---|" + "---:|" * len(titles)]
    lines += [f"| {q} | " + " | ".join(cells) + " |" for q, cells in rows]
    for k in d["fit"]:
        if d["fit"][k].get("note"):
            lines.append(f"\n{STAGE_TITLES.get(k, k)}: {d['fit'][k]['note']}")
    if d.get("hybrid"):
        lines += _hybrid_markdown(d["hybrid"])
    rem = d["mismatch"]["after"]
    lines += ["", f"## What remains ({rem['model']})", "", rem["sentence"], ""]
    lines += _mismatch_table(rem["by_recording"])
    lines += ["", "## Where the nominal simulator disagrees", ""]
    lines += _mismatch_table(d["mismatch"]["by_recording"])
    if d["notes"]:
        lines += ["", "## Notes", ""] + [f"* {n}" for n in d["notes"]]
    return "\n".join(lines) + "\n"
