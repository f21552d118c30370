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
the smooth discrepancy, each term and pair of terms with probability, log
evidence and coefficient)
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

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any

from bayeshopf import posterior as hybrid_posterior
from bayeshopf._x64 import ensure_x64
from bayeshopf.data.recording import RecordingSet
from bayeshopf.discrepancy.calibrated import with_calibration
from bayeshopf.discrepancy.features import DEFAULT_K
from bayeshopf.discrepancy.prepare import prepare
from bayeshopf.discrepancy.records import CalibratedTermFit, CalibrationError, CalibrationReport
from bayeshopf.discrepancy.render import markdown, stage_rows
from bayeshopf.discrepancy.select import ALPHA, TIE_FACTOR, TermFit
from bayeshopf.discrepancy.single import single_terms
from bayeshopf.discrepancy.terms import KINDS
from bayeshopf.inference.collapsed import CollapsedSettings
from bayeshopf.simulators.base import System
from bayeshopf.simulators.registry import get_system

__all__ = ["ALPHA", "TIE_FACTOR", "DiscrepancyReport", "analyse", "hybrid_summary", "prepare",
           "stage_rows"]


@dataclass(frozen=True)
class DiscrepancyReport:
    """Result of :func:`analyse` (immutable).

    Attributes:
        data: The report as JSON-serialisable dict (``report.json``).
        system: The simulator.
        fits: Posterior of every term, most probable first
            (:class:`~bayeshopf.discrepancy.select.TermFit`, or
            :class:`~bayeshopf.discrepancy.records.CalibratedTermFit` with
            calibration).
        extras: Arrays for the figures (orbits, diagrams, features).
        calibration: The
            :class:`~bayeshopf.discrepancy.records.CalibrationReport`
            (``None`` without calibration).
    """

    data: dict
    system: System = field(repr=False)
    fits: tuple[TermFit, ...] | tuple[CalibratedTermFit, ...] = field(repr=False, default=())
    extras: dict = field(repr=False, default_factory=dict)
    calibration: CalibrationReport | None = field(repr=False, default=None)

    def to_json(self) -> dict:
        """The ``report.json`` structure."""
        return self.data

    @property
    def verdict(self) -> dict:
        """``{"kind", "terms", "sentence"}`` (with calibration, the calibration's verdict)."""
        return self.data["verdict"]

    def to_markdown(self) -> str:
        """``report.md`` (:func:`~bayeshopf.discrepancy.render.markdown`)."""
        return markdown(self.data)


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
            "nothing wrong", "parameters off", "a term missing" and "unexplained"
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
        raise CalibrationError(f"{system.name}: calibrate=True needs uncertain parameters "
                               "(System.uncertain); it declares none (use calibrate=False)")
    prepared = prepare(recordings, system, K, kinds,
                       parameters=[u.name for u in system.uncertain] if calibrate else ())
    cal_report = None
    if calibrate:
        data, fits, extras, cal_report = with_calibration(recordings, system, prepared, K=K,
                                                          kinds=kinds, progress=progress)
    else:
        data, fits, extras = single_terms(system, prepared, seed=seed, progress=progress,
                                          point_intervals=point_intervals)
    hyb = None
    hybrid_fit = None
    if hybrid:
        hybrid_fit = hybrid_posterior.fit_hybrid(recordings, "subcritical", seed=seed,
                                                 settings=hybrid_settings, progress=progress)
        hyb = hybrid_summary(hybrid_fit)
    lib = prepared.fitter.lib
    settings = {"harmonics": K, "seed": seed, "hybrid": hybrid}
    if calibrate:
        settings["calibration"] = True
    data.update({
        "hybrid": hyb,
        "simulator": system.name,
        "library": {"terms": list(lib.names), "skipped": dict(lib.skipped),
                    "typical_amplitude": dict(lib.amplitude)},
        "settings": settings,
        "notes": [n for n in prepared.notes if n],
        "runtime_s": time.perf_counter() - t0,
    })
    extras["hybrid"] = hybrid_fit
    return DiscrepancyReport(data=data, system=system, fits=tuple(fits), extras=extras,
                             calibration=cal_report)


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
    elif po.get("method") == "importance":
        conv.update(pareto_k=po.get("pareto_k"), ess=po.get("ess"))
    elif po.get("method") == "svi":
        pl = po.get("elbo_plateau", {})
        conv.update(elbo_plateau=bool(pl.get("plateau", False)), steps=po.get("steps"))
        ok = ok and conv["elbo_plateau"]
    conv["ok"] = bool(ok)
    return {"hopf": _interval(post.interval("mu0")), "fold": _interval(post.interval("mu_fold")),
            "settings": dataclasses.asdict(post.settings), "seed": int(post.seed),
            "convergence": conv, "warnings": list(diag.get("warnings", [])),
            "seconds": {k: float(v) for k, v in post.timings.items()}}
