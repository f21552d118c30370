r"""Calibrate the simulator's uncertain parameters, then ask whether a term is still missing.

A simulator's parameters are never exactly right. Before a mismatch is called
missing physics, the parameters that the :class:`~bayeshopf.simulators.System`
declares uncertain (``system.uncertain``, each with a prior,
:class:`~bayeshopf.simulators.base.UncertainParameter`) are calibrated against
the recordings as nuisance parameters, with the same whitened feature
residuals as :mod:`bayeshopf.discrepancy.select`, and three kinds of model are
compared by their evidence:

* :math:`M_0`, **nominal**: every parameter at its nominal value, no term;
* :math:`M_P`, **parameters off**: the uncertain parameters calibrated, no term;
* :math:`M_k`, **term k missing**: the uncertain parameters calibrated jointly
  with the coefficient of library term :math:`k`;
* :math:`M_D`, **unexplained**: the uncertain parameters calibrated, and a
  smooth discrepancy of the orbits' fundamentals over the diagram
  (:mod:`~bayeshopf.discrepancy.unexplained`).

The pieces: the stacked residuals, their Jacobian and the least-squares fit
(:mod:`~bayeshopf.discrepancy.problem`); the Laplace evidence and the relative
model error :math:`\tau` integrated out (:mod:`~bayeshopf.discrepancy.evidence`);
the fits of the parameters alone, with one term and with pairs of terms
(:mod:`~bayeshopf.discrepancy.fitting`); the typed records they return
(:mod:`~bayeshopf.discrepancy.records`); the verdict
(:mod:`~bayeshopf.discrepancy.verdict`). :func:`calibrate` runs them in
named steps:

1. **Calibrate** the parameters with no term from a first whitening
   (:data:`TAU_START`), refitted at the inferred :math:`\tau` where that changes
   the whitening (:func:`_calibrate_parameters`).
2. **Screen, then refine the terms** (:func:`_scan_terms`). Fitting every term
   in full costs as much as the calibration itself, and most terms are
   hopeless. Every term is first *screened* (the linear model at the
   calibration); the :data:`N_REFINE` terms of highest screened evidence before
   the screening's charge (what the linear model promises; the charge says the
   linearisation does not hold that far, which only a full fit settles), among
   those within :data:`SCREEN_NATS` of the best, are then fitted in full, and
   again the most probable term as long as it is only screened; the others keep
   their screened evidence (``refined=False``). A full fit starts from the
   calibration when the calibration fits within noise, and from the nominal
   parameters when it does not.
3. **Pairs** (:func:`_scan_pairs`): the :data:`N_PAIR` best-screened single
   terms pairwise and, stepwise, every other term added to the most probable
   refined single term; the most probable pair is fitted in full when its
   probability exceeds :data:`PAIR_REFINE` (at most :data:`N_PAIR_REFINE`).
4. **Check the parameters named off** by the most probable model of the most
   probable class, by pinning them at nominal; a pinned refit that lands below
   the mode shows the mode was a local one, and the model is refitted from
   there (:func:`_check_best`).
5. **Unexplained**: :math:`M_D` at the final calibration
   (:func:`~bayeshopf.discrepancy.unexplained.unexplained`).
6. **Verdict** (:func:`~bayeshopf.discrepancy.verdict.build_verdict`): the most
   probable class.

**Model probabilities.** Prior probability 1/4 for each of "nothing wrong"
(:math:`M_0`), "parameters off" (:math:`M_P`), "unexplained" (:math:`M_D`)
and "a term missing", the last shared by the :math:`n` single terms (1/8) and
the :math:`n(n-1)/2` pairs (1/8); :math:`P(M \mid y) \propto \pi_M Z_M`
(:func:`_probabilities`). Without the scan, 1/3 each for :math:`M_0`,
:math:`M_P` and :math:`M_D`. Every term's coefficient has the scale-free prior
of :mod:`~bayeshopf.discrepancy.nested` (its prior scale times a factor
log-uniform over three decades). A term model nested on
:math:`M_P` (or a pair on one of its terms) whose fit is confirmed at its mode
takes :math:`Z_M` from the Savage–Dickey ratio on its coefficients' marginal
(:mod:`~bayeshopf.discrepancy.nested`, which argues where), so it neither wins
nor loses by where the nested model's optimiser stopped; the verdict also
gives each class's Bayes factor apart from the prior odds, and the most
probable terms' Bayes factor with the prior scales halved and doubled. Nothing hand-set enters the
comparison of models; the posterior of :math:`\tau` under the verdict's model
is reported (``verdict["model_error"]``).

**Identifiability.** What keeps a recalibration from being reported as a term,
and a term from being absorbed by the parameters: the priors (a parameter
cannot move ten standard deviations to mimic a term for free; the Laplace
:math:`\log\det H` is the Occam price of every parameter the data pin down),
the shape of the orbits at several amplitudes on both branches (a linear
parameter changes every orbit in a pattern a nonlinear term cannot copy at
all amplitudes at once), and the Floquet stability of each branch (a
calibration that moves a fold past a recording loses its orbit). A term that
*is* an uncertain parameter in another guise (``alpha_cubic_stiffness`` is a
change of ``k_alpha3``) could be told apart only by the prior, so it is left
out of the candidates (:func:`~bayeshopf.discrepancy.terms.library` with the
calibrated ``parameters``; :attr:`~bayeshopf.discrepancy.terms.Library.skipped`)
and the verdict names the parameter "equivalently" as that term.
:attr:`~bayeshopf.discrepancy.records.CalibratedTermFit.separability`
measures what remains of this for the other terms: the share of a term's
effect on the whitened features that no change of the parameters can mimic.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import numpy as np
from scipy import stats
from tqdm.auto import tqdm

from bayeshopf._x64 import ensure_x64
from bayeshopf.data.recording import RecordingSet
from bayeshopf.discrepancy.evidence import _null, laplace_evidence, term_marginal
from bayeshopf.discrepancy.features import DEFAULT_K
from bayeshopf.discrepancy.fitting import (
    check_off,
    fit_parameters,
    fit_term,
    needs_refit,
    refit_pair,
    refit_term,
    screen_pair,
    screen_second,
    screen_term,
)
from bayeshopf.discrepancy.nested import class_bayes_factors, nested_log_z, sensitivity
from bayeshopf.discrepancy.prepare import Prepared, prepare
from bayeshopf.discrepancy.problem import MAX_NFEV
from bayeshopf.discrepancy.records import (
    KIND_NONE,
    KIND_PARAMS,
    KIND_TERM,
    KIND_UNEXPLAINED,
    OFF_LEVEL,
    Z90,
    CalibratedPairFit,
    CalibratedTermFit,
    Calibration,
    CalibrationError,
    CalibrationReport,
    ModelError,
    ParameterPosterior,
    off_threshold,
)
from bayeshopf.discrepancy.select import ALPHA, TIE_FACTOR, Fitter
from bayeshopf.discrepancy.terms import KINDS, Library
from bayeshopf.discrepancy.unexplained import unexplained
from bayeshopf.discrepancy.verdict import (
    MIN_MODEL_ERROR,
    build_verdict,
    with_bayes_factors,
    with_notes,
)
from bayeshopf.simulators.base import System, UncertainParameter
from bayeshopf.simulators.registry import get_system

__all__ = ["ALPHA", "KIND_NONE", "KIND_PARAMS", "KIND_TERM",
           "KIND_UNEXPLAINED", "MAX_NFEV", "MIN_MODEL_ERROR", "N_PAIR", "N_PAIR_REFINE",
           "N_REFINE", "OFF_LEVEL", "PAIR_REFINE", "SCREEN_NATS", "TAU_START", "TIE_FACTOR",
           "Z90", "CalibratedPairFit", "CalibratedTermFit", "Calibration", "CalibrationError",
           "CalibrationReport", "ModelError", "ParameterPosterior",
           "calibrate", "check_off", "fit_parameters", "fit_term", "laplace_evidence",
           "off_threshold", "refit_pair", "refit_term", "screen_pair", "screen_second",
           "screen_term", "term_marginal"]

#: Terms fitted in full after the screening (:func:`calibrate`).
N_REFINE = 3
#: Only terms whose screened evidence is within this many nats of the best are refined.
SCREEN_NATS = 100.0
#: Relative model error of the first whitening (below the features' noise on typical
#: records; refitted at the inferred τ where that differs).
TAU_START = 1e-4
#: Pairs of terms are screened among this many best single terms.
N_PAIR = 4
#: A screened pair is fitted in full when its probability exceeds this ...
PAIR_REFINE = 0.05
#: ... the most probable first, at most this many.
N_PAIR_REFINE = 3

_Probabilities = Callable[[Sequence[CalibratedTermFit], Sequence[CalibratedPairFit]],
                          dict[str, float]]


def _log_priors(fits: Sequence[CalibratedTermFit], pair_fits: Sequence[CalibratedPairFit], *,
                scan: bool, pairs: int, n: int) -> dict[str, float]:
    """Log prior probability of every model (module docstring, "Model probabilities")."""
    if not scan:
        return {k: np.log(1 / 3) for k in ("none", "parameters", "unexplained")}
    lp = {k: np.log(1 / 4) for k in ("none", "parameters", "unexplained")}
    lp.update({f.term.name: np.log(1 / 4 / (2 if pairs else 1) / n) for f in fits})
    lp.update({f.name: np.log(1 / 8 / (n * (n - 1) // 2)) for f in pair_fits})
    return lp


def _probabilities(log_z: Mapping[str, float], fits: Sequence[CalibratedTermFit],
                   pair_fits: Sequence[CalibratedPairFit], *, scan: bool, pairs: int,
                   n: int) -> dict[str, float]:
    """Posterior probability of every model (module docstring, "Model probabilities").

    Args:
        log_z: Log evidence of ``"none"``, ``"parameters"`` and (where compared)
            ``"unexplained"``.
        fits: The single terms.
        pair_fits: The pairs.
        scan: Whether the terms are compared at all.
        pairs: Whether pairs share the prior of "a term missing".
        n: Number of terms in the library.
    """
    lp = _log_priors(fits, pair_fits, scan=scan, pairs=pairs, n=n)
    lz = {k: log_z[k] for k in ("none", "parameters", "unexplained") if k in log_z}
    lz.update({f.term.name: f.log_z for f in fits})
    lz.update({f.name: f.log_z for f in pair_fits})
    lw = np.array([lp[k] + lz[k] for k in lz])
    w = np.exp(lw - lw.max())
    return dict(zip(lz, (float(v) for v in w / w.sum()), strict=True))


def _nest(log_z_p: float, fits: Sequence[CalibratedTermFit],
          pair_fits: Sequence[CalibratedPairFit]
          ) -> tuple[list[CalibratedTermFit], list[CalibratedPairFit]]:
    """The fits with the evidence compared (:func:`~bayeshopf.discrepancy.nested.nested_log_z`).

    Savage–Dickey against the nested model where that uses it, else their own.
    """
    lz, how = nested_log_z(log_z_p, fits, pair_fits)
    return ([replace(f, log_z=lz[f.term.name], evidence=how[f.term.name]) for f in fits],
            [replace(f, log_z=lz[f.name], evidence=how[f.name]) for f in pair_fits])


def _promise(f: CalibratedPairFit) -> CalibratedPairFit:
    """A screened pair with the evidence its linear model promises (its charge given back)."""
    return replace(f, log_z=f.log_z + f.penalty,
                   log_z_laplace=(f.log_z_laplace if f.log_z_laplace is not None
                                  else f.log_z) + f.penalty)


def _bayes(log_z: Mapping[str, float], fits: Sequence[CalibratedTermFit],
           pair_fits: Sequence[CalibratedPairFit], probs: Mapping[str, float], best_model: str,
           *, scan: bool, pairs: int, n: int) -> tuple[dict, list[dict]]:
    """The classes' Bayes factors and prior probabilities, and the prior-scale bands.

    The bands are those of the two most probable single terms and of the
    verdict's model when it is a pair (:mod:`~bayeshopf.discrepancy.nested`).
    """
    lp = _log_priors(fits, pair_fits, scan=scan, pairs=pairs, n=n)
    bayes = class_bayes_factors(lp, log_z, {
        KIND_NONE: ["none"], KIND_PARAMS: ["parameters"], KIND_UNEXPLAINED: ["unexplained"],
        KIND_TERM: [f.term.name for f in fits] + [f.name for f in pair_fits]})
    top = sorted(fits, key=lambda f: -probs[f.term.name])[:2]
    top += [f for f in pair_fits if f.name == best_model]
    bands = []
    for f in top:
        single = isinstance(f, CalibratedTermFit)
        name = f.term.name if single else f.name
        if f.coefficients is None:
            continue
        b = log_z[name] - log_z["parameters"]
        label = f.term.plain if single else " together with ".join(t.plain for t in f.terms)
        bands.append({"model": name, "label": label, "evidence": f.evidence,
                      "log_bayes_factor": b,
                      "scales": {str(k): b + v for k, v in sensitivity(f.coefficients).items()}})
    return bayes, bands


def _classes(probs: Mapping[str, float], fits: Sequence[CalibratedTermFit],
             pair_fits: Sequence[CalibratedPairFit]) -> dict[str, float]:
    """Probability of each class: nothing wrong, parameters off, a term missing, unexplained."""
    return {KIND_NONE: probs["none"], KIND_PARAMS: probs["parameters"],
            KIND_TERM: float(sum(probs[f.term.name] for f in fits)
                             + sum(probs[f.name] for f in pair_fits)),
            KIND_UNEXPLAINED: probs.get("unexplained", 0.0)}


def _best_model(best_class: str, probs: Mapping[str, float],
                fits: Sequence[CalibratedTermFit], pair_fits: Sequence[CalibratedPairFit]
                ) -> str:
    """The most probable model of the class ``best_class``."""
    if best_class == KIND_NONE:
        return "none"
    if best_class == KIND_PARAMS:
        return "parameters"
    if best_class == KIND_UNEXPLAINED:
        return "unexplained"
    return max([f.term.name for f in fits] + [f.name for f in pair_fits], key=probs.get)


def _calibrate_parameters(fitter: Fitter, unc: Sequence[UncertainParameter], dof0: int,
                          max_nfev: int) -> tuple[Calibration, bool]:
    """Step 1: the parameters calibrated with no term, refitted at the inferred model error.

    Returns:
        ``(calibration, compromise)``: the calibration (its ``fitter`` the last
        whitening) and whether, at the first whitening, it left a significant
        misfit (then the terms are fitted from nominal).
    """
    cal = fit_parameters(fitter, unc, max_nfev=max_nfev)
    # a calibration that leaves a significant misfit is a compromise: fit terms from nominal
    compromise = bool(stats.chi2.sf(cal.chi2, dof0 - cal.p_eff) < ALPHA)
    for _ in range(2):
        if not needs_refit(fitter, cal.model_error.median):
            break
        # the data want another model error than the whitening assumed: refit with it
        fitter = fitter.with_model_error(cal.model_error.median)
        cal = fit_parameters(fitter, unc, max_nfev=max_nfev, start=cal)
    return cal, compromise


def _scan_terms(fitter: Fitter, unc: Sequence[UncertainParameter], lib: Library,
                cal: Calibration, *, n_ref: int, compromise: bool, max_nfev: int,
                progress: bool) -> tuple[list[CalibratedTermFit], list[CalibratedTermFit],
                                         list[int], dict[str, float]]:
    """Step 2: every term screened, the best ones fitted in full (module docstring).

    Returns:
        ``(fits, screened, order, seconds)``: the terms in library order
        (refined where fitted in full), the same as screened, the screened
        ones' order by decreasing evidence, and the wall time per stage.
    """
    secs = {}
    t1 = time.perf_counter()
    fits = [screen_term(fitter, unc, term, cal) for term in lib.terms]
    screened = list(fits)
    secs["screen"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    start = "nominal" if compromise else "calibration"
    # ranked by what the linear model at the calibration promises, before its charge: the
    # charge says that linearisation does not hold that far, which a full fit settles
    promise = [f.log_z + f.penalty for f in fits]
    order = [int(i) for i in np.argsort([-v for v in promise])]
    todo = [i for i in order[:n_ref] if promise[i] >= promise[order[0]] - SCREEN_NATS]
    bar = tqdm(total=len(todo), desc="terms", disable=not progress, leave=False)
    while n_ref and (todo or not fits[int(np.argmax([f.log_z for f in fits]))].refined):
        # then the most probable term, as long as it is only screened
        i = todo.pop(0) if todo else int(np.argmax([f.log_z for f in fits]))
        t2 = time.perf_counter()
        fits[i] = fit_term(fitter, unc, fits[i].term, cal, start=start, max_nfev=max_nfev)
        if needs_refit(fitter, fits[i].model_error.median):
            fits[i] = refit_term(fitter.with_model_error(fits[i].model_error.median), unc,
                                 fits[i], max_nfev=max_nfev)
        secs[f"term {fits[i].term.name}"] = time.perf_counter() - t2
        bar.update()
    bar.close()
    secs["terms"] = time.perf_counter() - t1
    return fits, screened, order, secs


def _scan_pairs(fitter: Fitter, unc: Sequence[UncertainParameter], lib: Library,
                cal: Calibration, fits: Sequence[CalibratedTermFit],
                screened: Sequence[CalibratedTermFit], order: Sequence[int], *, pairs: int,
                n_ref: int, max_nfev: int, probabilities: _Probabilities
                ) -> tuple[list[CalibratedPairFit], dict[str, float]]:
    """Step 3: pairs screened two ways, the most probable fitted in full (module docstring).

    Args:
        fitter: The calibration's residuals.
        unc: The uncertain parameters.
        lib: The library.
        cal: The calibration.
        fits: The single terms after step 2.
        screened: The same, as screened.
        order: The screened terms by decreasing evidence.
        pairs: Pairs are screened among this many best single terms (at least 2).
        n_ref: How many terms were refined (0: pairs screened only).
        max_nfev: Residual evaluations of a full fit.
        probabilities: Every model's probability given the single terms and pairs.

    Returns:
        ``(pair_fits, seconds)``.
    """
    secs = {}
    best = [screened[i] for i in order[: max(2, int(pairs))]]
    pair_fits = [screen_pair(fitter, unc, a, b, cal)
                 for k, a in enumerate(best) for b in best[k + 1:]]
    probs = probabilities(fits, pair_fits)
    if n_ref:
        # stepwise: every other term added to the most probable refined single (at its
        # mode: more accurate than the same pair screened at the calibration)
        first = max((f for f in fits if f.refined), key=lambda f: probs[f.term.name])
        step = [screen_second(unc, first, t) for t in lib.terms if t.name != first.term.name]
        have = {frozenset(t.name for t in f.terms) for f in step}
        pair_fits = step + [f for f in pair_fits
                            if frozenset(t.name for t in f.terms) not in have]
        probs = probabilities(fits, pair_fits)
    for _ in range(N_PAIR_REFINE if n_ref else 0):
        # as for the single terms: screened pairs ranked by what their linear model
        # promises, before the charge that a full fit settles
        probs = probabilities(fits, [f if f.refined else _promise(f) for f in pair_fits])
        todo_p = [k for k, f in enumerate(pair_fits)
                  if not f.refined and probs[f.name] > PAIR_REFINE]
        if not todo_p:
            break
        k = max(todo_p, key=lambda k: probs[pair_fits[k].name])
        t2 = time.perf_counter()
        full = refit_pair(pair_fits[k].fitter, unc, pair_fits[k], max_nfev=max_nfev)
        if needs_refit(fitter, full.model_error.median):
            full = refit_pair(fitter.with_model_error(full.model_error.median), unc, full,
                              max_nfev=max_nfev)
        pair_fits[k] = full
        secs[f"pair {full.name}"] = time.perf_counter() - t2
        probs = probabilities(fits, pair_fits)
    return pair_fits, secs


def _check_best(best_model: str, unc: Sequence[UncertainParameter], cal: Calibration,
                fits: Sequence[CalibratedTermFit], pair_fits: Sequence[CalibratedPairFit],
                me_best: ModelError, max_nfev: int
                ) -> tuple[Calibration, list[CalibratedTermFit], list[CalibratedPairFit]]:
    """Step 4: the parameters named off by ``best_model`` checked by pinning them at nominal.

    A pinned refit that lands below the mode shows the mode was a local one:
    the model is refitted from there (once) and checked again.

    Returns:
        ``(cal, fits, pair_fits)`` with ``best_model``'s parameters checked
        (:attr:`~bayeshopf.discrepancy.records.ParameterPosterior.pinned`).
    """
    fits, pair_fits = list(fits), list(pair_fits)
    for attempt in range(2):
        if best_model in ("parameters", "unexplained"):       # M_D has M_P's parameters
            checked, better = check_off(cal.fitter, unc, (), cal.z_mode, cal.orbits,
                                        cal.parameters, me_best.median)
            if better is not None and attempt == 0:
                cal = fit_parameters(cal.fitter, unc, max_nfev=max_nfev,
                                     start=replace(cal, z_mode=better[0], orbits=better[1]))
                me_best = cal.model_error
                continue
            cal = replace(cal, parameters=checked)
        elif best_model != "none":
            k, f = next((k, f) for k, f in enumerate([*fits, *pair_fits])
                        if (f.term.name if isinstance(f, CalibratedTermFit) else f.name)
                        == best_model)
            terms_k = (f.term,) if isinstance(f, CalibratedTermFit) else f.terms
            checked, better = check_off(f.fitter, unc, terms_k, f.x, f.orbits, f.parameters,
                                        me_best.median)
            if better is not None and attempt == 0:
                moved = replace(f, x=better[0], orbits=better[1])
                f = (refit_term(f.fitter, unc, moved, max_nfev=max_nfev)
                     if isinstance(f, CalibratedTermFit)
                     else refit_pair(f.fitter, unc, moved, max_nfev=max_nfev))
                me_best = f.model_error
            else:
                f = replace(f, parameters=checked)
            if k < len(fits):
                fits[k] = f
            else:
                pair_fits[k - len(fits)] = f
            if better is not None and attempt == 0:
                continue
        break
    return cal, fits, pair_fits


def calibrate(recordings: RecordingSet, system: System | str, *, kinds: tuple[str, ...] = KINDS,
              K: int = DEFAULT_K, scan: bool = True, refine: int | None = N_REFINE,
              pairs: int = N_PAIR, progress: bool = False, max_nfev: int = MAX_NFEV,
              prepared: Prepared | None = None) -> CalibrationReport:
    """Calibrate the simulator's uncertain parameters, then scan the library for what is missing.

    **Main arguments**

    Args:
        recordings: Stable and unstable LCO recordings (μ and branch labelled).
        system: The simulator (with ``uncertain`` parameters declared), or its
            name for :func:`~bayeshopf.simulators.get_system`.
        kinds: Kinds of term in the library.
        scan: Also fit the library's terms (and pairs) jointly with the
            parameters; without it only "none" and "parameters off" are compared.
        refine: How many terms to fit in full: every term is first screened by
            the linear model at the calibration
            (:func:`~bayeshopf.discrepancy.fitting.screen_term`), then the
            ``refine`` with the highest screened evidence before its charge, among those within
            :data:`SCREEN_NATS` of the best, are fitted in full
            (:func:`~bayeshopf.discrepancy.fitting.fit_term`), then the most
            probable term as long as it is only screened. ``None``: every term
            in full; 0: none.
        pairs: Pairs of terms are screened among this many best single terms
            (:func:`~bayeshopf.discrepancy.fitting.screen_pair`) and stepwise
            from the best single term
            (:func:`~bayeshopf.discrepancy.fitting.screen_second`), and the most
            probable pair is fitted in full
            (:func:`~bayeshopf.discrepancy.fitting.refit_pair`) when its
            probability exceeds :data:`PAIR_REFINE`; 0: no pairs.

    **Other arguments**

    Args:
        K: Harmonics per channel.
        progress: Show a progress bar over the terms.
        max_nfev: Largest number of residual evaluations per least-squares fit.
        prepared: What :func:`~bayeshopf.discrepancy.prepare.prepare` returned
            for these recordings, system, ``K`` and ``kinds`` (saves shooting
            the nominal orbits twice when the caller has them).

    Returns:
        A :class:`~bayeshopf.discrepancy.records.CalibrationReport` (module
        docstring for the method).

    Raises:
        CalibrationError: If the system declares no uncertain parameters.
        BayesHopfError: Bad recordings, or a simulator without extra-force input.
    """
    ensure_x64()
    t0 = time.perf_counter()
    system = get_system(system)
    unc = system.uncertain
    if not unc:
        raise CalibrationError(f"{system.name}: uncertain parameters expected (System."
                               "uncertain, a tuple of UncertainParameter); it declares none")
    if prepared is None:
        prepared = prepare(recordings, system, K, kinds, parameters=[u.name for u in unc])
    fitter, _, notes = prepared
    lib = fitter.lib
    secs = {"prepare": time.perf_counter() - t0}
    R, P = fitter.mf.y.shape
    dof0 = R * P - len(fitter.mf.layout.channels)
    fitter = fitter.with_model_error(TAU_START)
    e0 = fitter.residuals(fitter.base)
    chi0 = float(np.sum(e0**2))
    me0 = _null(fitter, e0, fitter.base.ok)

    # 1. the parameters alone
    t1 = time.perf_counter()
    cal, compromise = _calibrate_parameters(fitter, unc, dof0, max_nfev)
    fitter = cal.fitter
    secs["calibrate"] = time.perf_counter() - t1
    md, md_cal = unexplained(cal), cal
    log_z = {"none": me0.log_z, "parameters": cal.log_z, "unexplained": md.log_z}
    errors = {"none": me0, "parameters": cal.model_error, "unexplained": cal.model_error}
    n = len(lib.terms)

    def probabilities(fits, pair_fits) -> dict[str, float]:
        fits, pair_fits = _nest(log_z["parameters"], fits, pair_fits)
        return _probabilities(log_z, fits, pair_fits, scan=scan, pairs=pairs, n=n)

    # 2., 3. the terms and pairs of terms
    fits: list[CalibratedTermFit] = []
    pair_fits: list[CalibratedPairFit] = []
    if scan:
        n_ref = len(lib.terms) if refine is None else min(int(refine), len(lib.terms))
        fits, screened, order, s = _scan_terms(fitter, unc, lib, cal, n_ref=n_ref,
                                               compromise=compromise, max_nfev=max_nfev,
                                               progress=progress)
        secs.update(s)
        if pairs and n > 1:
            t1 = time.perf_counter()
            pair_fits, s = _scan_pairs(fitter, unc, lib, cal, fits, screened, order,
                                       pairs=pairs, n_ref=n_ref, max_nfev=max_nfev,
                                       probabilities=probabilities)
            secs.update(s)
            secs["pairs"] = time.perf_counter() - t1
    fits, pair_fits = _nest(log_z["parameters"], fits, pair_fits)
    for f in fits:
        log_z[f.term.name] = f.log_z
        errors[f.term.name] = f.model_error
    for f in pair_fits:
        log_z[f.name] = f.log_z
        errors[f.name] = f.model_error
    probs = probabilities(fits, pair_fits)
    fits.sort(key=lambda f: -probs[f.term.name])
    pair_fits.sort(key=lambda f: -probs[f.name])
    classes = _classes(probs, fits, pair_fits)
    best_class = max(classes, key=classes.get)
    best_model = _best_model(best_class, probs, fits, pair_fits)

    # 4. the parameters that the most probable model names off, checked
    t1 = time.perf_counter()
    cal, fits, pair_fits = _check_best(best_model, unc, cal, fits, pair_fits, errors[best_model],
                                       max_nfev)
    # a refit of the best model (or of M_P) moves the evidences nested on it
    log_z["parameters"], errors["parameters"] = cal.log_z, cal.model_error
    if cal is not md_cal:                                  # M_D sits on M_P's mode
        md = unexplained(cal)
    log_z["unexplained"], errors["unexplained"] = md.log_z, cal.model_error
    fits, pair_fits = _nest(log_z["parameters"], fits, pair_fits)
    for f in fits:
        log_z[f.term.name], errors[f.term.name] = f.log_z, f.model_error
    for f in pair_fits:
        log_z[f.name], errors[f.name] = f.log_z, f.model_error
    probs = probabilities(fits, pair_fits)
    fits.sort(key=lambda f: -probs[f.term.name])
    pair_fits.sort(key=lambda f: -probs[f.name])
    classes = _classes(probs, fits, pair_fits)
    secs["check off"] = time.perf_counter() - t1

    best_class = max(classes, key=classes.get)
    best_model = _best_model(best_class, probs, fits, pair_fits)

    # 5., 6. the verdict
    verdict = build_verdict(system, lib, fitter, cal, fits, pair_fits, probs, classes,
                            best_class, best_model, me0, errors[best_model], md)
    verdict = with_bayes_factors(verdict, *_bayes(log_z, fits, pair_fits, probs, best_model,
                                                  scan=scan, pairs=pairs, n=n))
    verdict = with_notes(verdict, notes)
    secs["total"] = time.perf_counter() - t0
    return CalibrationReport(system=system.name, verdict=verdict, log_z=log_z,
                             probabilities=probs, class_probabilities=classes,
                             chi2_nominal=chi0, n_features=dof0, calibration=cal,
                             terms=tuple(fits), pairs=tuple(pair_fits),
                             model_errors=errors, seconds=secs, unexplained=md)
