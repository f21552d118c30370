r"""Nested models: Savage–Dickey Bayes factors, class Bayes factors, prior-scale sensitivity.

**Savage–Dickey.** The parameters-only model :math:`M_P` is :math:`M_k` with
the term's coefficient :math:`\zeta_k = 0`, and :math:`M_k` is the pair
:math:`M_{jk}` with :math:`\zeta_j = 0`. With priors independent between the
coefficient and the rest (every unknown has its own standard normal prior,
:mod:`~bayeshopf.discrepancy.problem`), the evidence ratio of the nested models
is the density ratio of the larger model's coefficient marginal at 0,

.. math::  \log Z_k - \log Z_P = \log p(\zeta_k = 0) - \log p(\zeta_k = 0 \mid y, M_k),

(Dickey 1971; Verdinelli & Wasserman 1995, whose correction factor is 1
here). The marginal is the Laplace one that the fit already has: at each
relative model error :math:`\tau` a normal :math:`\mathcal N(m_\tau, C_\tau)`
(:func:`gaussian_marginal`), truncated to :math:`\zeta \ge 0` for a gap or a
dissipative term (then :math:`p(0\mid y) = \mathcal N(0; m, C)/P(\zeta\ge0)`
and the half-normal prior density at 0 is twice the normal's), and
:math:`\tau`, shared by both models with the same prior, is integrated out by
mixing over the larger model's posterior weights :math:`w_\tau`:
:math:`p(0 \mid y) = \sum_\tau w_\tau\, p_\tau(0 \mid y)`
(:func:`log_bayes_factor`). For residuals linear in the unknowns the ratio is
exact, whatever point the fits stopped at.

**Where it replaces the separate evidences** (:func:`use_savage_dickey`,
:func:`nested_log_z`). Each model's own Laplace evidence rests on its own
optimiser's end point: a parameters-only fit that stopped short of its mode
loses to every term fitted from a better start, although the term's
coefficient is at 0 within its posterior, and a polish charge at one model and
not the other moves the comparison by that charge. The Savage–Dickey ratio
needs only the larger model's posterior between its mode and 0, so it is used
(:math:`\log Z_k = \log Z_P + \log B_{kP}`) when

* the larger model is fitted in full (``refined``): the marginal is that of
  its mode, not of the linear model at another model's end point; and
* 0 lies within :data:`SD_RANGE` posterior standard deviations of the
  marginal's centre (for a coefficient bounded at 0, of a positive centre):
  the normal marginal is then extrapolated no further than its own intervals
  reach, and this is where the question "term or parameters?" is decided.

Otherwise (a term the data demand by many standard deviations) the normal
tail at 0 is an extrapolation over a range where the orbits change
nonlinearly, and each model keeps its own Laplace evidence; the two agree for
linear residuals, and where the term is needed that strongly the choice
changes no verdict. The larger model's polish charge (what its linear model
promised beyond the orbits re-shot at its mode,
:func:`~bayeshopf.discrepancy.problem.charge`) is kept:
:math:`\log Z_k = \log Z_P + \log B_{kP} - \text{charge}_k`, the same
correction its own evidence carries (0 for linear residuals). A pair is
nested in each of its single terms: its evidence is the Savage–Dickey ratio on
the other coefficient's marginal (same rule, its own charge kept) added to the
evidence of its more probable single term.

**A scale-free prior on a term's size** (:func:`mixture_log_bf`). The
library's prior scale :math:`s` of a coefficient is that of a gross error
(:mod:`~bayeshopf.discrepancy.terms`); a term hidden in a simulator is as
plausible at a thousandth of it as at all of it. The coefficient's prior is
therefore the scale mixture :math:`c \mid f \sim \mathcal N(0, f^2 s^2)`,
:math:`f` log-uniform on :data:`SCALE_RANGE` (a half-normal mixture for a
coefficient bounded at 0), and every term model's evidence is averaged over
:math:`f` on :data:`N_SCALES` quantile points:
:math:`Z_k = \overline{Z_k(f)}`, each :math:`Z_k(f)/Z_k(1)` from the Gaussian
algebra below ("Sensitivity"), exact for residuals linear in the unknowns (a
model that keeps its own Laplace evidence takes the ratio of the averages on
the few τ that hold 99.9% of its weight, :attr:`CoefficientPosterior.thinned`). A
term the data resolve at a few standard deviations no longer pays the Occam
factor of a gross-error prior; a term of no effect costs little (its small
scales are indistinguishable from :math:`M_P`), and one the data exclude still
loses. The fits, and the intervals of the coefficients, stay those at
:math:`f = 1`. A pair's second coefficient gets its own :math:`f`
(Savage–Dickey against its single term); a pair that keeps its own Laplace
evidence mixes one :math:`f` for both.

**Bayes factors apart from the prior odds** (:func:`class_bayes_factors`).
A class's evidence is its models' evidences averaged with their prior
weights within the class, :math:`Z_c = \sum_{M\in c}\pi_M Z_M / \sum_{M\in c}\pi_M`,
so that :math:`P(c\mid y)/P(c'\mid y) = B_{cc'}\,\pi_c/\pi_{c'}`; the
report gives :math:`\log B` of each class against "nothing wrong" and
"parameters off", and the prior probabilities, so that a reader can apply
their own.

**Sensitivity to the terms' prior scales** (:func:`log_bayes_factor` with
``factor``). Every coefficient is :math:`c = s\,\zeta`; a prior scale
:math:`f s` is a prior :math:`\mathcal N(0, f^2)` on :math:`\zeta`. The
likelihood's part of the Gaussian marginal is
:math:`\Lambda = C^{-1} - I`, :math:`b = C^{-1} m`, so with the new prior the
posterior is :math:`C_f = (\Lambda + I/f^2)^{-1}`, :math:`m_f = C_f b`, and
the Bayes factor follows without a new fit. Over :math:`\tau`, with
:math:`B_\tau(f)` the ratio at one :math:`\tau`,
:math:`B(f) = \sum_\tau w_\tau B_\tau(f)/B_\tau(1) \big/ \sum_\tau w_\tau/B_\tau(1)`
(the weights :math:`w_\tau` re-weighted by the change of each
:math:`Z_k(\tau)`).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import special, stats

__all__ = ["BAND_FACTORS", "N_SCALES", "SCALES", "SCALE_RANGE", "SD_RANGE",
           "CoefficientPosterior", "class_bayes_factors", "gaussian_log_bf",
           "gaussian_marginal", "log_bayes_factor", "mixture_log_bf", "mixture_shift",
           "nested_log_z", "sensitivity", "use_savage_dickey"]

#: Savage–Dickey is used when 0 lies within this many posterior standard deviations.
SD_RANGE = 4.0
#: Factors of every term's prior scale in the sensitivity band.
BAND_FACTORS = (0.5, 2.0)
#: Range of the factor f of a term's prior scale (log-uniform): from a thousandth of a
#: gross error to a gross error.
SCALE_RANGE = (1e-3, 1.0)
#: Quantile points of f on which the evidence is averaged.
N_SCALES = 12
#: The factors: midpoint quantiles of the log-uniform prior of f.
SCALES = tuple(float(v) for v in np.exp(
    np.log(SCALE_RANGE[0]) + (np.arange(N_SCALES) + 0.5) / N_SCALES
    * np.log(SCALE_RANGE[1] / SCALE_RANGE[0])))


@dataclass(frozen=True)
class CoefficientPosterior:
    r"""The Laplace marginal of a model's term coefficients :math:`\zeta` (prior units).

    Attributes:
        weights: Posterior weights of the relative model error τ at the points
            kept (summing to 1), shape ``(n,)``.
        mean: The normal marginal's mean at each, shape ``(n, k)`` (before any
            truncation at 0).
        cov: Its covariance, shape ``(n, k, k)``.
        positive: Whether each coefficient is bounded at 0 (half-normal prior).
    """

    weights: np.ndarray = field(repr=False)
    mean: np.ndarray = field(repr=False)
    cov: np.ndarray = field(repr=False)
    positive: tuple[bool, ...] = ()

    def sub(self, idx: Sequence[int]) -> CoefficientPosterior:
        """The marginal of the coefficients ``idx`` (one object per ``idx``: its caches kept)."""
        idx = tuple(int(i) for i in idx)
        subs = self.__dict__.setdefault("_subs", {})
        if idx not in subs:
            subs[idx] = CoefficientPosterior(self.weights, self.mean[:, list(idx)],
                                             self.cov[:, list(idx)][:, :, list(idx)],
                                             tuple(self.positive[i] for i in idx))
        return subs[idx]

    @functools.cached_property
    def thinned(self) -> CoefficientPosterior:
        """The marginal at the fewest τ that hold 99.9% of the weight (at most 6), reweighted."""
        order = np.argsort(self.weights)[::-1]
        n = min(int(np.searchsorted(np.cumsum(self.weights[order]), 0.999)) + 1, 6,
                order.size)
        k = np.sort(order[:n])
        w = self.weights[k]
        return CoefficientPosterior(w / w.sum(), self.mean[k], self.cov[k], self.positive)

    @functools.cached_property
    def log_bf(self) -> float:
        """:func:`log_bayes_factor` at the library's prior scale (computed once)."""
        return log_bayes_factor(self)

    @functools.cached_property
    def mixture_log_bf(self) -> float:
        """:func:`mixture_log_bf` (computed once)."""
        return mixture_log_bf(self)

    @property
    def distance(self) -> float:
        """How many posterior standard deviations 0 lies from the centre.

        The largest over the coefficients, at the most probable τ; a negative
        centre of a bounded coefficient counts 0 (its posterior sits at 0).
        """
        k = int(np.argmax(self.weights))
        m, sd = self.mean[k], np.sqrt(np.diag(self.cov[k]))
        m = np.where(self.positive, np.maximum(m, 0.0), np.abs(m))
        return float(np.max(m / sd)) if m.size else 0.0


