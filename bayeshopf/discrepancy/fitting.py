r"""The joint fits: uncertain parameters alone, with one term, with a pair of terms.

**Parameters alone** (:math:`M_P`, :func:`fit_parameters`): the mode of the
stacked residuals (:mod:`~bayeshopf.discrepancy.problem`) from nominal, its
Laplace evidence with τ integrated out (:mod:`~bayeshopf.discrepancy.evidence`).

**One term** (:math:`M_k`). *Screened* (:func:`screen_term`): the
calibration's Jacobian plus the term's own column (its exact derivative in ζ
at ζ = 0, from the calibration's orbits) make a linear model in :math:`(z, \zeta)`
whose evidence is that of :func:`~bayeshopf.discrepancy.evidence.term_marginal`
at the calibration. *Fitted in full* (:func:`fit_term`): the joint mode, from
the calibration or from the nominal parameters (a calibration that cannot
explain the data is a compromise that has pushed weakly identified parameters
far out to absorb what a term would explain, and the fit with the right term
converges faster from nominal than from that compromise).

**Pairs.** Screened with both columns at the calibration (:func:`screen_pair`,
no orbit shot), or stepwise, a second term added to a refined single term at
its mode (:func:`screen_second`, no orbit re-shot), which finds a
second term whose signature only shows once the first is in; fitted in full
by :func:`refit_pair`. The coefficients' correlation says whether the data
see both terms or only their combination.

**The linearisation checked, for every model.** Every evidence here is a
Laplace evidence about some point: the calibration's mode (screened terms and
pairs), a refined single term's mode (stepwise pairs) or a model's own mode
(refined fits). Each pays the same charge
(:func:`~bayeshopf.discrepancy.problem.charge`): the orbits are re-shot at the
linear model's mode and the misfit it promised is replaced by the lower of
the re-shot one and the one at the point of expansion. A screened model
costs one more orbit set for it; without it a screened model would keep a
credit that a refined one on the same linearisation pays back, and the two
would not be comparable in one posterior.

**Refits.** The modes are found at a fixed whitening, and a fit is redone at
its own posterior median of τ when that changes σ by more than
:data:`REFIT_FACTOR` (:func:`needs_refit`, :func:`refit_term`,
:func:`refit_pair`): a mode found with one weighting is not the mode of
another, and the linearised step between them is not to be trusted when the
posterior is several times narrower.

**Parameters off, checked** (:func:`check_off`). The 90% intervals are
reported as they are; the stricter test of
:attr:`~bayeshopf.discrepancy.records.ParameterPosterior.off` keeps the
verdict from naming a nominal parameter off by chance (with 90% intervals
each nominal parameter would be named with probability about 0.1). The
pinned refit is there because the posterior of weakly identified parameters
(the aerodynamic lag coefficients) need not be Gaussian: it can have a second
mode behind a ridge, and the Laplace interval of one mode can exclude a
nominal value that the other mode holds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from scipy import stats

from bayeshopf.discrepancy.evidence import (
    GRID,
    TAU,
    _at_tau,
    _gauss_evidence,
    _model_error,
    _rewhiten,
    _zeta_density,
    _zeta_gaussian,
    laplace_evidence,
)
from bayeshopf.discrepancy.nested import CoefficientPosterior, gaussian_marginal
from bayeshopf.discrepancy.orbits import OrbitBatch
from bayeshopf.discrepancy.problem import (
    MAX_NFEV,
    Problem,
    charge,
    charge_at_every_tau,
    minimise,
    polish,
)
from bayeshopf.discrepancy.records import (
    CalibratedPairFit,
    CalibratedTermFit,
    Calibration,
    CalibrationError,
    ParameterPosterior,
    posteriors,
)
from bayeshopf.discrepancy.select import Fitter, _cdf
from bayeshopf.discrepancy.terms import Term
from bayeshopf.simulators.base import UncertainParameter

__all__ = ["PROFILE_NFEV", "REFIT_FACTOR", "check_off", "fit_parameters", "fit_term",
           "needs_refit", "refit_pair", "refit_term", "screen_pair", "screen_second",
           "screen_term"]

#: A fit is redone at the inferred τ when σ(τ) differs from the whitening's σ by more
#: than this factor (root mean square of the log ratio over the features).
REFIT_FACTOR = 1.5
#: Largest number of residual evaluations of a pinned refit.
PROFILE_NFEV = 10


def _coefficients(fitter: Fitter, E: np.ndarray, G: np.ndarray, ok: np.ndarray, x: np.ndarray,
                  me, terms: Sequence[Term]) -> CoefficientPosterior:
    """The terms' Laplace marginal at every τ of non-negligible weight under the model.

    A :class:`~bayeshopf.discrepancy.nested.CoefficientPosterior`, for Savage–Dickey.
    """
    keep = np.nonzero(me.weights > 1e-12 * me.weights.max())[0]
    Es, Gs, _ = _rewhiten(fitter, E, G, ok, TAU[keep])
    means, covs = gaussian_marginal(Es, Gs, x, len(terms))
    w = me.weights[keep]
    return CoefficientPosterior(w / w.sum(), means, covs, tuple(t.positive for t in terms))


def fit_parameters(fitter: Fitter, unc: Sequence[UncertainParameter], *,
                   max_nfev: int = MAX_NFEV, start: Calibration | None = None) -> Calibration:
    """Calibrate the uncertain parameters with no term (:math:`M_P`; module docstring).

    Args:
        fitter: Residuals of the recordings against the simulator (its
            ``base`` orbits are those at the nominal parameters).
        unc: The uncertain parameters.
        max_nfev: Largest number of residual evaluations.
        start: A calibration with another whitening (another ``model_error``
            of the fitter) to start from: its mode, orbits and nominal Jacobian.
    """
    d = len(unc)
    R, P = fitter.mf.y.shape
    seeds = [(np.zeros(d), fitter.base)]
    if start is None:
        x0, known = np.zeros(d), []
    else:
        seeds.append((start.z_mode, start.orbits))
        x0 = start.z_mode.copy()
        old = start.fitter
        jn = _at_tau(old, np.zeros(R * P), start.jac_nominal, fitter.base.ok,
                     fitter.model_error)[1]
        known = [(np.zeros(d), jn)]
    prob = Problem(fitter, unc, None, seeds, known=known)
    x, ob, E, G, res = minimise(prob, x0, max_nfev)
    jac0 = known[0][1] if known else prob.first[1][: R * P]   # at z = 0, the first one
    def evidence(x, E, G, ok, penalty):
        return _model_error(fitter, E, G, ok, lambda Es, Gs: laplace_evidence(Es, Gs)[0],
                            penalty)[0]

    x, ob, E, G, me, _ = _charged(prob, x, ob, E, G, evidence, refined=True)
    _, delta, cov = laplace_evidence(*_at_tau(fitter, E, G, ob.ok, me.median))
    z = x + delta
    e = E[: R * P].reshape(R, P)
    units = [fitter.system.param_units.get(u.name, "") for u in unc]
    return Calibration(
        parameters=posteriors(unc, prob.nominal, units, z, cov), z_mode=x, cov=cov,
        log_z=me.log_z, chi2=float(np.sum(e**2)), p_eff=float(d - np.trace(cov)), e_mode=e,
        jac=G[: R * P], jac_nominal=jac0, orbits=ob,
        lost=tuple(int(i) for i in np.nonzero(~ob.ok)[0]), nfev=int(res.nfev),
        status=int(res.status), model_error=me, fitter=fitter)



def _term_problem(fitter: Fitter, unc: Sequence[UncertainParameter], term: Term,
                  cal: Calibration) -> tuple[Problem, np.ndarray]:
    """The residuals over ``(z, ζ)``, seeded with the calibration (its orbits and Jacobian)."""
    d = len(unc)
    x0 = np.concatenate([cal.z_mode, [0.0]])
    prob = Problem(fitter, unc, term, [(np.zeros(d + 1), fitter.base), (x0, cal.orbits)],
                    known=[(cal.z_mode, cal.jac), (np.zeros(d), cal.jac_nominal)])
    return prob, x0


def _charged(prob, x, ob, E, G, evidence, refined: bool):
    """The evidence at ``x`` with its linearisation charge paid at every τ.

    A refined fit is polished first (:func:`~bayeshopf.discrepancy.problem.polish`:
    the linear step once, where the re-shot orbits confirm it). Then the orbits
    are re-shot at the linear model's mode (:func:`~bayeshopf.discrepancy.problem.charge`)
    and the evidence is integrated over τ with the charge at each τ
    (:func:`~bayeshopf.discrepancy.problem.charge_at_every_tau`). ``evidence``
    maps ``(x, E, G, ok, penalty)`` to a :class:`~bayeshopf.discrepancy.records.ModelError`.

    Returns:
        ``(x, ob, E, G, model_error, penalty)`` at the point kept; ``penalty``
        is the fall of the log evidence that the charge makes.
    """
    me = evidence(x, E, G, ob.ok, None)
    if refined:
        x, ob, E, G, _ = polish(prob, x, ob, E, G, me.median)
        me = evidence(x, E, G, ob.ok, None)
    c = charge(prob, x, ob, E, G, me.median)
    charged = evidence(x, E, G, ob.ok, charge_at_every_tau(prob, x, c))
    return x, ob, E, G, charged, me.log_z - charged.log_z


def _term_fit(prob: Problem, x: np.ndarray, ob: OrbitBatch, E: np.ndarray, G: np.ndarray, *,
              refined: bool, status: int) -> CalibratedTermFit:
    """Marginal posterior, evidence and diagnostics of the term at ``x``.

    The evidence and marginal are those of :mod:`~bayeshopf.discrepancy.evidence`.
    τ is integrated out on :data:`TAU`; the coefficient's marginal is the
    mixture over τ of its normal marginals; the parameters' posterior and the
    linearised misfit are those at the median of τ.
    """
    term, unc, fitter = prob.term, prob.unc, prob.fitter
    d = prob.d

    def evidence(x, E, G, ok, penalty):
        return _model_error(fitter, E, G, ok,
                            lambda Es, Gs: _zeta_gaussian(Es, Gs, float(x[d]),
                                                          term.positive)[0], penalty)[0]

    x, ob, E, G, me, penalty = _charged(prob, x, ob, E, G, evidence, refined)
    zeta = float(x[d])
    keep = np.nonzero(me.weights > 1e-6 * me.weights.max())[0]
    Es, Gs, _ = _rewhiten(fitter, E, G, ob.ok, TAU[keep])
    _, centres, sds = _zeta_gaussian(Es, Gs, zeta, term.positive)
    parts = [(float(c), float(sd)) for c, sd in zip(centres, sds, strict=True)]
    lo = min(c - 6 * sd for c, sd in parts)
    lo = max(lo, 0.0) if term.positive else lo
    grid = np.linspace(lo, max(max(c + 6 * sd for c, sd in parts), lo + 1e-12), 2 * GRID - 1)
    dens = sum(me.weights[k] * _zeta_density(grid, c, sd, term.positive)
               for k, (c, sd) in zip(keep, parts, strict=True)) / me.weights[keep].sum()
    q = np.interp([0.05, 0.5, 0.95], _cdf(grid, dens), grid)
    Et, Gt = _at_tau(fitter, E, G, ob.ok, me.median)
    _, delta, cov = laplace_evidence(Et, Gt)
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
        mode=float(s * xm[d]), log_z=me.log_z, chi2=chi2,
        p_eff=float(d + 1 - np.trace(cov)), separability=sep,
        parameters=posteriors(unc, prob.nominal, units, xm[:d], cov[:d, :d]),
        grid=s * grid, density=dens / s, lost=tuple(int(i) for i in np.nonzero(~ob.ok)[0]),
        status=status, refined=refined, orbits=ob, model_error=me,
        column=G[: R * P, d] if not refined else None, x=x, jac=G[: R * P], fitter=fitter,
        penalty=penalty, log_z_laplace=me.log_z,
        coefficients=_coefficients(fitter, E, G, ob.ok, x, me, (term,)))


def screen_term(fitter: Fitter, unc: Sequence[UncertainParameter], term: Term,
                cal: Calibration) -> CalibratedTermFit:
    r"""The term linearised at the calibration's mode: no orbit re-shot.

    The calibration's Jacobian plus the term's column (its exact derivative
    in ζ at ζ = 0) make a linear model in :math:`(z, \zeta)` whose evidence
    (:func:`~bayeshopf.discrepancy.evidence.term_marginal`) ranks the terms;
    :func:`~bayeshopf.discrepancy.calibration.calibrate` refits the best
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
    x, ob, E, G, res = minimise(prob, x_start, max_nfev)
    return _term_fit(prob, x, ob, E, G, refined=True, status=int(res.status))


