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
  with the coefficient of library term :math:`k`.

**Coordinates.** Uncertain parameter :math:`j` is written through its
standard normal coordinate :math:`z_j` (:meth:`UncertainParameter.value`:
:math:`\theta_j = \theta_{0j} e^{\sigma_j z_j}` or :math:`\theta_{0j}(1 + s_j z_j)`),
and the term's coefficient as :math:`c = s_k\zeta` with the library's prior
scale :math:`s_k`, so every unknown :math:`x = (z, \zeta)` has a standard normal
prior (half-normal for a freeplay gap, :math:`\zeta \ge 0`).

**Residuals.** With the whitened feature residuals :math:`e(x)` of
:class:`~bayeshopf.discrepancy.select.Fitter` (sensor offsets profiled out,
orbits re-shot at every :math:`x` by homotopy from the nearest point already
solved, an orbit lost when it no longer exists or changes its Floquet
stability), the negative log posterior is half the squared norm of the
stacked vector

.. math::  E(x) = \begin{bmatrix} e(x) \\ x \end{bmatrix}, \qquad
           -\log p(x \mid y) = \tfrac12 \lVert E(x)\rVert^2 + \text{const},

the prior rows :math:`x` being the standard normal priors. The mode is found by
:func:`scipy.optimize.least_squares` (trust-region Gauss–Newton, a bound
:math:`\zeta \ge 0` for a gap), with the Jacobian :math:`G = \partial E/\partial x`
by forward differences of re-shot orbits (steps a tenth of the current
posterior standard deviation, as in :mod:`~bayeshopf.discrepancy.select`);
rows of orbits lost at either end of a difference are zero.

**Recorded orbits must exist.** An orbit that the simulator has at the start
of a fit (the nominal parameters) but loses at a trial point (its fold moved
past the recording's μ, or it changed its Floquet stability) gives every one
of its features the whitened residual :data:`BARRIER`: a recorded orbit exists,
so a model without it has (practically) zero likelihood, and the trust region
rejects the step. :mod:`~bayeshopf.discrepancy.select` instead charges a lost
orbit a finite :math:`\chi^2` of 25 per feature; from far away (nominal
parameters several percent off give :math:`\chi^2 \sim 10^3` per feature) losing
an orbit is then cheaper than fitting it, and the minimiser stalls on that
discontinuity. An orbit already missing at the start keeps the finite charge.

**Evidence (Laplace).** Linearising :math:`E(\hat x + \delta) \approx E + G\delta`
at the mode, with :math:`H = G^\top G = J^\top J + I`,

.. math::  \log Z_P = -\tfrac12\big(\lVert E\rVert^2 - b^\top H^{-1} b\big)
                     - \tfrac12 \log\det H, \qquad b = G^\top E

(the prior's :math:`(2\pi)^{-d/2}` cancels the Gaussian integral's
:math:`(2\pi)^{d/2}`), and :math:`\log Z_0 = -\tfrac12\lVert e(0)\rVert^2`. For
:math:`M_k` the parameters are integrated out analytically and the term's
coefficient on a grid of :math:`\pm 6` posterior standard deviations (which
respects the bound of a gap): with :math:`G = [G_z, g]`,
:math:`P_\perp = I - G_z (G_z^\top G_z)^{-1} G_z^\top`,

.. math::  \log Z_k = \log\int \exp\!\big(-\tfrac12 \lVert P_\perp (E + g(\zeta - \hat\zeta))
           \rVert^2\big)\, d\zeta - \tfrac12\log 2\pi\ [+\log 2]
           - \tfrac12 \log\det G_z^\top G_z ,

whose integrand is also the marginal posterior of :math:`\zeta`: its median and
90% interval are the term's. Every model drops the same constant
:math:`-\tfrac12\sum\log 2\pi\sigma^2`, so the :math:`\log Z` compare directly.

**Screening, then refinement.** Fitting every term in full costs as much as
the calibration itself, and most terms are hopeless. Every term is first
*screened*: the calibration's Jacobian plus the term's own column (one
re-shot orbit set, a forward difference in ζ at ζ = 0) make a linear model in
:math:`(z, \zeta)` whose evidence is the formula above at the calibration
(:func:`screen_term`). The :data:`N_REFINE` terms of highest screened evidence,
among those within :data:`SCREEN_NATS` of the best, are then fitted in full
(:func:`fit_term`), and again the most probable term as long as it is only
screened; the others keep their screened evidence (marked ``refined=False``).
A full fit starts from the calibration when the calibration fits within noise,
and from the nominal parameters when it does not: a calibration that cannot
explain the data is a compromise that has pushed weakly identified parameters
far out (several prior standard deviations) to absorb what a term would
explain, and the fit with the right term converges several times faster from
nominal than from that compromise.

**Parameters' posterior.** :math:`z \sim \mathcal N(\hat z, H^{-1})` (the
:math:`z` block for :math:`M_k`); each parameter's median is
:math:`\theta(\hat z_j)` and its 90% interval
:math:`\theta(\hat z_j \pm 1.645\,\mathrm{sd}_j)`, in physical units (the maps
are monotone). A parameter is **off** when that interval excludes its nominal value.