def gaussian_marginal(E: np.ndarray, G: np.ndarray, x: np.ndarray, k: int
                      ) -> tuple[np.ndarray, np.ndarray]:
    r"""Mean and covariance of the last ``k`` unknowns under the linear model :math:`E + G\delta`.

    ``E`` and ``G`` include the standard normal prior rows; the posterior is
    :math:`\mathcal N(x + \delta, H^{-1})`, :math:`H = G^\top G`,
    :math:`\delta = -H^{-1}G^\top E`. With a leading axis of whitenings
    (``E`` of shape ``(S, N)``, ``G`` of ``(S, N, n)``) the means and
    covariances have it too.
    """
    Gt = np.swapaxes(G, -1, -2)
    cov = np.linalg.inv(Gt @ G)
    delta = -(cov @ (Gt @ E[..., None]))[..., 0]
    return (np.asarray(x, float)[-k:] + delta[..., -k:]), cov[..., -k:, -k:]


#: Gauss–Legendre nodes and weights on [0, 1] of each panel of :func:`_orthant2`.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(32)
_GL = ((_GL_X + 1.0) / 2.0, _GL_W / 2.0)


def _orthant2(m: np.ndarray, C: np.ndarray) -> float:
    r"""``log P(ζ ≥ 0)`` for a bivariate normal ``N(m, C)``, in log space.

    :math:`P = \int_{-m_1/s_1}^\infty φ(u)\,Φ\big((m_2 + ρ s_2 u)/(s_2\sqrt{1-ρ^2})\big)\,du`.
    Gauss–Legendre on panels from the lower limit (or −13) to 13 standard
    deviations above it (or above 0), split where the Φ factor steps (its
    argument's zero), so that a correlation near ±1 is resolved.
    """
    s1, s2 = np.sqrt(C[0, 0]), np.sqrt(C[1, 1])
    rho = float(np.clip(C[0, 1] / (s1 * s2), -1.0, 1.0))
    r = np.sqrt(max(1.0 - rho**2, 1e-300))
    lo = max(-m[0] / s1, -13.0)                    # φ below −13: < 1e-37 of the mass
    hi = max(lo, 0.0) + 13.0
    cuts = {lo, hi}
    if rho != 0.0:
        step = -m[1] / (rho * s2)
        if lo < step < hi:
            cuts.add(step)
    cuts = np.array(sorted(cuts))
    edges = np.concatenate([np.linspace(a, b, 5)[:-1] for a, b in zip(cuts[:-1], cuts[1:],
                                                                    strict=True)] + [cuts[-1:]])
    x, w = _GL
    u = (edges[:-1, None] + np.diff(edges)[:, None] * x[None, :]).ravel()
    lw = (np.log(np.diff(edges))[:, None] + np.log(w)[None, :]).ravel()
    vals = (-0.5 * u**2 - 0.5 * np.log(2 * np.pi)
            + special.log_ndtr((m[1] + rho * s2 * u) / (s2 * r)) + lw)
    return float(special.logsumexp(vals))