def _pair_fit(fitter: Fitter, unc: Sequence[UncertainParameter], terms: tuple[Term, Term],
              nominal: np.ndarray, x: np.ndarray, ob: OrbitBatch, E: np.ndarray, G: np.ndarray,
              *, refined: bool, prob: Problem) -> CalibratedPairFit:
    d = len(unc)
    pos = [d + k for k, t in enumerate(terms) if t.positive]

    def evidence(x, E, G, ok, penalty):
        return _model_error(fitter, E, G, ok,
                            lambda Es, Gs: _gauss_evidence(Es, Gs, x, pos), penalty)[0]

    x, ob, E, G, me, penalty = _charged(prob, x, ob, E, G, evidence, refined)
    Et, Gt = _at_tau(fitter, E, G, ob.ok, me.median)
    _, delta, cov = laplace_evidence(Et, Gt)
    xm = x + delta
    R, P = fitter.mf.y.shape
    e, J = E[: R * P], G[: R * P]
    chi2 = float(e @ e) if refined else float(np.sum((e + J @ delta) ** 2))
    med, ci = [], []
    for k, t in enumerate(terms):
        m, sd = xm[d + k], np.sqrt(cov[d + k, d + k])
        if t.positive:
            dist = stats.truncnorm((0.0 - m) / sd, np.inf, loc=m, scale=sd)
        else:
            dist = stats.norm(m, sd)
        q = dist.ppf([0.05, 0.5, 0.95])
        med.append(float(t.scale * q[1]))
        ci.append((float(t.scale * q[0]), float(t.scale * q[2])))
    corr = float(cov[d, d + 1] / np.sqrt(cov[d, d] * cov[d + 1, d + 1]))
    units = [fitter.system.param_units.get(u.name, "") for u in unc]
    return CalibratedPairFit(
        terms=terms, medians=(med[0], med[1]), ci90=(ci[0], ci[1]), log_z=me.log_z, chi2=chi2,
        p_eff=float(d + 2 - np.trace(cov)), correlation=corr,
        parameters=posteriors(unc, nominal, units, xm[:d], cov[:d, :d]), model_error=me,
        orbits=ob, lost=tuple(int(i) for i in np.nonzero(~ob.ok)[0]), refined=refined, x=x,
        fitter=fitter, penalty=penalty, log_z_laplace=me.log_z,
        coefficients=_coefficients(fitter, E, G, ob.ok, x, me, terms))