**Verdict.** Prior probability 1/3 for each of "nothing wrong" (:math:`M_0`),
"parameters off" (:math:`M_P`) and "a term missing", the last shared equally
by the :math:`n` terms; :math:`P(M \mid y) \propto \pi_M Z_M`. The verdict is the
most probable of the three classes, unless its best model still leaves a
significant misfit: :math:`\chi^2` of the data rows above the 99.9% quantile of
:math:`\chi^2_\nu`, :math:`\nu` = features − sensor offsets − effective number of
fitted parameters :math:`p_{\rm eff} = \mathrm{tr}(J^\top J H^{-1}) = d - \mathrm{tr}\,H^{-1}`;
then it is ``"unexplained"``.

**Identifiability.** What keeps a recalibration from being reported as a term,
and a term from being absorbed by the parameters: the priors (a parameter
cannot move ten standard deviations to mimic a term for free; the Laplace
:math:`\log\det H` is the Occam price of every parameter the data pin down),
the shape of the orbits at several amplitudes on both branches (a linear
parameter changes every orbit in a pattern a nonlinear term cannot copy at
all amplitudes at once), and the Floquet stability of each branch (a
calibration that moves a fold past a recording loses its orbit). A term that
*is* an uncertain parameter in another guise (``alpha_cubic_stiffness`` is a
change of ``k_alpha3``) is told apart only by the prior: within the
parameter's prior width the evidence prefers the recalibration, by design.
:attr:`CalibratedTermFit.separability` measures this: the share of a term's
effect on the whitened features that no change of the parameters can mimic
(0 for such a duplicate).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import integrate, optimize, stats

from bayeshopf._x64 import ensure_x64
from bayeshopf.data.recording import RecordingSet
from bayeshopf.discrepancy.analysis import prepare
from bayeshopf.discrepancy.features import DEFAULT_K
from bayeshopf.discrepancy.orbits import OrbitBatch, track
from bayeshopf.discrepancy.select import Fitter, _cdf
from bayeshopf.discrepancy.terms import KINDS, Term
from bayeshopf.errors import BayesHopfError
from bayeshopf.simulators.base import System, UncertainParameter
from bayeshopf.simulators.registry import get_system

__all__ = ["CalibratedTermFit", "Calibration", "CalibrationError", "CalibrationReport",
           "ParameterPosterior",
           "calibrate", "fit_parameters", "fit_term", "laplace_evidence", "screen_term",
           "term_marginal"]

#: Standard normal quantile of a two-sided 90% interval.
Z90 = 1.6448536269514722
#: Significance level of a misfit (as in :mod:`~bayeshopf.discrepancy.analysis`).
ALPHA = 1e-3
#: Two terms are named together when their probabilities are within this factor.
TIE_FACTOR = 5.0
#: Grid points of the term coefficient's marginal posterior.
GRID = 241
#: Largest number of residual evaluations of one least-squares fit.
MAX_NFEV = 40
#: Terms fitted in full after the screening (:func:`calibrate`).
N_REFINE = 3
#: Only terms whose screened evidence is within this many nats of the best are refined.
SCREEN_NATS = 100.0
#: ``ftol``, ``xtol`` and ``gtol`` of the least-squares fits: a change of the log
#: posterior below ~1e-5 is far below anything the evidence resolves.
TOL = 1e-6
#: Whitened residual of every feature of a recorded orbit that a trial point loses.
BARRIER = 1e5
KIND_NONE, KIND_PARAMS, KIND_TERM, KIND_UNEXPLAINED = (
    "none", "parameters off", "term missing", "unexplained")


class CalibrationError(BayesHopfError, ValueError):
    """A system or setting the calibration cannot work with."""


@dataclass(frozen=True)
class ParameterPosterior:
    """Posterior of one uncertain parameter, in physical units.

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

    @property
    def off(self) -> bool:
        """Whether the 90% interval excludes the nominal value."""
        lo, hi = sorted(self.ci90)
        return not (lo <= self.nominal <= hi)

    @property
    def shift(self) -> float:
        """Median relative to nominal, minus 1."""
        return self.median / self.nominal - 1.0

    def to_json(self) -> dict:
        """JSON-serialisable dict."""
        return {"name": self.name, "units": self.units, "prior": self.prior,
                "prior_scale": self.prior_scale, "nominal": self.nominal,
                "median": self.median, "ci90": list(self.ci90), "shift": self.shift,
                "off": self.off, "z": self.z, "z_sd": self.z_sd}


@dataclass(frozen=True)
class Calibration:
    """The uncertain parameters calibrated with no term (:math:`M_P`; module docstring).

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

    def __getitem__(self, name: str) -> ParameterPosterior:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(f"uncertain parameter expected among "
                       f"{', '.join(p.name for p in self.parameters)}; got {name!r}")

    @property
    def off(self) -> tuple[str, ...]:
        """The parameters whose 90% interval excludes their nominal value."""
        return tuple(p.name for p in self.parameters if p.off)

    def values(self) -> dict[str, float]:
        """Posterior medians by name."""
        return {p.name: p.median for p in self.parameters}