def _orthant_logp(m: np.ndarray, C: np.ndarray) -> float:
    """``log P(ζ ≥ 0)`` for ``ζ ~ N(m, C)`` (every component)."""
    if m.size == 0:
        return 0.0
    if m.size == 1:
        return float(stats.norm.logcdf(m[0] / np.sqrt(C[0, 0])))
    if m.size == 2:
        return _orthant2(m, C)
    else:
        p = stats.multivariate_normal.cdf(np.zeros(m.size), mean=-m, cov=C, abseps=1e-10,
                                          releps=1e-8)
    return float(np.log(max(p, 1e-300)))


def gaussian_log_bf(mean: np.ndarray, cov: np.ndarray, positive: Sequence[bool],
                    factor: float = 1.0) -> float:
    r"""Savage–Dickey :math:`\log p(0) - \log p(0\mid y)` for one normal marginal.

    Args:
        mean: The marginal's mean with the standard prior, shape ``(k,)``.
        cov: Its covariance, shape ``(k, k)``.
        positive: Which coefficients are bounded at 0 (half-normal prior,
            normal marginal truncated to the orthant of the bounded ones).
        factor: The prior scale relative to the one of ``mean``, ``cov``
            (module docstring, "Sensitivity").
    """
    m, C = np.atleast_1d(np.asarray(mean, float)), np.atleast_2d(np.asarray(cov, float))
    k = m.size
    if factor != 1.0:
        P = np.linalg.inv(C)
        b = P @ m
        Pf = P - np.eye(k) + np.eye(k) / factor**2
        C = np.linalg.inv(Pf)
        m = C @ b
    pos = np.asarray(positive, bool)
    log_prior0 = float(-0.5 * k * np.log(2 * np.pi * factor**2) + np.log(2.0) * pos.sum())
    log_post0 = float(stats.multivariate_normal(mean=m, cov=C).logpdf(np.zeros(k)))
    log_post0 -= _orthant_logp(m[pos], C[np.ix_(pos, pos)])
    return log_prior0 - log_post0