def screen_pair(fitter: Fitter, unc: Sequence[UncertainParameter], a: CalibratedTermFit,
                b: CalibratedTermFit, cal: Calibration) -> CalibratedPairFit:
    """Two screened terms together, linearised at the calibration (no orbit is shot).

    Args:
        fitter: The residuals the calibration and the screening used.
        unc: The uncertain parameters.
        a: One term, as :func:`screen_term` returned it (its ``column``).
        b: The other.
        cal: The calibration.
    """
    if a.column is None or b.column is None:
        raise CalibrationError("screen_pair expects screened terms (screen_term, with their "
                               f"Jacobian column); got refined fits of {a.term.name}, "
                               f"{b.term.name}")
    d = len(unc)
    R, P = fitter.mf.y.shape
    x = np.concatenate([cal.z_mode, [0.0, 0.0]])
    E = np.concatenate([cal.e_mode.ravel(), x])
    G = np.zeros((R * P + d + 2, d + 2))
    G[: R * P, :d] = cal.jac
    G[: R * P, d], G[: R * P, d + 1] = a.column, b.column
    G[R * P:] = np.eye(d + 2)
    prob = Problem(fitter, unc, (a.term, b.term), [(np.zeros(d + 2), fitter.base),
                                                    (x, cal.orbits)])
    return _pair_fit(fitter, unc, (a.term, b.term), prob.nominal, x, cal.orbits, E, G,
                     refined=False, prob=prob)


