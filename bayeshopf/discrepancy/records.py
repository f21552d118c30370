r"""Typed records of the calibration: parameters' posteriors, fits, the report.

:func:`~bayeshopf.discrepancy.calibration.calibrate` returns a
:class:`CalibrationReport`; its parts are the calibration with no term
(:class:`Calibration`), each term fitted jointly with the uncertain
parameters (:class:`CalibratedTermFit`), pairs of terms
(:class:`CalibratedPairFit`; what the two share: :class:`LinearisedFit`), the
posterior of one uncertain parameter in physical units
(:class:`ParameterPosterior`) and that of the relative model error τ under one
model (:class:`ModelError`).

**Parameters' posterior.** :math:`z \sim \mathcal N(\hat z, H^{-1})`; each
parameter's median is :math:`\theta(\hat z_j)` and its 90% interval
:math:`\theta(\hat z_j \pm 1.645\,\mathrm{sd}_j)`, in physical units (the maps
are monotone). A parameter is named **off** when its posterior mean lies more
than :math:`z_c` standard deviations from nominal, :math:`z_c = \Phi^{-1}(1 -
\mathrm{level}/(2d))` over the :math:`d` declared parameters
(:data:`OFF_LEVEL`, :func:`off_threshold`), and, where it was checked, a refit
with the parameter pinned at nominal raises :math:`-2\log p(x\mid y)` by more
than :math:`z_c^2` (:func:`~bayeshopf.discrepancy.fitting.check_off`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from bayeshopf.discrepancy.nested import CoefficientPosterior
from bayeshopf.discrepancy.orbits import OrbitBatch
from bayeshopf.discrepancy.render import verdict_probability
from bayeshopf.discrepancy.select import Fitter
from bayeshopf.discrepancy.terms import Term
from bayeshopf.errors import BayesHopfError
from bayeshopf.simulators.base import UncertainParameter

__all__ = ["KIND_NONE", "KIND_PARAMS", "KIND_TERM", "KIND_UNEXPLAINED", "OFF_LEVEL", "Z90",
           "Unexplained",
           "CalibratedPairFit", "CalibratedTermFit", "Calibration", "CalibrationError",
           "CalibrationReport", "LinearisedFit", "ModelError", "ParameterPosterior",
           "off_threshold",
           "posteriors"]

#: Standard normal quantile of a two-sided 90% interval.
Z90 = 1.6448536269514722
#: Family-wise level of the parameters named off: with every parameter at its nominal
#: value, the verdict names one or more of the d declared parameters off with probability
#: at most this (Bonferroni: each at level OFF_LEVEL / d; :func:`off_threshold`).
OFF_LEVEL = 0.1
#: The verdict's kinds.
KIND_NONE, KIND_PARAMS, KIND_TERM, KIND_UNEXPLAINED = (
    "none", "parameters off", "term missing", "unexplained")


class CalibrationError(BayesHopfError, ValueError):
    """A system or setting the calibration cannot work with."""


@dataclass(frozen=True)
class ParameterPosterior:
    r"""Posterior of one uncertain parameter, in physical units.

    Attributes:
        name: The parameter.
        units: Its unit.
        prior: ``"lognormal"`` or ``"normal"``.
        prior_scale: The prior's relative standard deviation.
        nominal: The simulator's value (the prior's centre).
        median: Posterior median.
        ci90: 5% and 95% posterior quantiles.
        z: Posterior mean of the standard normal coordinate.
        z_sd: Its posterior standard deviation (1 = no information beyond the prior).
        pinned: Rise of :math:`-2\log p(x\mid y)` at the mode when this parameter
            is pinned at its nominal value and the others are refitted (a
            profile-likelihood check of "off"; ``None``: not checked).
        z_off: How many posterior standard deviations from nominal name it off
            (:func:`off_threshold`; :data:`Z90`: its 90% interval).
        tolerance: The simulator's declared relative tolerance
            (:attr:`~bayeshopf.simulators.base.UncertainParameter.tolerance`).
        tolerance_z: The band ``nominal · (1 ± tolerance)`` in ``z``.
    """

    name: str
    units: str
    prior: str
    prior_scale: float
    nominal: float
    median: float
    ci90: tuple[float, float]
    z: float
    z_sd: float
    pinned: float | None = None
    z_off: float = Z90
    tolerance: float = 0.0
    tolerance_z: tuple[float, float] = (0.0, 0.0)

    @property
    def p_beyond_tolerance(self) -> float:
        r"""Posterior mass beyond the declared tolerance, :math:`P(z \notin [z_-, z_+])`.

        With the posterior :math:`N(\hat z, \mathrm{sd}^2)` of the coordinate:
        :math:`\Phi((z_- - \hat z)/\mathrm{sd}) + \Phi((\hat z - z_+)/\mathrm{sd})`.
        """
        lo, hi = self.tolerance_z
        if self.z_sd <= 0:
            return float(not lo <= self.z <= hi)
        return float(stats.norm.cdf((lo - self.z) / self.z_sd)
                     + stats.norm.cdf((self.z - hi) / self.z_sd))

    @property
    def off(self) -> bool:
        r"""Whether the data put the parameter off: beyond its tolerance, and not by chance.

        Three conditions: most of the posterior lies beyond the simulator's
        declared tolerance (:attr:`p_beyond_tolerance` > 1/2; with tolerance 0
        that mass is 1 and the other two decide); the posterior puts nominal more than
        :attr:`z_off` standard deviations away,
        :math:`|\hat z| > z_{\rm off}\,\mathrm{sd}` (nominal is :math:`z = 0`;
        the family-wise level of :func:`off_threshold`); and, where
        :func:`~bayeshopf.discrepancy.fitting.check_off` checked it, pinning the
        parameter at nominal costs more than :math:`z_{\rm off}^2` in :math:`-2\log p`.
        """
        return (self.p_beyond_tolerance > 0.5 and abs(self.z) > self.z_off * self.z_sd
                and (self.pinned is None or self.pinned > self.z_off**2))

    @property
    def shift(self) -> float:
        """Median relative to nominal, minus 1."""
        return self.median / self.nominal - 1.0

    def to_json(self) -> dict:
        """JSON-serialisable dict."""
        return {"name": self.name, "units": self.units, "prior": self.prior,
                "prior_scale": self.prior_scale, "nominal": self.nominal,
                "median": self.median, "ci90": list(self.ci90), "shift": self.shift,
                "off": self.off, "z": self.z, "z_sd": self.z_sd, "z_off": self.z_off,
                "pinned": self.pinned, "tolerance": self.tolerance,
                "p_beyond_tolerance": self.p_beyond_tolerance}


@dataclass(frozen=True)
class Calibration:
    """The uncertain parameters calibrated with no term (:math:`M_P`).

    :mod:`~bayeshopf.discrepancy.calibration` describes the models compared.

    Attributes:
        parameters: Posterior of each uncertain parameter, in declaration order.
        z_mode: Posterior mode of the standard normal coordinates, shape ``(d,)``
            (``parameters`` add the linearised correction to the mean, ~0).
        cov: Their posterior covariance ``H⁻¹``, shape ``(d, d)``.
        log_z: Laplace log evidence (common constants dropped).
        chi2: Misfit of the data rows at the mode.
        p_eff: Effective number of fitted parameters.
        e_mode: Whitened residuals at ``z_mode``, shape ``(R, P)``.
        jac: Their Jacobian in ``z``, shape ``(R·P, d)``.
        jac_nominal: The same at the nominal parameters (``z = 0``).
        orbits: The orbits at ``z_mode``.
        lost: Recordings whose orbit the calibrated simulator lacks.
        nfev: Residual evaluations of the least-squares fit.
        status: :func:`scipy.optimize.least_squares` status (> 0: converged).
        model_error: Posterior of the relative model error τ (``log_z`` has it
            integrated out; ``parameters`` and ``cov`` are at its median).
        fitter: The residuals it was fitted with (their whitening: ``fitter.model_error``).
    """

    parameters: tuple[ParameterPosterior, ...]
    z_mode: np.ndarray
    cov: np.ndarray
    log_z: float
    chi2: float
    p_eff: float
    e_mode: np.ndarray = field(repr=False)
    jac: np.ndarray = field(repr=False)
    jac_nominal: np.ndarray = field(repr=False)
    orbits: OrbitBatch = field(repr=False)
    lost: tuple[int, ...] = ()
    nfev: int = 0
    status: int = 0
    model_error: ModelError | None = None
    fitter: Fitter | None = field(default=None, repr=False)

    def __getitem__(self, name: str) -> ParameterPosterior:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(f"uncertain parameter expected among "
                       f"{', '.join(p.name for p in self.parameters)}; got {name!r}")

    @property
    def off(self) -> tuple[str, ...]:
        """The parameters named off (:attr:`ParameterPosterior.off`)."""
        return tuple(p.name for p in self.parameters if p.off)

    def values(self) -> dict[str, float]:
        """Posterior medians by name."""
        return {p.name: p.median for p in self.parameters}


@dataclass(frozen=True, kw_only=True)
class LinearisedFit:
    """What a term's and a pair's joint fit share: where it was linearised, its evidence.

    The fields are keyword-only (after the fits' own fields in their
    constructors); :func:`~bayeshopf.discrepancy.calibration.calibrate`'s charge,
    refits and Savage–Dickey comparison read them of either kind of fit.

    Attributes:
        orbits: The simulator's orbits at the joint mode (at the calibration's
            mode with the terms' coefficients 0 when only screened).
        x: The point ``(z, ζ)`` the linearisation is about.
        fitter: The residuals (their whitening) of this fit.
        penalty: Nats charged to ``log_z`` for the linearisation's disagreement
            with the orbits re-shot at its mode
            (:func:`~bayeshopf.discrepancy.problem.charge`; screened and refined
            fits alike).
        log_z_laplace: The model's own Laplace evidence at its own end point
            (charge paid); ``log_z`` is the one compared, Savage–Dickey against
            the nested model where :func:`~bayeshopf.discrepancy.nested.nested_log_z`
            uses it (``evidence`` says which).
        coefficients: The Laplace marginal of the term coefficients at every τ
            (:class:`~bayeshopf.discrepancy.nested.CoefficientPosterior`).
        evidence: ``"laplace"`` or ``"savage-dickey vs <nested model>"``.
    """

    orbits: OrbitBatch | None = field(default=None, repr=False)
    x: np.ndarray | None = field(default=None, repr=False)
    fitter: Fitter | None = field(default=None, repr=False)
    penalty: float = 0.0
    log_z_laplace: float | None = None
    coefficients: CoefficientPosterior | None = field(default=None, repr=False)
    evidence: str = "laplace"


@dataclass(frozen=True)
class CalibratedTermFit(LinearisedFit):
    r"""One term fitted jointly with the uncertain parameters (:math:`M_k`).

    Attributes:
        term: The term.
        median: Posterior median of its coefficient (parameters integrated out).
        ci90: 5% and 95% quantiles.
        mode: Joint posterior mode of the coefficient.
        log_z: Log evidence (common constants dropped).
        chi2: Misfit of the data rows at the joint mode.
        p_eff: Effective number of fitted parameters (term included).
        separability: Share of the term's effect on the whitened features that no
            change of the uncertain parameters can mimic, at the joint mode
            (:math:`\lVert P_\perp J_c\rVert / \lVert J_c\rVert`, 0: the term is a
            parameter in another guise, 1: orthogonal to every parameter's effect).
        parameters: The uncertain parameters' posterior with the term.
        grid: Coefficient values of the marginal posterior.
        density: Marginal posterior density on the grid.
        lost: Recordings whose orbit is lost at the joint mode.
        status: :func:`scipy.optimize.least_squares` status (0 when screened only).
        refined: Whether the term was fitted in full
            (:func:`~bayeshopf.discrepancy.fitting.fit_term`) or only screened by the
            linear model at the calibration
            (:func:`~bayeshopf.discrepancy.fitting.screen_term`).
        model_error: Posterior of the relative model error τ under this model.
        column: When screened: the data rows of the term's Jacobian column at
            the calibration (:func:`~bayeshopf.discrepancy.fitting.screen_pair` reuses
            it).
        jac: The data rows of the Jacobian at ``x``, shape ``(R·P, d + 1)``.

    And :class:`LinearisedFit`'s ``orbits``, ``x``, ``fitter``, ``penalty``,
    ``log_z_laplace``, ``coefficients`` and ``evidence``.
    """

    term: Term
    median: float
    ci90: tuple[float, float]
    mode: float
    log_z: float
    chi2: float
    p_eff: float
    separability: float
    parameters: tuple[ParameterPosterior, ...]
    grid: np.ndarray = field(repr=False)
    density: np.ndarray = field(repr=False)
    lost: tuple[int, ...] = ()
    status: int = 0
    refined: bool = True
    model_error: ModelError | None = None
    column: np.ndarray | None = field(default=None, repr=False)
    jac: np.ndarray | None = field(default=None, repr=False)


@dataclass(frozen=True)
class Unexplained:
    """:math:`M_D`, the calibrated simulator with a smooth discrepancy.

    The model and its evidence: :mod:`~bayeshopf.discrepancy.unexplained`.

    Attributes:
        log_z: Log evidence (common constants as every model's).
        log_bf: Log Bayes factor against "parameters off" (:math:`M_P`).
        eta_median: Posterior median of η, the discrepancy's relative size.
        eta_ci90: Its 5% and 95% posterior quantiles.
        ell_median: Posterior median of ℓ (units of the diagram coordinates).
    """

    log_z: float
    log_bf: float
    eta_median: float
    eta_ci90: tuple[float, float]
    ell_median: float

    def to_json(self) -> dict:
        """JSON-serialisable dict."""
        return {"log_z": self.log_z, "log_bf_vs_parameters": self.log_bf,
                "eta_median": self.eta_median, "eta_ci90": list(self.eta_ci90),
                "ell_median": self.ell_median}


@dataclass(frozen=True)
class CalibrationReport:
    """Result of :func:`~bayeshopf.discrepancy.calibration.calibrate` (immutable).

    Attributes:
        system: The simulator's name.
        verdict: ``kind`` (``"none"``, ``"parameters off"``, ``"term missing"``,
            ``"unexplained"``), ``probability`` (of the most probable class),
            ``parameters`` (named off), ``terms`` (named missing), ``sentence``.
        log_z: Log evidence of ``"none"`` (nominal), ``"parameters"`` and each term.
        probabilities: Posterior probability of the same models.
        class_probabilities: Of ``"none"``, ``"parameters off"``, ``"term missing"``
            and ``"unexplained"``.
        chi2_nominal: Misfit with every parameter nominal.
        n_features: Features less sensor offsets (the degrees of freedom before any fit).
        calibration: The parameters calibrated with no term.
        terms: Each term with the parameters, most probable first.
        seconds: Wall time per stage.
        unexplained: The model "unexplained" (the calibrated simulator with a
            smooth discrepancy), or ``None`` where it was not compared.
    """

    system: str
    verdict: Mapping
    log_z: Mapping[str, float]
    probabilities: Mapping[str, float]
    class_probabilities: Mapping[str, float]
    chi2_nominal: float
    n_features: int
    calibration: Calibration
    terms: tuple[CalibratedTermFit, ...] = ()
    pairs: tuple[CalibratedPairFit, ...] = ()
    model_errors: Mapping[str, ModelError] = field(default_factory=dict)
    seconds: Mapping[str, float] = field(default_factory=dict)
    unexplained: Unexplained | None = None

    def to_json(self) -> dict:
        """JSON-serialisable dict."""
        cal = self.calibration
        return {
            "system": self.system, "verdict": dict(self.verdict),
            "class_probabilities": dict(self.class_probabilities),
            "models": [{"name": k, "log_evidence": float(self.log_z[k]),
                        "probability": float(self.probabilities[k])} for k in self.log_z],
            "nominal": {"chi2": self.chi2_nominal, "dof": self.n_features},
            "model_errors": {k: v.to_json() for k, v in self.model_errors.items()},
            "calibration": {"chi2": cal.chi2, "p_eff": cal.p_eff, "status": cal.status,
                            "lost": list(cal.lost),
                            "whitening_model_error": (cal.fitter.model_error
                                                      if cal.fitter is not None else None),
                            "parameters": [p.to_json() for p in cal.parameters]},
            "terms": [{"name": f.term.name, "probability": float(self.probabilities[f.term.name]),
                       "median": f.median, "ci90": list(f.ci90), "units": f.term.units,
                       "chi2": f.chi2, "log_evidence": f.log_z, "lost": list(f.lost),
                       "separability": f.separability, "refined": f.refined,
                       "penalty": f.penalty, "evidence": f.evidence,
                       "log_evidence_laplace": f.log_z_laplace,
                       "parameters_off": [p.name for p in f.parameters if p.off],
                       "parameters": [p.to_json() for p in f.parameters] if f.refined else None}
                      for f in self.terms],
            "pairs": [{"name": f.name, "probability": float(self.probabilities[f.name]),
                       "terms": [t.name for t in f.terms], "medians": list(f.medians),
                       "ci90": [list(c) for c in f.ci90],
                       "units": [t.units for t in f.terms], "chi2": f.chi2,
                       "log_evidence": f.log_z, "correlation": f.correlation,
                       "refined": f.refined, "penalty": f.penalty, "lost": list(f.lost),
                       "evidence": f.evidence, "log_evidence_laplace": f.log_z_laplace,
                       "parameters_off": [p.name for p in f.parameters if p.off]}
                      for f in self.pairs],
            "unexplained": (self.unexplained.to_json() if self.unexplained is not None
                            else None),
            "seconds": dict(self.seconds),
        }

    def summary(self) -> str:
        """The verdict, the calibrated parameters and the best terms, as plain text."""
        v = self.verdict
        lines = [f"Verdict ({v['kind']}, {verdict_probability(v)}): {v['sentence']}",
                 "", f"{'parameter':<10} {'nominal':>11} {'median':>11}   90% interval"
                 f"{'':<14} shift   off"]
        for p in self.calibration.parameters:
            lines.append(f"{p.name:<10} {p.nominal:>11.5g} {p.median:>11.5g}   "
                         f"[{p.ci90[0]:.5g}, {p.ci90[1]:.5g}]".ljust(62)
                         + f"{100 * p.shift:+6.2f}%  {'yes' if p.off else ''}")
        lines += ["", "model                        probability   log Z"]
        rows = [("none (nominal)", "none"), ("parameters calibrated", "parameters")]
        rows += [("unexplained (discrepancy)", "unexplained")] if "unexplained" in self.log_z \
            else []
        rows += [(f.term.name, f.term.name) for f in self.terms[:5]]
        rows += [(f.name, f.name) for f in self.pairs[:2]]
        for label, k in rows:
            lines.append(f"{label:<28} {self.probabilities[k]:>11.3g}   {self.log_z[k]:.1f}")
        return "\n".join(lines)



@dataclass(frozen=True)
class ModelError:
    r"""Posterior of the relative model error τ under one model.

    τ integrated out as :mod:`~bayeshopf.discrepancy.evidence` describes.

    Attributes:
        median: Posterior median of τ (a fraction of each channel's first-harmonic
            magnitude; a tenth of the frequency for the frequency).
        ci90: 5% and 95% posterior quantiles.
        log_z: Log evidence with τ integrated out (log-uniform prior over
            :data:`~bayeshopf.discrepancy.evidence.TAU`).
        weights: Posterior weights on :data:`~bayeshopf.discrepancy.evidence.TAU`.
    """

    median: float
    ci90: tuple[float, float]
    log_z: float
    weights: np.ndarray = field(repr=False)

    def to_json(self) -> dict:
        """JSON-serialisable dict."""
        return {"median": self.median, "ci90": list(self.ci90)}


@dataclass(frozen=True)
class CalibratedPairFit(LinearisedFit):
    """Two terms fitted jointly with the uncertain parameters.

    Attributes:
        terms: The two terms.
        medians: Posterior medians of their coefficients (normal marginals of
            the linearised model at the median of τ, truncated at 0 for a gap or
            a dissipative term).
        ci90: Their 5% and 95% quantiles.
        log_z: Log evidence, τ integrated out.
        chi2: Misfit of the data rows (at the mode when refined, else of the
            linear model at its mode).
        p_eff: Effective number of fitted parameters.
        correlation: Posterior correlation of the two coefficients (near ±1:
            the data see only their combination).
        parameters: The uncertain parameters' posterior with the pair.
        model_error: Posterior of τ under this model.
        lost: Recordings whose orbit is lost at the joint mode.
        refined: Whether fitted in full or only screened.

    And :class:`LinearisedFit`'s ``orbits``, ``x``, ``fitter``, ``penalty``,
    ``log_z_laplace``, ``coefficients`` (both terms') and ``evidence``.
    """

    terms: tuple[Term, Term]
    medians: tuple[float, float]
    ci90: tuple[tuple[float, float], tuple[float, float]]
    log_z: float
    chi2: float
    p_eff: float
    correlation: float
    parameters: tuple[ParameterPosterior, ...]
    model_error: ModelError
    lost: tuple[int, ...] = ()
    refined: bool = False

    @property
    def name(self) -> str:
        """``"<term>+<term>"``."""
        return "+".join(t.name for t in self.terms)


def off_threshold(d: int, level: float = OFF_LEVEL) -> float:
    r"""Standard normal quantile :math:`z_c = \Phi^{-1}(1 - \mathrm{level}/(2d))` for naming off.

    A parameter is named off when its posterior mean lies more than
    :math:`z_c` posterior standard deviations from nominal (and the pinned
    refit of :func:`~bayeshopf.discrepancy.fitting.check_off` costs more than
    :math:`z_c^2`). Over ``d`` parameters at nominal this names any of them with
    probability at most ``level`` (Bonferroni). ``d = 11`` (flutter3dof), level 0.1: :math:`z_c`
    = 2.61, each parameter at the 99.1% level; ``d = 1``: the 90% interval.
    """
    return float(stats.norm.ppf(1.0 - level / (2 * max(int(d), 1))))


def posteriors(unc: Sequence[UncertainParameter], nominal: np.ndarray, units: Sequence[str],
               z: np.ndarray, cov: np.ndarray) -> tuple[ParameterPosterior, ...]:
    """Each uncertain parameter's posterior from that of its standard normal coordinate.

    Args:
        unc: The uncertain parameters.
        nominal: Their nominal values, shape ``(d,)``.
        units: Their units.
        z: Posterior mean of the coordinates, shape ``(d,)``.
        cov: Their posterior covariance, shape ``(d, d)``.
    """
    out = []
    z_off = off_threshold(len(unc))
    for j, u in enumerate(unc):
        sd = float(np.sqrt(max(cov[j, j], 0.0)))
        lo, hi = (float(u.value(z[j] + s * Z90 * sd, nominal[j])) for s in (-1, 1))
        band = sorted(float(u.coordinate(nominal[j] * (1.0 + s * u.tolerance), nominal[j]))
                      for s in (-1, 1))
        out.append(ParameterPosterior(
            name=u.name, units=units[j], prior=u.prior, prior_scale=u.scale,
            nominal=float(nominal[j]), median=float(u.value(z[j], nominal[j])),
            ci90=(min(lo, hi), max(lo, hi)), z=float(z[j]), z_sd=sd, z_off=z_off,
            tolerance=u.tolerance, tolerance_z=(band[0], band[1])))
    return tuple(out)