def log_bayes_factor(post: CoefficientPosterior, factor: float = 1.0) -> float:
    r""":math:`\log Z_{\rm larger} - \log Z_{\rm nested}` with τ integrated out (module docstring).

    Args:
        post: The larger model's coefficient marginal (only the coefficients
            set to 0 in the nested model: :meth:`CoefficientPosterior.sub`).
        factor: Every coefficient's prior scale multiplied by this.
    """
    return float(_log_bayes_factors(post, (factor,))[0])


def _log_bayes_factors(post: CoefficientPosterior, factors: Sequence[float]) -> np.ndarray:
    """:func:`log_bayes_factor` at each of ``factors``, the ratios at scale 1 formed once."""
    lw = np.log(np.clip(post.weights, 1e-300, None))
    b1 = np.array([gaussian_log_bf(m, C, post.positive)
                   for m, C in zip(post.mean, post.cov, strict=True)])
    base = special.logsumexp(lw - b1)
    out = []
    for f in factors:
        if f == 1.0:
            out.append(-base)
            continue
        bf = np.array([gaussian_log_bf(m, C, post.positive, f)
                       for m, C in zip(post.mean, post.cov, strict=True)])
        out.append(special.logsumexp(lw + bf - b1) - base)
    return np.array(out, dtype=float)


def mixture_log_bf(post: CoefficientPosterior, scales: Sequence[float] = SCALES) -> float:
    """:func:`log_bayes_factor` with the prior scale averaged over ``scales`` (equal weights)."""
    return float(special.logsumexp(_log_bayes_factors(post, scales)) - np.log(len(scales)))