def screen_second(unc: Sequence[UncertainParameter], first: CalibratedTermFit, term: Term
                  ) -> CalibratedPairFit:
    """A second term added to a refined single-term fit, linearised at that fit's mode.

    The first fit's Jacobian is reused; only the new term's column is computed
    (exactly, at the first fit's orbits), so every term can be tried as the
    second one of a pair: the forward step of a stepwise search, which finds a
    second term whose signature only shows in the residual of the first.
    """
    if first.jac is None or first.fitter is None:
        raise CalibrationError(f"screen_second expects a fit from fit_term; got "
                               f"{first.term.name} without its Jacobian")
    fitter = first.fitter
    d = len(unc)
    x0 = np.concatenate([first.x, [0.0]])
    prob = Problem(fitter, unc, (first.term, term),
                    [(np.zeros(d + 2), fitter.base), (x0, first.orbits)],
                    known=[(first.x, first.jac)])
    ob, E = prob.solve(x0)
    return _pair_fit(fitter, unc, (first.term, term), prob.nominal, x0, ob, E,
                     prob.jacobian(x0), refined=False, prob=prob)


def needs_refit(fitter: Fitter, tau: float) -> bool:
    """Whether σ at ``tau`` differs from the fitter's by more than :data:`REFIT_FACTOR`."""
    r = np.log(fitter.sigma_at(tau) / fitter.sigma)
    return bool(np.sqrt(np.mean(r**2)) > np.log(REFIT_FACTOR))