@dataclass(frozen=True)
class CalibratedTermFit:
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
        refined: Whether the term was fitted in full (:func:`fit_term`) or only
            screened by the linear model at the calibration (:func:`screen_term`).
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


@dataclass(frozen=True)
class CalibrationReport:
    """Result of :func:`calibrate` (immutable).

    Attributes:
        system: The simulator's name.
        verdict: ``kind`` (``"none"``, ``"parameters off"``, ``"term missing"``,
            ``"unexplained"``), ``probability`` (of the most probable class),
            ``parameters`` (named off), ``terms`` (named missing), ``sentence``.
        log_z: Log evidence of ``"none"`` (nominal), ``"parameters"`` and each term.
        probabilities: Posterior probability of the same models.
        class_probabilities: Of ``"none"``, ``"parameters off"``, ``"term missing"``.
        chi2_nominal: Misfit with every parameter nominal.
        n_features: Features less sensor offsets (the degrees of freedom before any fit).
        calibration: The parameters calibrated with no term.
        terms: Each term with the parameters, most probable first.
        seconds: Wall time per stage.
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
    seconds: Mapping[str, float] = field(default_factory=dict)

    def to_json(self) -> dict:
        """JSON-serialisable dict."""
        cal = self.calibration
        return {
            "system": self.system, "verdict": dict(self.verdict),
            "class_probabilities": dict(self.class_probabilities),
            "models": [{"name": k, "log_evidence": float(self.log_z[k]),
                        "probability": float(self.probabilities[k])} for k in self.log_z],
            "nominal": {"chi2": self.chi2_nominal, "dof": self.n_features},
            "calibration": {"chi2": cal.chi2, "p_eff": cal.p_eff, "status": cal.status,
                            "lost": list(cal.lost),
                            "parameters": [p.to_json() for p in cal.parameters]},
            "terms": [{"name": f.term.name, "probability": float(self.probabilities[f.term.name]),
                       "median": f.median, "ci90": list(f.ci90), "units": f.term.units,
                       "chi2": f.chi2, "log_evidence": f.log_z, "lost": list(f.lost),
                       "separability": f.separability, "refined": f.refined,
                       "parameters_off": [p.name for p in f.parameters if p.off],
                       "parameters": [p.to_json() for p in f.parameters] if f.refined else None}
                      for f in self.terms],
            "seconds": dict(self.seconds),
        }

    def summary(self) -> str:
        """The verdict, the calibrated parameters and the best terms, as plain text."""
        v = self.verdict
        lines = [f"Verdict ({v['kind']}, probability {v['probability']:.2f}): {v['sentence']}",
                 "", f"{'parameter':<10} {'nominal':>11} {'median':>11}   90% interval"
                 f"{'':<14} shift   off"]
        for p in self.calibration.parameters:
            lines.append(f"{p.name:<10} {p.nominal:>11.5g} {p.median:>11.5g}   "
                         f"[{p.ci90[0]:.5g}, {p.ci90[1]:.5g}]".ljust(62)
                         + f"{100 * p.shift:+6.2f}%  {'yes' if p.off else ''}")
        lines += ["", "model                        probability   log Z"]
        rows = [("none (nominal)", "none"), ("parameters calibrated", "parameters")]
        rows += [(f.term.name, f.term.name) for f in self.terms[:5]]
        for label, k in rows:
            lines.append(f"{label:<28} {self.probabilities[k]:>11.3g}   {self.log_z[k]:.1f}")
        return "\n".join(lines)


# --------------------------------------------------------------------------- engine


def _posteriors(unc: Sequence[UncertainParameter], nominal: np.ndarray, units: Sequence[str],
                z: np.ndarray, cov: np.ndarray) -> tuple[ParameterPosterior, ...]:
    out = []
    for j, u in enumerate(unc):
        sd = float(np.sqrt(max(cov[j, j], 0.0)))
        lo, hi = (float(u.value(z[j] + s * Z90 * sd, nominal[j])) for s in (-1, 1))
        out.append(ParameterPosterior(
            name=u.name, units=units[j], prior=u.prior, prior_scale=u.scale,
            nominal=float(nominal[j]), median=float(u.value(z[j], nominal[j])),
            ci90=(min(lo, hi), max(lo, hi)), z=float(z[j]), z_sd=sd))
    return tuple(out)


class _Problem:
    """Stacked whitened residuals :math:`E(x)` and their forward-difference Jacobian.

    Orbits are memoised by ``x``; a new ``x`` is reached by homotopy
    (:func:`~bayeshopf.discrepancy.orbits.track`) from the solved point with the
    fewest lost orbits, nearest in ``x``.
    """

    def __init__(self, fitter: Fitter, unc: Sequence[UncertainParameter], term: Term | None,
                 seeds: Sequence[tuple[np.ndarray, OrbitBatch]], *,
                 known: Sequence[tuple[np.ndarray, np.ndarray]] = (),
                 h0: np.ndarray | None = None):
        self.fitter, self.unc, self.term = fitter, tuple(unc), term
        self.d = len(self.unc)
        self.n = self.d + (term is not None)
        self.nominal = np.array([fitter.params0[u.name] for u in self.unc])
        self.memo: list[tuple[np.ndarray, OrbitBatch, np.ndarray]] = []
        # the orbits found at the start must stay found: a recorded orbit exists
        self.must = np.logical_or.reduce([ob.ok for _, ob in seeds])
        for x, ob in seeds:
            self._store(np.asarray(x, float), ob)
        self.h = np.full(self.n, 1e-3) if h0 is None else np.asarray(h0, float).copy()
        self.n_track = 0
        # data rows of Jacobian columns already known at some points (the calibration's)
        self.known = list(known)
        self.last: tuple[np.ndarray, np.ndarray] | None = None
        self.first: tuple[np.ndarray, np.ndarray] | None = None

    def params(self, x: np.ndarray) -> dict:
        p = dict(self.fitter.params0)
        for j, u in enumerate(self.unc):
            p[u.name] = float(u.value(x[j], self.nominal[j]))
        if self.term is not None:
            p[self.term.param] = float(self.term.scale * x[self.d])
        return p

    def _E(self, x: np.ndarray, ob: OrbitBatch) -> np.ndarray:
        e = self.fitter.residuals(ob)
        e[self.must & ~ob.ok] = BARRIER
        return np.concatenate([e.ravel(), x])

    def _store(self, x, ob) -> np.ndarray:
        E = self._E(x, ob)
        self.memo.append((x.copy(), ob, E))
        if len(self.memo) > 48:
            del self.memo[1]                                  # keep the seed
        return E

    def _track(self, x_from, ob_from, x_to) -> OrbitBatch:
        self.n_track += 1
        return track(self.fitter.system, self.params(x_from), self.params(x_to), ob_from,
                     self.fitter.stable)

    def solve(self, x: np.ndarray) -> tuple[OrbitBatch, np.ndarray]:
        x = np.asarray(x, float)
        for xm, ob, E in self.memo:
            if np.array_equal(xm, x):
                return ob, E
        xm, ob, _ = min(self.memo, key=lambda m: (-int(m[1].ok.sum()),
                                                  float(np.sum((m[0] - x) ** 2))))
        ob_new = self._track(xm, ob, x)
        return ob_new, self._store(x, ob_new)

    def residual(self, x: np.ndarray) -> np.ndarray:
        return self.solve(x)[1]

    def jacobian(self, x: np.ndarray, *_) -> np.ndarray:
        x = np.asarray(x, float)
        if self.last is not None and np.array_equal(self.last[0], x):
            return self.last[1].copy()
        ob, E = self.solve(x)
        R, P = self.fitter.mf.y.shape
        G = np.zeros((E.size, self.n))
        kn = next((J for xk, J in self.known if np.array_equal(xk[: J.shape[1]], x[: J.shape[1]])
                   and not np.any(x[J.shape[1]:])), None)
        for j in range(self.n):
            if kn is not None and j < kn.shape[1]:
                G[: R * P, j] = kn[:, j]
                continue
            h = self.h[j]
            xj = x.copy()
            xj[j] += h
            ob_j = self._track(x, ob, xj)
            col = (self._E(xj, ob_j) - E) / h
            bad = ~(ob.ok & ob_j.ok)
            col[: R * P].reshape(R, P)[bad] = 0.0
            G[:, j] = col
        G[R * P:] = np.eye(self.n)                             # the prior rows, exactly
        H = G.T @ G
        sd = np.sqrt(np.clip(np.diag(np.linalg.inv(H)), 0.0, None))
        self.h = np.clip(0.1 * sd, 1e-5, 1e-2)
        self.last = (x.copy(), G.copy())
        if self.first is None:
            self.first = self.last
        return G


def _minimise(prob: _Problem, x0: np.ndarray, max_nfev: int):
    lower = np.full(prob.n, -np.inf)
    if prob.term is not None and prob.term.positive:
        lower[-1] = 0.0
    res = optimize.least_squares(prob.residual, x0, jac=prob.jacobian, bounds=(lower, np.inf),
                                 method="trf", x_scale=1.0, ftol=TOL, xtol=TOL, gtol=TOL,
                                 max_nfev=max_nfev)
    x = res.x
    ob, E = prob.solve(x)
    return x, ob, E, prob.jacobian(x), res


def laplace_evidence(E: np.ndarray, G: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    r"""Log evidence of the linearised model :math:`E + G\delta` (priors as rows of ``E``).

    For residuals whose last rows are the standard normal prior rows of the
    unknowns, :math:`\int \mathcal N(\delta; 0, I)\,e^{-\frac12\lVert e + J\delta\rVert^2}\,
    d\delta` with the prior's own :math:`(2\pi)^{-d/2}` folded in:
    :math:`\log Z = -\tfrac12(\lVert E\rVert^2 - b^\top H^{-1}b) - \tfrac12\log\det H`,
    :math:`H = G^\top G`, :math:`b = G^\top E`.

    Args:
        E: Stacked whitened residuals, shape ``(N,)``.
        G: Their Jacobian, shape ``(N, d)``.

    Returns:
        ``(log_z, delta, cov)``: the log evidence, the step to the mode of the
        linearised model, and the posterior covariance :math:`H^{-1}`.
    """
    H = G.T @ G
    b = G.T @ E
    cov = np.linalg.inv(H)
    log_z = float(-0.5 * (E @ E - b @ cov @ b) - 0.5 * np.linalg.slogdet(H)[1])
    return log_z, -cov @ b, cov


def term_marginal(E: np.ndarray, G: np.ndarray, zeta: float, positive: bool, *,
                  n_grid: int = GRID) -> tuple[float, np.ndarray, np.ndarray]:
    r"""Log evidence and marginal posterior of the last unknown ζ, the others integrated out.

    With :math:`G = [G_z, g]` and :math:`P_\perp` the projection off the columns
    of :math:`G_z`, the linearised model gives
    :math:`\log p(y, \zeta') = -\tfrac12\lVert P_\perp(E + g(\zeta' - \zeta))\rVert^2
    - \tfrac12\log 2\pi\,[+\log 2] - \tfrac12\log\det G_z^\top G_z` (module
    docstring), integrated by Simpson's rule on a grid of :math:`\pm 6` standard
    deviations about its maximum (truncated at 0 when ``positive``: half-normal prior).

    Args:
        E: Stacked whitened residuals (ζ's prior row included), shape ``(N,)``.
        G: Their Jacobian, shape ``(N, d + 1)``, ζ last.
        zeta: The value of ζ at which ``E`` and ``G`` are evaluated.
        positive: Whether ζ ≥ 0 (half-normal prior).
        n_grid: Grid points.

    Returns:
        ``(log_z, grid, density)``: the log evidence, the grid of ζ and the
        normalised marginal posterior density on it.
    """
    Gz, g = G[:, :-1], G[:, -1]
    Q, _ = np.linalg.qr(Gz)
    a, bb = E - Q @ (Q.T @ E), g - Q @ (Q.T @ g)
    s2 = float(bb @ bb)
    sd = 1.0 / np.sqrt(s2)
    centre = zeta - float(a @ bb) / s2                         # maximum of the quadratic
    lo, hi = centre - 6 * sd, centre + 6 * sd
    if positive:
        lo = max(lo, 0.0)
        hi = max(hi, lo + 12 * sd)
    grid = np.linspace(lo, hi, n_grid)
    t = grid - zeta
    lp = -0.5 * (a @ a + 2 * t * (a @ bb) + t**2 * s2)
    mx = lp.max()
    dens = np.exp(lp - mx)
    area = float(integrate.simpson(dens, x=grid))       # exact to O(h⁴) even at a bound
    log_z = float(mx + np.log(area) - 0.5 * np.log(2 * np.pi)
                  + (np.log(2.0) if positive else 0.0)
                  - 0.5 * np.linalg.slogdet(Gz.T @ Gz)[1])
    return log_z, grid, dens / area


def fit_parameters(fitter: Fitter, unc: Sequence[UncertainParameter], *,
                   max_nfev: int = MAX_NFEV) -> Calibration:
    """Calibrate the uncertain parameters with no term (:math:`M_P`; module docstring).

    Args:
        fitter: Residuals of the recordings against the simulator (its
            ``base`` orbits are those at the nominal parameters).
        unc: The uncertain parameters.
        max_nfev: Largest number of residual evaluations.
    """
    d = len(unc)
    prob = _Problem(fitter, unc, None, [(np.zeros(d), fitter.base)])
    x, ob, E, G, res = _minimise(prob, np.zeros(d), max_nfev)
    R, P = fitter.mf.y.shape
    jac0 = prob.first[1][: R * P]                               # at z = 0, the first one
    _, delta, _ = laplace_evidence(E, G)
    ob_z, E_z = prob.solve(x + delta)                          # the linearised mode, re-shot
    if E_z @ E_z <= E @ E:
        x, ob, E = x + delta, ob_z, E_z
        G = prob.jacobian(x)
    log_z, delta, cov = laplace_evidence(E, G)
    z = x + delta
    e = E[: R * P].reshape(R, P)
    units = [fitter.system.param_units.get(u.name, "") for u in unc]
    return Calibration(
        parameters=_posteriors(unc, prob.nominal, units, z, cov), z_mode=x, cov=cov,
        log_z=log_z, chi2=float(np.sum(e**2)), p_eff=float(d - np.trace(cov)), e_mode=e,
        jac=G[: R * P], jac_nominal=jac0, orbits=ob,
        lost=tuple(int(i) for i in np.nonzero(~ob.ok)[0]), nfev=int(res.nfev),
        status=int(res.status))


def _term_problem(fitter: Fitter, unc: Sequence[UncertainParameter], term: Term,
                  cal: Calibration) -> tuple[_Problem, np.ndarray]:
    """The residuals over ``(z, ζ)``, seeded with the calibration (its orbits and Jacobian)."""
    d = len(unc)
    x0 = np.concatenate([cal.z_mode, [0.0]])
    sd = np.sqrt(np.clip(np.diag(cal.cov), 0.0, None))
    prob = _Problem(fitter, unc, term, [(np.zeros(d + 1), fitter.base), (x0, cal.orbits)],
                    known=[(cal.z_mode, cal.jac), (np.zeros(d), cal.jac_nominal)],
                    h0=np.concatenate([np.clip(0.1 * sd, 1e-5, 1e-2), [1e-3]]))
    return prob, x0


def _term_fit(prob: _Problem, x: np.ndarray, ob: OrbitBatch, E: np.ndarray, G: np.ndarray, *,
              refined: bool, status: int) -> CalibratedTermFit:
    """Marginal posterior, evidence and diagnostics of the term at ``x`` (module docstring)."""
    term, unc, fitter = prob.term, prob.unc, prob.fitter
    d = prob.d
    log_z, grid, dens = term_marginal(E, G, float(x[d]), term.positive)
    q = np.interp([0.05, 0.5, 0.95], _cdf(grid, dens), grid)
    _, delta, cov = laplace_evidence(E, G)
    R, P = fitter.mf.y.shape
    e, J = E[: R * P], G[: R * P]
    # refined: the misfit at the mode; screened: the linearised model's at its mode
    chi2 = float(e @ e) if refined else float(np.sum((e + J @ delta) ** 2))
    Jz, jc = J[:, :d], J[:, d]
    Q, _ = np.linalg.qr(Jz)
    sep = float(np.linalg.norm(jc - Q @ (Q.T @ jc)) / (np.linalg.norm(jc) or 1.0))
    units = [fitter.system.param_units.get(u.name, "") for u in unc]
    s = term.scale
    xm = x + delta
    if term.positive:
        xm[d] = max(xm[d], 0.0)
    return CalibratedTermFit(
        term=term, median=float(s * q[1]), ci90=(float(s * q[0]), float(s * q[2])),
        mode=float(s * xm[d]), log_z=log_z, chi2=chi2,
        p_eff=float(d + 1 - np.trace(cov)), separability=sep,
        parameters=_posteriors(unc, prob.nominal, units, xm[:d], cov[:d, :d]),
        grid=s * grid, density=dens / s, lost=tuple(int(i) for i in np.nonzero(~ob.ok)[0]),
        status=status, refined=refined)


def screen_term(fitter: Fitter, unc: Sequence[UncertainParameter], term: Term,
                cal: Calibration) -> CalibratedTermFit:
    r"""The term linearised at the calibration's mode: one re-shot orbit set per term.

    The calibration's Jacobian plus the term's column (a forward difference
    in ζ at ζ = 0) make a linear model in :math:`(z, \zeta)` whose evidence
    (:func:`term_marginal`) ranks the terms; :func:`calibrate` refits the best
    ones in full (``refined=False`` here).
    """
    prob, x0 = _term_problem(fitter, unc, term, cal)
    ob, E = prob.solve(x0)
    return _term_fit(prob, x0, ob, E, prob.jacobian(x0), refined=False, status=0)


def fit_term(fitter: Fitter, unc: Sequence[UncertainParameter], term: Term, cal: Calibration,
             *, start: str = "calibration", max_nfev: int = MAX_NFEV) -> CalibratedTermFit:
    r"""One term's coefficient fitted jointly with the uncertain parameters (:math:`M_k`).

    Args:
        fitter: Residuals of the recordings against the simulator.
        unc: The uncertain parameters.
        term: The term.
        cal: The calibration without a term (:func:`fit_parameters`).
        start: ``"calibration"``: from the better (lower :math:`\lVert E\rVert`)
            of the calibration's mode with ζ = 0 and the mode of the linear
            model there (fast when the calibration fits); ``"nominal"``: from
            the nominal parameters with ζ = 0 (when the calibration does not fit,
            its mode is a compromise far from any term's, and the fit is faster
            from nominal).
        max_nfev: Largest number of residual evaluations.

    Raises:
        CalibrationError: If ``start`` is neither.
    """
    prob, x0 = _term_problem(fitter, unc, term, cal)
    if start == "nominal":
        x_start = np.zeros_like(x0)
    elif start == "calibration":
        _, E0 = prob.solve(x0)
        _, delta, _ = laplace_evidence(E0, prob.jacobian(x0))
        x_lin = x0 + delta
        if term.positive:
            x_lin[-1] = max(x_lin[-1], 0.0)
        _, E_lin = prob.solve(x_lin)
        x_start = x_lin if E_lin @ E_lin < E0 @ E0 else x0
    else:
        raise CalibrationError(f"start must be 'calibration' or 'nominal'; got {start!r}")
    x, ob, E, G, res = _minimise(prob, x_start, max_nfev)
    return _term_fit(prob, x, ob, E, G, refined=True, status=int(res.status))


# ---------------------------------------------------------------------- front door


def _pct(p: ParameterPosterior) -> str:
    lo, hi = (100 * (v / p.nominal - 1) for v in p.ci90)
    return f"{p.name} {100 * p.shift:+.1f}% (90% {lo:+.1f}% to {hi:+.1f}%)"


def calibrate(recordings: RecordingSet, system: System | str, *, kinds: tuple[str, ...] = KINDS,
              K: int = DEFAULT_K, scan: bool = True, refine: int | None = N_REFINE,
              progress: bool = False, max_nfev: int = MAX_NFEV) -> CalibrationReport:
    """Calibrate the simulator's uncertain parameters, then scan the library for a missing term.

    **Main arguments**

    Args:
        recordings: Stable and unstable LCO recordings (μ and branch labelled).
        system: The simulator (with ``uncertain`` parameters declared), or its
            name for :func:`~bayeshopf.simulators.get_system`.
        kinds: Kinds of term in the library.
        scan: Also fit every library term jointly with the parameters; without
            it only "none" and "parameters off" are compared.
        refine: How many terms to fit in full: every term is first screened by
            the linear model at the calibration (:func:`screen_term`), then the
            ``refine`` with the highest screened evidence, among those within
            :data:`SCREEN_NATS` of the best, are fitted in full
            (:func:`fit_term`), then the most probable term as long as it is
            only screened. ``None``: every term in full; 0: none.

    **Other arguments**

    Args:
        K: Harmonics per channel.
        progress: Show a progress bar over the terms.
        max_nfev: Largest number of residual evaluations per least-squares fit.

    Returns:
        A :class:`CalibrationReport` (module docstring for the method).

    Raises:
        CalibrationError: If the system declares no uncertain parameters.
        BayesHopfError: Bad recordings, or a simulator without extra-force input.
    """
    ensure_x64()
    from tqdm.auto import tqdm

    t0 = time.perf_counter()
    system = get_system(system)
    unc = system.uncertain
    if not unc:
        raise CalibrationError(f"{system.name}: uncertain parameters expected (System."
                               "uncertain, a tuple of UncertainParameter); it declares none")
    fitter, _, notes = prepare(recordings, system, K, kinds)
    lib = fitter.lib
    secs = {"prepare": time.perf_counter() - t0}
    e0 = fitter.residuals(fitter.base)
    chi0 = float(np.sum(e0**2))
    log_z = {"none": -0.5 * chi0}
    t1 = time.perf_counter()
    cal = fit_parameters(fitter, unc, max_nfev=max_nfev)
    secs["calibrate"] = time.perf_counter() - t1
    log_z["parameters"] = cal.log_z
    fits: list[CalibratedTermFit] = []
    if scan:
        t1 = time.perf_counter()
        fits = [screen_term(fitter, unc, term, cal) for term in lib.terms]
        secs["screen"] = time.perf_counter() - t1
        t1 = time.perf_counter()
        n_ref = len(fits) if refine is None else min(int(refine), len(fits))
        # a calibration that leaves a significant misfit is a compromise: fit from nominal
        dof_p = fitter.mf.y.size - len(fitter.mf.layout.channels) - cal.p_eff
        start = "nominal" if stats.chi2.sf(cal.chi2, dof_p) < ALPHA else "calibration"
        order = [int(i) for i in np.argsort([-f.log_z for f in fits])]
        top_screened = fits[order[0]].log_z
        todo = [i for i in order[:n_ref] if fits[i].log_z >= top_screened - SCREEN_NATS]
        bar = tqdm(total=len(todo), desc="terms", disable=not progress, leave=False)
        while n_ref and (todo or not fits[int(np.argmax([f.log_z for f in fits]))].refined):
            # then the most probable term, as long as it is only screened
            i = todo.pop(0) if todo else int(np.argmax([f.log_z for f in fits]))
            t2 = time.perf_counter()
            fits[i] = fit_term(fitter, unc, fits[i].term, cal, start=start, max_nfev=max_nfev)
            secs[f"term {fits[i].term.name}"] = time.perf_counter() - t2
            bar.update()
        bar.close()
        secs["terms"] = time.perf_counter() - t1
    n = len(fits)
    for f in fits:
        log_z[f.term.name] = f.log_z
    names = list(log_z)
    lprior = ([np.log(1 / 3)] * 2 + [np.log(1 / (3 * n))] * n) if n else [np.log(0.5)] * 2
    lw = np.array(lprior) + np.array([log_z[k] for k in names])
    w = np.exp(lw - lw.max())
    w /= w.sum()
    probs = dict(zip(names, (float(v) for v in w), strict=True))
    order = np.argsort([-probs[f.term.name] for f in fits])
    fits = [fits[i] for i in order]
    classes = {KIND_NONE: probs["none"], KIND_PARAMS: probs["parameters"],
               KIND_TERM: float(sum(probs[f.term.name] for f in fits))}

    R, P = fitter.mf.y.shape
    dof0 = R * P - len(fitter.mf.layout.channels)
    best = max(classes, key=classes.get)
    if best == KIND_NONE:
        chi, dof = chi0, dof0
    elif best == KIND_PARAMS:
        chi, dof = cal.chi2, dof0 - cal.p_eff
    else:
        chi, dof = fits[0].chi2, dof0 - fits[0].p_eff
    significant = bool(stats.chi2.sf(chi, dof) < ALPHA)
    kind = KIND_UNEXPLAINED if significant else best
    off = [p for p in cal.parameters if p.off]
    named_terms: list[str] = []
    if kind == KIND_NONE:
        sentence = (f"The simulator with its nominal parameters matches the recordings within "
                    f"their noise (chi² {chi0:.0f} for {dof0} features).")
    elif kind == KIND_PARAMS:
        what = "; ".join(_pct(p) for p in off) if off else \
            "jointly, no single one outside its 90% interval"
        tail = (f" No term is missing (the most probable, {fits[0].term.plain}, has "
                f"probability {probs[fits[0].term.name]:.2g})." if fits else "")
        sentence = (f"The simulator's parameters are off: {what}. Calibrated, it fits the "
                    f"recordings within noise (chi² {chi0:.0f} → {cal.chi2:.0f} for {dof0} "
                    f"features).{tail}")
    elif kind == KIND_TERM:
        f0 = fits[0]
        named_terms = [f0.term.name]
        if n > 1 and probs[fits[1].term.name] * TIE_FACTOR >= probs[f0.term.name]:
            named_terms.append(fits[1].term.name)
        u = f" {f0.term.units}" if f0.term.units else ""
        off = [p for p in f0.parameters if p.off]
        sentence = (f"After calibrating the parameters the simulator lacks {f0.term.plain}: "
                    f"{f0.median:.3g}{u} (90% interval {f0.ci90[0]:.3g} to {f0.ci90[1]:.3g})"
                    + (f", or {fits[1].term.plain} (the data cannot tell them apart)"
                       if len(named_terms) > 1 else "")
                    + (f"; parameters off: {'; '.join(_pct(p) for p in off)}" if off else "")
                    + f" (chi² {chi0:.0f} → {f0.chi2:.0f} for {dof0} features).")
    else:
        sentence = (f"The simulator and the recordings disagree beyond noise even after "
                    f"calibration (chi² {chi0:.0f} → {chi:.0f} for {dof0} features, best "
                    f"model: {best})" + (f"; the best term, {fits[0].term.plain}, is only "
                                         "partial" if fits else "") + ".")
    if notes:
        sentence += " Note: " + " ".join(notes)
    verdict = {"kind": kind, "probability": classes[best],
               "parameters": [p.name for p in off] if kind in (KIND_PARAMS, KIND_TERM) else [],
               "terms": named_terms, "sentence": sentence}
    secs["total"] = time.perf_counter() - t0
    return CalibrationReport(system=system.name, verdict=verdict, log_z=log_z,
                             probabilities=probs, class_probabilities=classes,
                             chi2_nominal=chi0, n_features=dof0, calibration=cal,
                             terms=tuple(fits), seconds=secs)
