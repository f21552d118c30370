r"""The calibration's verdict: which class of model, what remains, in one paragraph.

Of the four classes "nothing wrong" (:math:`M_0`), "parameters off"
(:math:`M_P`), "a term missing" and "unexplained" (:math:`M_D`: the calibrated
simulator with a smooth discrepancy, :mod:`~bayeshopf.discrepancy.unexplained`),
the verdict is the most probable, with its most probable model. A **mismatch
remains** when the 90% interval of the relative model error :math:`\tau`
under that model lies above :data:`MIN_MODEL_ERROR` (a reporting threshold,
not part of the evidence); it is located (:func:`located`: the recordings and
channels that carry most of the misfit at that :math:`\tau`) and reported
with the verdict. Models within a factor
:data:`~bayeshopf.discrepancy.select.TIE_FACTOR` of the best one in
probability are named with it: the data cannot tell them apart
(``verdict["indistinguishable"]``), whether they are two terms, a term and a
pair, or a term and a recalibration of the parameters. A parameter named off
whose force is that of a library term left out of the candidates
(:attr:`~bayeshopf.discrepancy.terms.Library.duplicates`: ``k_alpha3`` and
``alpha_cubic_stiffness``) is named with it ("equivalently: cubic stiffness in
pitch"; ``verdict["equivalent_terms"]``).

**Bayes factors** (:func:`with_bayes_factors`). Beside the class
probabilities the verdict gives each class's log Bayes factor against
"nothing wrong" and against "parameters off" and the prior probabilities used
(``verdict["bayes_factors"]``), and for the most probable terms the log Bayes
factor against "parameters off" with every term's prior scale halved and
doubled (``verdict["prior_sensitivity"]``;
:mod:`~bayeshopf.discrepancy.nested`). Where that band crosses 0 for the
model the verdict rests on, the sentence says the prior scales decide it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from bayeshopf.discrepancy.evidence import _at_tau
from bayeshopf.discrepancy.records import (
    KIND_NONE,
    KIND_PARAMS,
    KIND_TERM,
    KIND_UNEXPLAINED,
    CalibratedPairFit,
    CalibratedTermFit,
    Calibration,
    ModelError,
    ParameterPosterior,
    Unexplained,
)
from bayeshopf.discrepancy.select import TIE_FACTOR, Fitter
from bayeshopf.discrepancy.terms import Library
from bayeshopf.simulators.base import System

__all__ = ["MIN_MODEL_ERROR", "band_words", "build_verdict", "located",
           "with_bayes_factors", "with_notes"]

#: A model error whose 90% interval lies above this (0.1% of the amplitude) remains: a
#: reporting threshold, not part of the evidence, above the agreement of the feature
#: estimator and the shooting solver on exact-model simulated records.
MIN_MODEL_ERROR = 1e-3


def _pct(p: ParameterPosterior, lib: Library | None = None) -> str:
    lo, hi = (100 * (v / p.nominal - 1) for v in p.ci90)
    same = [t.plain for t, par in (lib.duplicates if lib is not None else ()) if par == p.name]
    return (f"{p.name} {100 * p.shift:+.1f}% (90% {lo:+.1f}% to {hi:+.1f}%"
            + (f"; equivalently: {' or '.join(same)}" if same else "") + ")")


def located(fitter: Fitter, e: np.ndarray, tau: float, ok: np.ndarray, n: int = 2
              ) -> list[dict]:
    """Where the misfit at relative model error ``tau`` sits: the largest (recording, channel)."""
    R, P = fitter.mf.y.shape
    Et, _ = _at_tau(fitter, e.ravel(), np.zeros((R * P, 0)), ok, tau)
    c2 = Et.reshape(R, P) ** 2
    lay, mf = fitter.mf.layout, fitter.mf
    rows = []
    for r in range(R):
        for ch in lay.channels:
            cols = [j for j, c in enumerate(lay.channel) if c == ch]
            rows.append((float(c2[r, cols].sum()), r, ch))
    total = float(c2.sum()) or 1.0
    rows.sort(reverse=True)
    return [{"recording": mf.names[r], "mu": float(mf.mu[r]), "branch": mf.branch[r],
             "channel": ch, "share": v / total} for v, r, ch in rows[:n]]


def build_verdict(system: System, lib: Library, fitter: Fitter, cal: Calibration,
                  fits: Sequence[CalibratedTermFit], pair_fits: Sequence[CalibratedPairFit],
                  probs: Mapping[str, float], classes: Mapping[str, float],
                  best_class: str, best_model: str, me0: ModelError, me_best: ModelError,
                  md: Unexplained | None = None) -> dict:
    """The report's ``verdict`` (module docstring).

    Args:
        system: The simulator.
        lib: Its library of terms.
        fitter: The residuals (their whitening) the mismatch is located with.
        cal: The calibration with no term.
        fits: The single terms, most probable first.
        pair_fits: The pairs, most probable first.
        probs: Posterior probability of every model.
        classes: Of the three classes.
        best_class: The most probable class.
        best_model: Its most probable model.
        me0: Posterior of the model error with every parameter nominal.
        me_best: Under ``best_model``.
        md: The model "unexplained", where compared.

    Returns:
        ``kind``, ``probability`` (of the class), ``model``, ``model_probability``
        (of that model alone: the class's shared with its rivals), ``parameters`` (named off),
        ``terms`` (named missing), ``pair``, ``indistinguishable``,
        ``model_error``, ``remaining`` and ``sentence``.
    """
    # where the remaining misfit sits (residuals at the best model's mode)
    if best_model == "none":
        ob = fitter.base
    elif best_model in ("parameters", "unexplained"):
        ob = cal.orbits
    else:
        ob = next(f.orbits for f in [*fits, *pair_fits]
                  if getattr(f, "name", None) == best_model
                  or (isinstance(f, CalibratedTermFit) and f.term.name == best_model))
    e_best, ok_best = fitter.residuals(ob), ob.ok
    remains = bool(me_best.ci90[0] > MIN_MODEL_ERROR)
    kind = best_class
    where = (located(fitter, e_best, me_best.median, ok_best)
             if remains or kind == KIND_UNEXPLAINED else [])
    # models the data cannot tell from the best one
    rivals = [k for k in sorted(probs, key=probs.get, reverse=True)
              if k != best_model and k != "none" and probs[k] * TIE_FACTOR >= probs[best_model]]

    def model_words(k: str) -> str:
        if k == "parameters":
            return "a recalibration of the parameters alone"
        if k == "unexplained":
            return "a smooth discrepancy that no library term explains"
        return " together with ".join(lib[t].plain for t in k.split("+"))

    off = [p for p in cal.parameters if p.off]
    named_terms: list[str] = []

    def err(me: ModelError) -> str:
        return f"{100 * me.median:.2g}% (90% {100 * me.ci90[0]:.2g}–{100 * me.ci90[1]:.2g}%)"

    tail = ""
    if remains and kind != KIND_UNEXPLAINED:
        loc = where[0]
        tail = (f" A smaller mismatch remains: model error {err(me_best)} of the orbit "
                f"amplitude, largest in {loc['channel']} at {loc['recording']} "
                f"({loc['branch']}, {system.parameter} = {loc['mu']:g}; "
                f"{100 * loc['share']:.0f}% of the misfit).")
    if kind == KIND_NONE:
        sentence = ("The simulator with its nominal parameters matches the recordings within "
                    f"their noise (model error {err(me0)} of the orbit amplitude).")
    elif kind == KIND_PARAMS:
        what = "; ".join(_pct(p, lib) for p in off) if off else \
            "jointly, no single one outside its 90% interval"
        sentence = (f"The simulator's parameters are off: {what}. Calibrated, its model error "
                    f"goes from {err(me0)} to {err(cal.model_error)} of the orbit amplitude."
                    + (f" No term is missing (the most probable, {fits[0].term.plain}, has "
                       f"probability {probs[fits[0].term.name]:.2g})." if fits else ""))
    elif kind == KIND_TERM:
        pf = next((f for f in pair_fits if f.name == best_model), None)
        if pf is not None:
            named_terms = [t.name for t in pf.terms]
            parts = [f"{t.plain} {m:.3g}{' ' + t.units if t.units else ''} (90% {lo:.3g} to "
                     f"{hi:.3g})" for t, m, (lo, hi) in zip(pf.terms, pf.medians, pf.ci90,
                                                            strict=True)]
            params_after = pf.parameters
            sentence = f"After calibrating the parameters the simulator lacks two terms: " \
                       f"{' and '.join(parts)}"
        else:
            f0 = next(f for f in fits if f.term.name == best_model)
            named_terms = [f0.term.name]
            u = f" {f0.term.units}" if f0.term.units else ""
            params_after = f0.parameters
            sentence = (f"After calibrating the parameters the simulator lacks {f0.term.plain}: "
                        f"{f0.median:.3g}{u} (90% interval {f0.ci90[0]:.3g} to "
                        f"{f0.ci90[1]:.3g})")
        off = [p for p in params_after if p.off]
        sentence += ((f"; parameters off: {'; '.join(_pct(p, lib) for p in off)}" if off
                      else "")
                     + f". Model error {err(me0)} → {err(me_best)} of the orbit amplitude.")
    else:
        eta = ("" if md is None else f": a smooth discrepancy of the orbits' fundamentals of "
               f"{100 * md.eta_median:.2g}% (90% {100 * md.eta_ci90[0]:.2g}–"
               f"{100 * md.eta_ci90[1]:.2g}%) of their size over the diagram")
        runner = max((k for k in probs if k not in ("none", "unexplained")), key=probs.get,
                     default=None)
        sentence = ("The simulator and the recordings disagree in a way that neither its "
                    "parameters nor a library term explain" + eta
                    + (f", largest in {where[0]['channel']} at {where[0]['recording']}"
                       if where else "")
                    + f" (model error {err(me0)} of the orbit amplitude nominal, "
                    f"{err(cal.model_error)} calibrated)"
                    + (f". The best explanation by the library, {model_words(runner)}, has "
                       f"probability {probs[runner]:.2g}" if runner is not None else "")
                    + ".")
    if rivals and kind in (KIND_PARAMS, KIND_TERM):
        sentence += (" The data cannot tell this from " + " or ".join(model_words(k)
                                                                  for k in rivals)
                     + f" (probabilities {probs[best_model]:.2g} against "
                     + ", ".join(f"{probs[k]:.2g}" for k in rivals) + ").")
    sentence += tail
    return {"kind": kind, "probability": classes[best_class], "model": best_model,
            "model_probability": float(probs.get(best_model, classes[best_class])),
            "parameters": [p.name for p in off] if kind in (KIND_PARAMS, KIND_TERM) else [],
            "terms": named_terms, "pair": len(named_terms) == 2,
            "equivalent_terms": {p.name: t.name for p in off for t, par in lib.duplicates
                                 if par == p.name and kind in (KIND_PARAMS, KIND_TERM)},
            "indistinguishable": rivals,
            "model_error": {"nominal": me0.to_json(), "final": me_best.to_json()},
            "remaining": {"significant": remains, "where": where},
            "sentence": sentence}


def with_notes(verdict: Mapping, notes: Sequence[str]) -> dict:
    """The verdict with the preparation's notes closing its sentence, after the Bayes factors."""
    v = dict(verdict)
    if notes:
        v["sentence"] += " Note: " + "; ".join(n.rstrip(". ") for n in notes) + "."
    return v


def band_words(b: Mapping) -> str:
    """``"log B 12.3 [10.1, 13.0] over prior scales ×0.5–×2"`` of a ``prior_sensitivity`` row."""
    vals = [b["log_bayes_factor"], *b["scales"].values()]
    fs = [float(k) for k in b["scales"]]
    return (f"log B {b['log_bayes_factor']:.1f} [{min(vals):.1f}, {max(vals):.1f}] over "
            f"prior scales ×{min(fs):g}–×{max(fs):g}")


def with_bayes_factors(verdict: Mapping, bayes: Mapping, bands: Sequence[Mapping]) -> dict:
    """The verdict with its Bayes factors, prior odds and prior-scale band (module docstring).

    Args:
        verdict: :func:`build_verdict`'s.
        bayes: :func:`~bayeshopf.discrepancy.nested.class_bayes_factors`' (class names
            :data:`~bayeshopf.discrepancy.records.KIND_NONE` etc.).
        bands: Per model: ``model``, ``label``, ``evidence``, ``log_bayes_factor`` (against
            "parameters off") and ``scales`` (the same with every prior scale
            multiplied by each factor).

    Returns:
        A copy with ``bayes_factors`` (``prior``, ``log_evidence`` and
        ``log_bayes_factor`` of each class against ``"none"`` and
        ``"parameters off"``) and ``prior_sensitivity``; the sentence extended.
    """
    v = dict(verdict)
    lb = bayes["log_bayes_factor"]
    v["bayes_factors"] = {
        "prior": dict(bayes["prior"]), "log_evidence": dict(bayes["log_evidence"]),
        "log_bayes_factor": {c: {o: lb[c][o] for o in (KIND_NONE, KIND_PARAMS) if o in lb[c]}
                             for c in lb}}
    v["prior_sensitivity"] = [dict(b) for b in bands]
    if v["kind"] == KIND_UNEXPLAINED and KIND_UNEXPLAINED in lb and KIND_PARAMS in lb:
        v["sentence"] = v["sentence"] + (
            f" Apart from the prior odds, the log Bayes factor of the smooth discrepancy "
            f"against parameters off is {lb[KIND_UNEXPLAINED][KIND_PARAMS]:.1f}"
            + (f", of a missing term {lb[KIND_TERM][KIND_PARAMS]:.1f}"
               if KIND_TERM in lb else "") + ".")
        return v
    if KIND_TERM not in lb or KIND_PARAMS not in lb:
        return v
    words = (f" Apart from the prior odds ({bayes['prior'][KIND_TERM]:.2g} against "
             f"{bayes['prior'][KIND_PARAMS]:.2g}), the log Bayes factor of a missing term "
             f"against parameters off is {lb[KIND_TERM][KIND_PARAMS]:.1f}")
    model = v["model"] if v["kind"] == KIND_TERM else None
    row = next((b for b in bands if b["model"] == model), bands[0] if bands else None)
    if row is not None:
        words += f"; {row.get('label', row['model'])}: {band_words(row)}"
        vals = [row["log_bayes_factor"], *row["scales"].values()]
        if min(vals) < 0 < max(vals):
            words += (". Whether this term is missing rests on the terms' prior scales, "
                      "not on the data alone")
    v["sentence"] = v["sentence"] + words + "."
    return v