def refit_term(fitter: Fitter, unc: Sequence[UncertainParameter], fit: CalibratedTermFit, *,
               max_nfev: int = MAX_NFEV) -> CalibratedTermFit:
    """A refined term fit redone with another whitening (``fitter``), from its own mode."""
    prob = Problem(fitter, unc, fit.term, [(np.zeros(len(unc) + 1), fitter.base),
                                            (fit.x, fit.orbits)])
    x, ob, E, G, res = minimise(prob, fit.x.copy(), max_nfev)
    return _term_fit(prob, x, ob, E, G, refined=True, status=int(res.status))


def refit_pair(fitter: Fitter, unc: Sequence[UncertainParameter], fit: CalibratedPairFit, *,
               max_nfev: int = MAX_NFEV) -> CalibratedPairFit:
    """A pair fitted in full from the point of ``fit`` (screened or refined), with ``fitter``."""
    prob = Problem(fitter, unc, fit.terms, [(np.zeros(len(unc) + 2), fitter.base),
                                             (fit.x, fit.orbits)])
    x, ob, E, G, _ = minimise(prob, fit.x.copy(), max_nfev)
    return _pair_fit(fitter, unc, fit.terms, prob.nominal, x, ob, E, G, refined=True,
                     prob=prob)


def check_off(fitter: Fitter, unc: Sequence[UncertainParameter], terms: Sequence[Term],
              x: np.ndarray, orbits: OrbitBatch, params: Sequence[ParameterPosterior],
              tau: float, *, max_nfev: int = PROFILE_NFEV) -> tuple[ParameterPosterior, ...]:
    r"""Profile-likelihood check of each parameter whose Laplace posterior names it off.

    The Laplace interval is a local, Gaussian statement; where the posterior
    has a second mode or a curved ridge (the aerodynamic lag coefficients trade
    against the stiffnesses) it can exclude a nominal value that a refit with
    that parameter pinned at nominal explains as well. For each such
    parameter the others (and the terms) are refitted with it pinned; it stays
    "off" when :math:`-2\log p(x\mid y)`, at the model error ``tau``, rises by more
    than the parameter's :math:`z_{\rm off}^2` (:func:`off_threshold`).

    Args:
        fitter: The residuals of the fit.
        unc: The uncertain parameters.
        terms: The model's terms (none for the calibration).
        x: Its mode ``(z, ζ...)``.
        orbits: The orbits there.
        params: The parameters' posterior of the model.
        tau: The model error at which the objectives are compared.
        max_nfev: Residual evaluations of each pinned refit.

    Returns:
        ``(params, better)``: ``params`` with ``pinned`` set where it was
        checked, and ``(x, orbits)`` of the lowest point found below the mode
        by a pinned refit (the mode was a local one), or ``None``.
    """
    d = len(unc)
    full = Problem(fitter, unc, tuple(terms) or None, [(np.asarray(x, float), orbits)])
    ob, E = full.solve(x)

    def obj(E_, ok):
        Et, _ = _at_tau(fitter, E_, np.zeros((E_.size, 0)), ok, tau)
        return float(Et @ Et)

    base = obj(E, ob.ok)
    out = list(params)
    better, lowest = None, 0.0
    for j, p in enumerate(params):
        if not p.off:
            continue
        keep = [k for k in range(d) if k != j]
        x0 = np.concatenate([np.asarray(x)[keep], np.asarray(x)[d:]])
        prob = Problem(fitter, [unc[k] for k in keep], tuple(terms) or None,
                        [(np.zeros(x0.size), fitter.base)])
        ob0, E0 = prob.solve(x0)
        rise = obj(E0, ob0.ok) - base
        x1, ob1 = x0, ob0
        if rise > p.z_off**2:
            x1, ob1, E1, _, _ = minimise(prob, x0, max_nfev)
            rise = min(rise, obj(E1, ob1.ok) - base)
        if rise < lowest:
            lowest = rise
            better = (np.insert(np.asarray(x1, float), j, 0.0), ob1)
        out[j] = replace(p, pinned=float(rise))
    return tuple(out), better

