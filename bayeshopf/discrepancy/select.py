r"""Which single library term explains the recordings: coefficients, evidence, verdict.

**Likelihood.** With measured features :math:`y_{r}` of recording :math:`r`
(:mod:`bayeshopf.discrepancy.features`), their standard errors
:math:`s_{r}` and the simulator's features :math:`g_r(c)` with a term of
coefficient :math:`c`,

.. math::

    -2\log p(y \mid c, o) = \sum_{r,j}
        \frac{(y_{rj} - g_{rj}(c) - o_{c(j)}[j \text{ is a mean}])^2}{\sigma_{rj}^2}
        + \text{const},
    \qquad \sigma_{rj}^2 = \tfrac{m_r-1}{m_r-3}\,s_{rj}^2 + \text{floor}_{rj}^2,

where :math:`o_c` is the offset of sensor :math:`c`, shared by all recordings
(one nuisance per channel, flat prior), and :math:`m_r` the number of
segments (the factor turns the segment-spread standard error into the
variance of a Student-t with :math:`m_r-1` degrees of freedom). The offsets
enter linearly, so they are marginalised exactly: the residuals of the means
are replaced by their deviations from the :math:`1/\sigma^2`-weighted mean over
recordings; the remaining Gaussian normalisations are the same for every
model and cancel in the comparison. The **model-error floor** is
:data:`FLOOR_REL` (0.1%) of the channel's first-harmonic magnitude for every
coefficient and mean, and :data:`FLOOR_FREQ` (0.01%) of the frequency. It
lies far above the disagreement of the feature estimator and the shooting
solver on noise-free simulated recordings, so it does not hide numerical
error; it stands for what no rig reproduces better than 0.1% (sensor
calibration, small temperature drifts) and keeps a well-measured record from
declaring a 0.01% discrepancy significant.

An orbit that the simulator with the term does not have at a recording's μ
(its branch's fold moved past μ) contributes a large but finite misfit,
:data:`LOST_CHI2` per feature, and is listed.

**Posterior of each term.** :math:`c \sim \mathcal N(0, s_k^2)`
(half-normal, :math:`c \ge 0`, for a freeplay gap and the dissipative terms:
:meth:`~bayeshopf.discrepancy.terms.Term.log_prior`) with the library's prior
scale. The mode is
found by Gauss–Newton on the whitened residuals with the orbits re-shot at
every iterate (homotopy from the previous one) and the exact sensitivities
of the orbits (:func:`~bayeshopf.discrepancy.orbits.sensitivities`); then the
features are linearised at the mode and the 1-D posterior is evaluated on a
grid of :math:`\pm 6` posterior standard deviations, which gives the median,
the 90% interval and the marginal likelihood
:math:`Z_k = \int p(y\mid c)\,p(c)\,dc` (trapezoid rule).

**Selection.** A discrete spike-and-slab over single terms: prior
probability 1/2 that nothing is missing (:math:`c = 0`, :math:`Z_0 = p(y\mid 0)`)
and 1/2 shared equally by the terms, so
:math:`P(k\mid y) \propto \pi_k Z_k`. Single terms only: one missing effect at a
time is what the evidence can resolve from a handful of recordings.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from bayeshopf.discrepancy.features import MeasuredFeatures, simulated
from bayeshopf.discrepancy.orbits import OrbitBatch, sensitivities, track
from bayeshopf.discrepancy.terms import Library, Term, library_params
from bayeshopf.simulators.base import System

__all__ = ["ALPHA", "FLOOR_FREQ", "FLOOR_REL", "TIE_FACTOR", "Fitter", "TermFit"]

#: Significance level of a misfit (:math:`\chi^2` survival probability below it).
ALPHA = 1e-3
#: Two models are named together when their probabilities are within this factor.
TIE_FACTOR = 5.0

FLOOR_REL = 1e-3
FLOOR_FREQ = 1e-4
LOST_CHI2 = 25.0
GRID = 241
GN_ITER = 4


@dataclass(frozen=True)
class TermFit:
    """Posterior of one term's coefficient.

    Attributes:
        term: The term.
        mode: Posterior mode (Gauss–Newton).
        sd: Posterior standard deviation (linearised).
        median: Posterior median.
        ci90: 5% and 95% quantiles.
        log_z: Log marginal likelihood (common constants dropped).
        chi2: Misfit at the mode.
        grid: Grid of coefficient values.
        density: Posterior density on the grid.
        lost: Recordings whose orbit the system with the term lacks (at the mode).
        e_mode: Whitened residuals at the mode, shape ``(R, P)``.
        jac: Their derivative in c, shape ``(R, P)``.
        orbits: The orbits at the mode.
    """

    term: Term
    mode: float
    sd: float
    median: float
    ci90: tuple[float, float]
    log_z: float
    chi2: float
    grid: np.ndarray
    density: np.ndarray
    lost: tuple[int, ...]
    e_mode: np.ndarray
    jac: np.ndarray
    orbits: OrbitBatch

    def draws(self, n: int, seed: int = 0) -> np.ndarray:
        """``n`` draws of c from the grid posterior (inverse CDF)."""
        cdf = _cdf(self.grid, self.density)
        u = (np.arange(n) + np.random.default_rng(seed).uniform()) / n
        return np.interp(u, cdf, self.grid)


def _cdf(x, d):
    c = np.concatenate([[0.0], np.cumsum(0.5 * (d[1:] + d[:-1]) * np.diff(x))])
    return c / c[-1]


class Fitter:
    r"""Whitened residuals of the simulator with one term against the measured features.

    Args:
        system: The simulator with every term of ``lib`` (coefficients ``dc_<name>``).
        lib: The library.
        mf: The measured features.
        base: The simulator's orbits at the recordings with every coefficient 0.
        model_error: Relative model error τ of the whitening,
            :math:`\sigma^2 = \text{noise} + (\tau\,\text{ref})^2` (the floor above;
            :mod:`~bayeshopf.discrepancy.calibration` infers it).
    """

    def __init__(self, system: System, lib: Library, mf: MeasuredFeatures, base: OrbitBatch,
                 model_error: float = FLOOR_REL):
        self.system, self.lib, self.mf, self.base = system, lib, mf, base
        self.model_error = float(model_error)
        self.params0 = {**system.params, **library_params(lib)}
        self.stable = np.array([b == "stable" for b in mf.branch])
        lay = mf.layout
        self.obs = [system.state_names.index(c) for c in lay.channels]
        m = np.maximum(mf.n_segments, 4).astype(float)
        infl = (m - 1) / (m - 3)
        # floor: per channel first-harmonic magnitude of each recording
        h1 = np.stack([np.abs(mf.y[:, lay.labels.index(f"{c}:Re1")]
                              + 1j * (mf.y[:, lay.labels.index(f"{c}:Im1")]
                                      if f"{c}:Im1" in lay.labels else 0.0))
                       for c in lay.channels], axis=1)
        ref = np.zeros_like(mf.y)
        for j, (kind, ch) in enumerate(zip(lay.kind, lay.channel, strict=True)):
            ref[:, j] = ((FLOOR_FREQ / FLOOR_REL) * mf.y[:, 0] if kind == "f"
                         else h1[:, lay.channels.index(ch)])
        #: σ² = noise + (model_error · ref)²: the segments' variance of the mean and
        #: the scale of a relative model error (first-harmonic magnitude; a tenth
        #: of the frequency for the frequency)
        self.noise_var = infl[:, None] * mf.se**2
        self.ref = ref
        self.sigma = self.sigma_at(self.model_error)
        self.mean_cols = [j for j, k in enumerate(lay.kind) if k == "mean"]

    def sigma_at(self, model_error: float | np.ndarray) -> np.ndarray:
        """Standard deviation of every feature, ``(R, P)``, at a relative model error.

        An array of model errors broadcasts against ``(R, P)`` (``(S, 1, 1)``
        gives ``(S, R, P)``).
        """
        return np.sqrt(self.noise_var + (model_error * self.ref) ** 2)

    def with_model_error(self, model_error: float) -> Fitter:
        """The same fitter whitening with another relative model error."""
        return Fitter(self.system, self.lib, self.mf, self.base, model_error)

    def features(self, ob: OrbitBatch) -> np.ndarray:
        """Simulated features ``(R, P)`` (NaN rows where an orbit is lost)."""
        out = np.full_like(self.mf.y, np.nan)
        ok = np.asarray(ob.ok, bool)
        if ok.any():
            out[ok] = simulated(self.mf.layout, ob.states[ok][:, :, self.obs], ob.period[ok])
        return out

    def residuals(self, ob: OrbitBatch) -> np.ndarray:
        """Whitened residuals ``(R, P)``, offsets profiled out; lost rows: ``±√LOST_CHI2``."""
        e = (self.mf.y - self.features(ob)) / self.sigma
        ok = ob.ok
        for j in self.mean_cols:
            w = 1.0 / self.sigma[ok, j] ** 2
            if ok.any():
                off = np.sum(w * e[ok, j] * self.sigma[ok, j]) / w.sum()
                e[:, j] = e[:, j] - off / self.sigma[:, j]
        e[~ok] = np.sqrt(LOST_CHI2)
        return e

    def derivatives(self, ob: OrbitBatch, params: dict, names: Sequence[str], *,
                    orbits: bool = False):
        """Exact derivatives ``(R, P, m)`` of the whitened residuals in ``params[names]``.

        The orbits' derivatives come from one implicit solve at ``ob``
        (:func:`~bayeshopf.discrepancy.orbits.sensitivities`); the features are
        smooth functions of an orbit's samples and period (Fourier coefficients
        with a fixed phase, the frequency), differentiated along each exact
        direction by a central difference of 10⁻⁶ of the orbits' size, which
        re-solves no orbit. A lost orbit's rows are 0.

        With ``orbits``, also returns the orbits' own derivatives
        ``(∂x0/∂p, ∂T/∂p)``, shapes ``(R, n, m)`` and ``(R, m)``.
        """
        R, P = self.mf.y.shape
        out = np.zeros((R, P, len(names)))
        ok = ob.ok
        if not ok.any():
            n = ob.x0.shape[1]
            return (out, np.zeros((R, n, len(names))), np.zeros((R, len(names)))) if orbits \
                else out
        dS, dT = sensitivities(self.system, params, ob, names)
        size = float(np.max(np.abs(ob.states[ok])))
        for c in range(len(names)):
            rel = max(float(np.max(np.abs(dS[ok, ..., c]))) / size,
                      float(np.max(np.abs(dT[ok, c] / ob.period[ok]))))
            if rel == 0.0:
                continue
            h = 1e-6 / rel
            plus = replace(ob, states=ob.states + h * dS[..., c],
                           period=ob.period + h * dT[:, c])
            minus = replace(ob, states=ob.states - h * dS[..., c],
                            period=ob.period - h * dT[:, c])
            out[..., c] = (self.residuals(plus) - self.residuals(minus)) / (2 * h)
        out[~ok] = 0.0
        return (out, dS[:, 0], dT) if orbits else out       # the samples start at x0

    def offsets(self, ob: OrbitBatch) -> dict[str, float]:
        """The sensor offsets that the residuals profile out, per channel."""
        ysim = self.features(ob)
        out = {}
        for j in self.mean_cols:
            ok = ob.ok
            w = 1.0 / self.sigma[ok, j] ** 2
            ch = self.mf.layout.channel[j]
            out[ch] = float(np.sum(w * (self.mf.y[ok, j] - ysim[ok, j])) / w.sum()) \
                if ok.any() else 0.0
        return out

    def orbits(self, term: Term, c: float, start: OrbitBatch, c_start: float) -> OrbitBatch:
        """Orbits with coefficient ``c`` of ``term``, tracked from ``start`` at ``c_start``."""
        p_from = {**self.params0, term.param: c_start}
        p_to = {**self.params0, term.param: c}
        return track(self.system, p_from, p_to, start, self.stable)

    def fit(self, term: Term) -> TermFit:
        """Gauss–Newton with re-shooting, then the grid posterior (module docstring)."""
        s = term.scale
        c, ob = 0.0, self.base
        e = self.residuals(ob)
        logpost = -0.5 * np.sum(e**2)

        def sensitivity(c, ob):
            g = self.derivatives(ob, {**self.params0, term.param: c}, [term.param])[..., 0]
            return g, float(np.sum(g**2) + 1.0 / s**2)

        g, prec = sensitivity(c, ob)
        for _ in range(GN_ITER):
            d = -(np.sum(g * e) + c / s**2) / prec
            for _ in range(6):  # step halving until the log posterior does not decrease
                c_new = max(c + d, 0.0) if term.positive else c + d
                ob_new = self.orbits(term, c_new, ob, c)
                e_new = self.residuals(ob_new)
                lp_new = -0.5 * np.sum(e_new**2) - 0.5 * c_new**2 / s**2
                if lp_new >= logpost - 1e-9 * abs(logpost):
                    break
                d *= 0.5
            else:
                break
            step = abs(c_new - c)
            c, ob, e, logpost = c_new, ob_new, e_new, lp_new
            g, prec = sensitivity(c, ob)
            if step < 1e-2 / np.sqrt(prec):
                break
        sd = 1.0 / np.sqrt(prec)
        lo = c - 6 * sd
        if term.positive:
            lo = max(lo, 0.0)
        grid = np.linspace(lo, max(c + 6 * sd, lo + 12 * sd), GRID)
        # linearised residuals on the grid
        ll = np.array([-0.5 * np.sum((e + g * (x - c)) ** 2) for x in grid])
        lp = ll + term.log_prior(grid)
        mx = lp.max()
        dens = np.exp(lp - mx)
        area = np.sum(0.5 * (dens[1:] + dens[:-1]) * np.diff(grid))
        # mass of the prior beyond the grid is negligible (grid spans ±6 sd of the posterior)
        log_z = float(mx + np.log(area))
        dens = dens / area
        cdf = _cdf(grid, dens)
        q = np.interp([0.05, 0.5, 0.95], cdf, grid)
        return TermFit(term=term, mode=float(c), sd=float(sd), median=float(q[1]),
                       ci90=(float(q[0]), float(q[2])), log_z=log_z,
                       chi2=float(np.sum(e**2)), grid=grid, density=dens,
                       lost=tuple(int(i) for i in np.nonzero(~ob.ok)[0]), e_mode=e, jac=g,
                       orbits=ob)


def null_log_z(fitter: Fitter) -> tuple[float, np.ndarray]:
    """``log p(y | c = 0)`` (common constants dropped) and the residuals ``(R, P)``."""
    e = fitter.residuals(fitter.base)
    return float(-0.5 * np.sum(e**2)), e


def probabilities(log_z0: float, fits: list[TermFit]) -> tuple[float, np.ndarray]:
    """Posterior probability of "none" and of each single-term model (module docstring)."""
    n = len(fits)
    lw = np.array([np.log(0.5) + log_z0] + [np.log(0.5 / n) + f.log_z for f in fits])
    w = np.exp(lw - lw.max())
    w /= w.sum()
    return float(w[0]), w[1:]