def mixture_shift(post: CoefficientPosterior | None) -> float:
    """``log Z`` (scale mixture) − ``log Z`` (scale s) of a model, from its coefficients."""
    if post is None:
        return 0.0
    thin = post.thinned              # a ratio of two averages over τ: few points suffice
    return thin.mixture_log_bf - thin.log_bf


def sensitivity(post: CoefficientPosterior, factors: Sequence[float] = BAND_FACTORS
                ) -> dict[float, float]:
    """The change of :func:`log_bayes_factor` with every prior scale multiplied by each factor."""
    b1 = log_bayes_factor(post)
    return {float(f): log_bayes_factor(post, f) - b1 for f in factors}


def use_savage_dickey(post: CoefficientPosterior | None, refined: bool) -> bool:
    """Whether the Savage–Dickey ratio replaces a model's own evidence (module docstring)."""
    return post is not None and refined and post.distance <= SD_RANGE


def nested_log_z(log_z_p: float, singles: Sequence, pairs: Sequence
                 ) -> tuple[dict[str, float], dict[str, str]]:
    """Every term model's log evidence, Savage–Dickey where :func:`use_savage_dickey` says.

    Args:
        log_z_p: Log evidence of the parameters-only model.
        singles: Single-term fits: ``term.name``, ``log_z_laplace`` (their own
            evidence; ``log_z`` where that is ``None``), ``coefficients``
            (:class:`CoefficientPosterior` or ``None``), ``refined``, ``penalty``.
        pairs: Pair fits: ``name``, ``terms``, the same attributes.

    Every evidence is that of the scale-free prior (module docstring, :func:`mixture_log_bf`).

    Returns:
        ``(log_z, how)``: the log evidence by model name, and for each
        ``"savage-dickey vs parameters"``, ``"savage-dickey vs <term>"`` or ``"laplace"``.
    """
    def own(f) -> float:
        return f.log_z if getattr(f, "log_z_laplace", None) is None else f.log_z_laplace

    out: dict[str, float] = {}
    how: dict[str, str] = {}
    for f in singles:
        name = f.term.name
        if use_savage_dickey(f.coefficients, f.refined):
            out[name] = log_z_p + f.coefficients.mixture_log_bf - f.penalty
            how[name] = "savage-dickey vs parameters"
        else:
            out[name], how[name] = own(f) + mixture_shift(f.coefficients), "laplace"
    for f in pairs:
        out[f.name], how[f.name] = own(f) + mixture_shift(f.coefficients), "laplace"
        base = sorted((k for k, t in enumerate(f.terms) if t.name in out),
                      key=lambda k: -out[f.terms[k].name])
        if not base or f.coefficients is None:
            continue
        k = base[0]
        other = f.coefficients.sub([1 - k])
        if use_savage_dickey(other, f.refined):
            out[f.name] = out[f.terms[k].name] + other.mixture_log_bf - f.penalty
            how[f.name] = f"savage-dickey vs {f.terms[k].name}"
    return out, how


def class_bayes_factors(log_prior: Mapping[str, float], log_z: Mapping[str, float],
                        classes: Mapping[str, Sequence[str]]) -> dict:
    r"""Each class's log Bayes factor against every other, and the prior probabilities.

    Args:
        log_prior: Log prior probability of every model.
        log_z: Its log evidence.
        classes: The models of each class.

    Returns:
        ``{"log_evidence": {class: log Z_c}, "prior": {class: π_c},
        "log_bayes_factor": {class: {other: log B}}}`` (module docstring), the
        prior probabilities normalised over the models given (those compared).
    """
    lz, prior = {}, {}
    for c, models in classes.items():
        ms = [m for m in models if m in log_z]
        if not ms:
            continue
        lp = np.array([log_prior[m] for m in ms])
        prior[c] = float(np.exp(special.logsumexp(lp)))
        lz[c] = float(special.logsumexp(lp + np.array([log_z[m] for m in ms]))
                      - special.logsumexp(lp))
    total = sum(prior.values())
    prior = {c: v / total for c, v in prior.items()}
    return {"log_evidence": lz, "prior": prior,
            "log_bayes_factor": {c: {o: lz[c] - lz[o] for o in lz if o != c} for c in lz}}
