r"""Leave-one-out refits on the collapsed core: how well a fit predicts a recording it has not seen.

The harmonic features of all recordings are extracted once, in one planar
frame (:func:`~bayeshopf.features.harmonics.extract_harmonics`); for each
recording ``i`` the model is refitted on the others
(:func:`~bayeshopf.posterior.fit_hybrid`), and the held-out amplitude ``A_i``
(peak-to-peak of z1) is compared with the prediction at its μ and branch:

* ``"bayes"``: the posterior median and the 90% band of a *new* measurement,
  :meth:`~bayeshopf.posterior.HybridPosterior.amplitude` with ``predictive=True``
  and the held-out recording's own standard errors: the model's coefficients
  scaled by the model error away from the recordings, plus
  ``N(0, se² + σ_c² + (σ_rel c)²)`` noise;
* ``"map"``: a plug-in prediction from the same fit's MAP point (no posterior):
  the nonlinear parameters ``θ̂`` at the MAP, the map coefficients at their
  conditional mean ``β̂ = E[β | y, θ̂] = V^{1/2} A^{-1} b``
  (:func:`~bayeshopf.model.collapsed.conditional_draw`), the point prediction
  the amplitude of that orbit, and a plug-in band from the fitted noise scales
  only, ``c + N(0, se² + σ̂_c² + (σ̂_rel c)²)``.

The paper's maximum-likelihood fit (``"ml"``) lived on the legacy inference
core and is not offered here.

Robustness is then the held-out error ``|Â_i − A_i| / A_i``, the coverage of the
90% bands, and how far the fold ``μ_SN`` moves from fold to fold. With few
folds the coverage is a coarse measure, so the summary also gives the binomial
probability of so few held-out recordings inside if the bands were calibrated:
``P(X ≤ k)``, ``X ~ Binomial(n, 0.9)`` (the folds share data, so this treats
them as more independent than they are).

How much too narrow: each fold's log residual ``r_i = log A_i − median log Â_i``
against its band *without* the model error away from the recordings, that
band's log variance ``v_i``, and the unit process's sd ``c_i`` at ``μ_i``
(:func:`~bayeshopf.model.collapsed.extrapolation_sd`) give the scale ``s`` of
that error that the held-out recordings themselves would choose,

.. math::  \hat s = \arg\max_s \prod_i N(r_i;\ 0,\ v_i + s^2 c_i^2),

reported beside the prior's scale ``S``
(``CollapsedSettings.extrapolation_scale``). It is read off the recordings
being validated, so it describes the misfit; set ``S`` from other rigs.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import jax.numpy as jnp
import numpy as np
from scipy.optimize import minimize_scalar
from tqdm.auto import tqdm

from bayeshopf._x64 import ensure_x64
from bayeshopf.data.recording import RecordingSet
from bayeshopf.diagnostics.summaries import CI, interval
from bayeshopf.errors import FitError
from bayeshopf.features.harmonics import HarmonicFeatures, extract_harmonics
from bayeshopf.inference.collapsed import CollapsedSettings
from bayeshopf.model import collapsed as cm
from bayeshopf.model.normal_form import branch_sign
from bayeshopf.posterior import HybridPosterior, fit_hybrid
from bayeshopf.predictive import amplitude_of, noise_sd, orbit_coefficients

#: The fits compared, in the order reported.
METHODS = ("bayes", "map")
METHOD_LABELS = {
    "bayes": "Bayesian (posterior)",
    "map": "MAP plug-in",
}
#: Noise draws of a plug-in band.
N_PLUG_IN_DRAWS = 2000
#: :meth:`LeaveOneOut.check` flags a coverage this improbable under calibrated bands.
COVERAGE_ALPHA = 0.05


@dataclass(frozen=True)
class HeldOut:
    """One method's prediction of one held-out recording.

    Attributes:
        median: Predicted amplitude (posterior median, or the plug-in point prediction).
        lo: Lower end of the 90% band.
        hi: Upper end of the 90% band.
        p_exists: Share of draws with an LCO on that branch at that μ (0 or 1 for a plug-in).
        mu_fold: ``(median, lo, hi)`` of the fold (``lo = hi = median`` for a plug-in;
            ``nan`` for a supercritical fit).
        mu0: ``(median, lo, hi)`` of the Hopf point.
        base_log_median: Median of the log amplitude in the band without the model
            error away from the recordings (``nan`` for a plug-in).
        base_log_var: Variance of that log amplitude (``nan`` for a plug-in).
        away_sd: The unit process's sd ``c`` at μ (module docstring; ``nan`` for a plug-in).
        draws: The predictive amplitude draws where the branch exists (for
            :meth:`HeldOutFold.log_density`).
    """

    median: float
    lo: float
    hi: float
    p_exists: float
    mu_fold: tuple[float, float, float]
    mu0: tuple[float, float, float]
    base_log_median: float = np.nan
    base_log_var: float = np.nan
    away_sd: float = np.nan
    draws: np.ndarray | None = field(default=None, repr=False, compare=False)


@dataclass(frozen=True)
class HeldOutFold:
    """One leave-one-out fold: a recording held out and what the others' fit predicts for it.

    Attributes:
        name: Held-out recording.
        mu: Its μ.
        branch: ``"stable"`` or ``"unstable"``.
        measured: Its measured amplitude (peak-to-peak of z1).
        measured_sd: Spread of the measured amplitude over segments.
        predictions: Method name → :class:`HeldOut`.
        fit: The fold's :class:`~bayeshopf.posterior.HybridPosterior` (kept only when asked;
            both methods come from it).
        extrapolation_scale: The scale ``S`` of the extra model error away from
            the recordings of this fold's refit
            (:attr:`~bayeshopf.posterior.HybridPosterior.extrapolation_scale`: the
            setting; 0 with the model discrepancy and no setting, or when off).
    """

    name: str
    mu: float
    branch: str
    measured: float
    measured_sd: float
    predictions: dict
    fit: HybridPosterior | None = None
    extrapolation_scale: float = cm.EXTRAPOLATION_SCALE

    def inside(self, method: str) -> bool:
        """Whether the measured amplitude lies in ``method``'s 90% band (ends included)."""
        p = self.predictions[method]
        return bool(p.lo <= self.measured <= p.hi)

    def relative_error(self, method: str) -> float:
        """``|Â − A| / A`` of ``method``'s median prediction."""
        return float(abs(self.predictions[method].median - self.measured) / self.measured)

    def log_density(self, method: str = "bayes") -> float:
        r"""``log p(A | y_{−i})``: the predictive density of the held-out amplitude.

        A Gaussian kernel density of the predictive draws (SciPy's
        ``gaussian_kde``, Scott's bandwidth) at the measured amplitude, times the
        share of draws in which the branch exists there (``-inf`` where none).
        """
        from scipy.stats import gaussian_kde  # slow to import; a fit needs it only here

        p = self.predictions[method]
        d = p.draws
        if d is None or np.size(d) < 2 or np.ptp(d) == 0:
            return -np.inf
        return float(np.log(p.p_exists) + gaussian_kde(d).logpdf(self.measured)[0])

    def log_residual(self, method: str = "bayes") -> float:
        """``log A − median log Â`` against the band without the model error away from the data."""
        return float(np.log(self.measured) - self.predictions[method].base_log_median)




@dataclass(frozen=True)
class LeaveOneOut:
    """All folds.

    Attributes:
        folds: One :class:`HeldOutFold` per held-out recording.
        methods: Methods compared.
    """

    folds: tuple[HeldOutFold, ...]
    methods: tuple[str, ...]

    @property
    def extrapolation_scales(self) -> tuple[float, ...]:
        """The refits' scales ``S`` of the model error away from the recordings, sorted, unique.

        The setting; 0 for refits with the model discrepancy and no setting.
        """
        return tuple(sorted({f.extrapolation_scale for f in self.folds}))

    def coverage(self, method: str) -> int:
        """Number of folds whose held-out amplitude lies in the 90% band."""
        return sum(f.inside(method) for f in self.folds)

    def coverage_p(self, method: str) -> float:
        """``P(X ≤ k)`` for ``X ~ Binomial(n_folds, CI)`` and ``k`` = :meth:`coverage`.

        ``CI`` is the mass of the bands (:data:`~bayeshopf.diagnostics.summaries.CI`, 0.9).
        The probability that calibrated 90% bands would hold this few held-out
        recordings or fewer; small values (below 0.05, say) mean the bands are
        too narrow.
        """
        from scipy.stats import binom  # slow to import; a fit needs it only here

        return float(binom.cdf(self.coverage(method), len(self.folds), CI))

    def held_out_scale(self, method: str = "bayes") -> float:
        """The scale ``ŝ`` of the model error away from the data that the held-out residuals choose.

        The maximum of ``Π N(r_i; 0, v_i + s² c_i²)`` over ``0 ≤ s ≤ 3`` (module
        docstring), over the folds whose band exists; ``nan`` when none has one.
        It is read off the held-out recordings: a description of the misfit, not
        a setting validated on them.
        """
        rows = [(f.log_residual(method), f.predictions[method].base_log_var,
                 f.predictions[method].away_sd) for f in self.folds]
        rows = np.array([r for r in rows if np.all(np.isfinite(r))]).reshape(-1, 3)
        if not rows.size:
            return np.nan
        r, v, c = rows.T

        def nll(s):
            var = v + s**2 * c**2
            return 0.5 * np.sum(np.log(var) + r**2 / var)

        return float(minimize_scalar(nll, bounds=(0.0, 3.0), method="bounded").x)

    def check(self, method: str = "bayes", alpha: float = COVERAGE_ALPHA) -> dict:
        """Whether the held-out coverage is plausible for calibrated 90% bands.

        It fails when ``coverage_p < alpha``: so few held-out recordings inside
        their bands would be that improbable if the bands were calibrated (with
        7 folds: 4 or fewer inside; 5 of 7 has ``P = 0.15`` and passes).

        Returns:
            JSON-ready: ``inside_ci90``, ``n_folds``, ``coverage_p``, ``alpha``,
            ``ok``, ``prior_scale`` (``S``), ``held_out_scale``
            (:meth:`held_out_scale`), and ``warning`` (one line, ``None`` when ``ok``).
        """
        k, n, p = self.coverage(method), len(self.folds), self.coverage_p(method)
        s_hat = self.held_out_scale(method) if method == "bayes" else np.nan
        ok = bool(p >= alpha)
        warning = None if ok else (
            f"leave-one-out: {k}/{n} held-out amplitudes inside their {100 * CI:g}% predictive "
            f"bands (P = {p:.2g} if the bands were calibrated): the bands away from the "
            "recordings are too narrow for these data"
            + ("" if not np.isfinite(s_hat) else
               f" (the held-out residuals choose a model-error scale of {s_hat:.2g} away from "
               f"the recordings; the prior's is {_scales_text(self.extrapolation_scales)})"))
        return {"method": method, "inside_ci90": k, "n_folds": n, "coverage_p": p,
                "alpha": alpha, "ok": ok,
                "prior_scale": _scales_text(self.extrapolation_scales),
                "prior_scales": [f.extrapolation_scale for f in self.folds],
                "held_out_scale": s_hat, "warning": warning}

    def report(self, method: str = "bayes") -> dict:
        """JSON-ready, for ``summary.json``: :meth:`check`, :meth:`summary` and :meth:`table`."""
        return {"check": self.check(method), "summary": self.summary()[method],
                "folds": self.table()}

    def summary(self) -> dict:
        """Per method: coverage (and :meth:`coverage_p`), held-out errors and the fold's spread."""
        out = {}
        for m in self.methods:
            err = np.array([f.relative_error(m) for f in self.folds])
            fold_mu = np.array([f.predictions[m].mu_fold[0] for f in self.folds])
            width = np.array([f.predictions[m].hi - f.predictions[m].lo for f in self.folds])
            out[m] = {
                "label": METHOD_LABELS[m],
                "coverage": self.coverage(m),
                "n_folds": len(self.folds),
                "coverage_p": self.coverage_p(m),
                "mean_relative_error": float(np.nanmean(err)),
                "max_relative_error": float(np.nanmax(err)),
                "mu_fold_sd": float(np.nanstd(fold_mu, ddof=1)) if fold_mu.size > 1 else np.nan,
                "mu_fold_range": [float(np.nanmin(fold_mu)), float(np.nanmax(fold_mu))],
                "mean_band_width": float(np.nanmean(width)),
                "log_predictive_density": float(sum(f.log_density(m) for f in self.folds)),
            }
        return out

    def to_dataset(self):
        """The folds as an :class:`xarray.Dataset` over ``recording`` and ``estimator``.

        ``estimator`` holds the methods (``"bayes"``, ``"map"``; not named
        ``method``, which ``Dataset.sel`` takes as its own argument). Per
        recording: ``mu``, ``branch``, ``measured``, ``measured_sd``; per
        recording and estimator: the prediction's ``median``, ``lower``, ``upper``
        (its 90% band), ``inside``, ``relative_error``, ``p_exists``, and the
        fit's ``mu_fold``/``mu0`` medians and interval ends (``mu_fold_lower``, …).
        """
        import xarray as xr

        r, rm = ("recording",), ("recording", "estimator")

        def per(get):
            return (rm, np.array([[get(f, m) for m in self.methods] for f in self.folds],
                                 dtype=float))

        def pred(attr, k=None):
            if k is None:
                return per(lambda f, m: getattr(f.predictions[m], attr))
            return per(lambda f, m: getattr(f.predictions[m], attr)[k])

        data = {
            "mu": (r, np.array([f.mu for f in self.folds], float)),
            "branch": (r, np.array([f.branch for f in self.folds])),
            "measured": (r, np.array([f.measured for f in self.folds], float)),
            "measured_sd": (r, np.array([f.measured_sd for f in self.folds], float)),
            "median": pred("median"), "lower": pred("lo"), "upper": pred("hi"),
            "inside": (rm, np.array([[f.inside(m) for m in self.methods]
                                     for f in self.folds])),
            "relative_error": per(lambda f, m: f.relative_error(m)),
            "p_exists": pred("p_exists"),
            "mu_fold": pred("mu_fold", 0), "mu_fold_lower": pred("mu_fold", 1),
            "mu_fold_upper": pred("mu_fold", 2),
            "mu0": pred("mu0", 0), "mu0_lower": pred("mu0", 1), "mu0_upper": pred("mu0", 2),
        }
        return xr.Dataset(data, coords={"recording": [f.name for f in self.folds],
                                        "estimator": list(self.methods)}, attrs={"ci": CI})

    def to_dataframe(self):
        """One row per held-out recording and estimator (:meth:`to_dataset`), pandas."""
        return self.to_dataset().to_dataframe()

    def table(self) -> list[dict]:
        """One row per fold (JSON-ready)."""
        rows = []
        for f in self.folds:
            row = {"file": f.name, "mu": f.mu, "branch": f.branch, "measured": f.measured,
                   "extrapolation_scale": f.extrapolation_scale}
            for m in self.methods:
                p = f.predictions[m]
                row[m] = {"median": p.median, "ci90": [p.lo, p.hi], "inside": f.inside(m),
                          "relative_error": f.relative_error(m), "p_exists": p.p_exists,
                          "log_residual": f.log_residual(m),
                          "base_log_sd": float(np.sqrt(p.base_log_var)), "away_sd": p.away_sd,
                          "mu_fold": {"median": p.mu_fold[0], "ci90": list(p.mu_fold[1:])},
                          "mu0": {"median": p.mu0[0], "ci90": list(p.mu0[1:])}}
            rows.append(row)
        return rows


# ----------------------------------------------------------------- the MAP plug-in
def map_theta(post: HybridPosterior) -> dict:
    """The nonlinear parameters ``θ̂`` at the MAP, each with a leading axis of one draw.

    Raises:
        FitError: If the MAP point lacks a site the orbits need.
    """
    p = post.map_point.params
    missing = sorted(set(post.theta) - set(p))
    if missing:
        raise FitError(f"the MAP point has no {missing}; expected every site of the posterior "
                       f"draws, found {sorted(p)}")
    return {k: np.asarray(p[k], dtype=float)[None] for k in post.theta}


def map_coefficients(post: HybridPosterior, theta: dict | None = None) -> np.ndarray:
    r"""``β̂ = E[β | y, θ̂]`` per channel, ``(J, 2)``: the map at its conditional mean.

    With ``Φ`` the design at ``θ̂``, ``V = diag(v(τ_μ, τ_s))`` the prior variances
    and ``D = diag(se² + σ_c² + (σ_rel y)²)``, ``β̂_c = V^{1/2} A^{-1} b`` with
    ``A = I + Φ'^T D^{-1} Φ'``, ``b = Φ'^T D^{-1} y_c``, ``Φ' = Φ V^{1/2}``
    (:func:`~bayeshopf.model.collapsed.conditional_draw`, its second output).
    """
    th = {k: jnp.asarray(v[0]) for k, v in (theta or map_theta(post)).items()}
    f = post.features
    control = None if post.spec.control_scale is None else jnp.asarray(f.control)
    return np.asarray(cm.map_mean(post.spec, th, jnp.asarray(f.mu),
                                  jnp.asarray(np.where(f.unstable, -1.0, 1.0)),
                                  jnp.asarray(f.coeffs), jnp.asarray(f.coeffs_se), control))


def plug_in_coefficients(post: HybridPosterior, mu, branch: str, control=None) -> np.ndarray:
    """Harmonic coefficients of the MAP plug-in orbit at μ, ``(n_mu, 2, 2K+1)``; ``nan``: no LCO.

    ``control`` ``(n_mu, 2)``: the control's fundamental there (``None``: uncontrolled).
    """
    sign = branch_sign(branch)
    if branch == "unstable" and post.criticality != "subcritical":
        return np.full((np.size(mu), 2, 2 * post.spec.n_harmonics + 1), np.nan)
    theta = map_theta(post)
    beta = map_coefficients(post, theta)
    return orbit_coefficients(post.spec, theta, beta[None], np.atleast_1d(mu), sign,
                              control=control)[0]


def plug_in_amplitude(post: HybridPosterior, mu, branch: str = "stable",
                      control=None) -> np.ndarray:
    """The MAP plug-in amplitude (peak-to-peak of z1) at μ, ``(n_mu,)``; ``nan`` where no LCO."""
    return amplitude_of(post.spec, plug_in_coefficients(post, mu, branch, control))


def plug_in_band(post: HybridPosterior, mu: float, branch: str, coeffs_se=None, *,
                 n_draws: int = N_PLUG_IN_DRAWS, seed: int | None = None,
                 control=None) -> np.ndarray:
    """Amplitude draws of a new measurement under the plug-in, ``(n_draws,)``.

    ``c + N(0, se² + σ̂_c² + (σ̂_rel c)²)`` with ``c`` the plug-in orbit at μ and
    ``σ̂`` the MAP's noise scales (no parameter uncertainty, no model error away
    from the data); ``coeffs_se`` defaults to the training recordings' median.
    """
    c = plug_in_coefficients(post, [mu], branch, control)                 # (1, 2, 2K+1)
    p = post.map_point.params
    se = np.median(post.features.coeffs_se, axis=0) if coeffs_se is None else coeffs_se
    sd = noise_sd(c[None], np.asarray(p["sigma"])[None], np.asarray(p["sigma_rel"])[None], se)
    rng = np.random.default_rng(post.seed if seed is None else seed)
    reps = c[None] + sd * rng.standard_normal((n_draws,) + c.shape)       # (n, 1, 2, 2K+1)
    return amplitude_of(post.spec, reps)[:, 0]


# ----------------------------------------------------------------- predictions
_NAN3 = (np.nan, np.nan, np.nan)


def _triple(post: HybridPosterior, name: str) -> tuple[float, float, float]:
    iv = post.interval(name)
    return _NAN3 if iv is None else (iv.median, iv.lo, iv.hi)


def _bayes_prediction(post: HybridPosterior, mu: float, branch: str, coeffs_se,
                      control) -> HeldOut:
    amp = post.amplitude([mu], branch, predictive=True, coeffs_se=coeffs_se,
                         control=control)[:, 0]
    ok = np.isfinite(amp)
    iv = interval(amp[ok]) if ok.any() else None
    base = replace(post, settings=replace(post.settings, extrapolation=False)).amplitude(
        [mu], branch, predictive=True, coeffs_se=coeffs_se, control=control)[:, 0]
    log_base = np.log(base[np.isfinite(base) & (base > 0)])
    f = post.features
    c = cm.extrapolation_sd([mu], f.mu[f.unstable == (branch == "unstable")],
                            cm.EXTRAPOLATION_LENGTH * post.spec.mu_span)[0]
    return HeldOut(median=iv.median if iv else np.nan, lo=iv.lo if iv else np.nan,
                   hi=iv.hi if iv else np.nan, p_exists=float(ok.mean()),
                   mu_fold=_triple(post, "mu_fold"), mu0=_triple(post, "mu0"),
                   base_log_median=float(np.median(log_base)) if log_base.size else np.nan,
                   base_log_var=float(np.var(log_base)) if log_base.size else np.nan,
                   away_sd=float(c), draws=amp[ok])


def _map_prediction(post: HybridPosterior, mu: float, branch: str, coeffs_se,
                    control) -> HeldOut:
    point = float(plug_in_amplitude(post, [mu], branch, control)[0])
    band = plug_in_band(post, mu, branch, coeffs_se, control=control)
    band = band[np.isfinite(band)]
    lo, hi = np.quantile(band, [(1 - CI) / 2, (1 + CI) / 2]) if band.size else (np.nan, np.nan)
    p = post.map_point.params
    fold = float(p["mu_fold"]) if "mu_fold" in p else np.nan
    mu0 = float(p["mu0"])
    return HeldOut(median=point, lo=float(lo), hi=float(hi), p_exists=float(np.isfinite(point)),
                   mu_fold=(fold, fold, fold), mu0=(mu0, mu0, mu0), draws=band)


def predict_held_out(post: HybridPosterior, method: str, mu: float, branch: str,
                     coeffs_se=None, control=None) -> HeldOut:
    """Prediction of a new recording at ``(μ, branch)`` by ``method`` (``"bayes"`` or ``"map"``).

    Args:
        post: A fit that has not seen the recording.
        method: ``"bayes"`` or ``"map"``.
        mu: Its μ.
        branch: ``"stable"`` or ``"unstable"``.
        coeffs_se: Its coefficients' standard errors in ``post``'s frame
            ``(2, 2K+1)`` (default: the training recordings' median).
        control: Its measured control fundamental ``(1, 2)`` (a CBC recording,
            with the model's control term), or ``None``.
    """
    if method == "bayes":
        return _bayes_prediction(post, mu, branch, coeffs_se, control)
    if method == "map":
        return _map_prediction(post, mu, branch, coeffs_se, control)
    raise FitError(f"method must be one of {METHODS}; got {method!r}")


def leave_one_out(
    rs: RecordingSet | HarmonicFeatures,
    criticality: str = "subcritical",
    *,
    methods=METHODS,
    seed: int = 0,
    settings: CollapsedSettings | None = None,
    folds=None,
    keep_fits: bool = False,
    progress: bool = True,
) -> LeaveOneOut:
    """Refit without each recording in turn and predict it.

    The features are extracted once from all recordings (one frame), and each
    fold's fit is :func:`~bayeshopf.posterior.fit_hybrid` on the others'
    features; both methods come from that one fit.

    Args:
        rs: All recordings (or their features).
        criticality: Normal form of every fit.
        methods: Any of ``"bayes"``, ``"map"``.
        seed: Seed of every fit.
        settings: :class:`~bayeshopf.inference.collapsed.CollapsedSettings` (the same
            for every fold; default settings when ``None``).
        folds: Names of the recordings to hold out (default: all).
        keep_fits: Keep every fold's fit (for figures; memory grows with folds).
        progress: Show a progress bar over folds.

    Returns:
        A :class:`LeaveOneOut`.

    Raises:
        FitError: For an unknown method or recording name.
    """
    ensure_x64()
    settings = settings or CollapsedSettings()
    methods = tuple(methods)
    unknown = set(methods) - set(METHODS)
    if unknown or not methods:
        hint = " (the maximum-likelihood fit was on the removed legacy core)" if "ml" in unknown \
            else ""
        raise FitError(f"methods must be among {METHODS}; got {methods!r}{hint}")
    methods = tuple(m for m in METHODS if m in methods)
    features = (rs if isinstance(rs, HarmonicFeatures) else
                extract_harmonics(rs, n_harmonics=settings.n_harmonics,
                                  segment_periods=settings.segment_periods))
    all_names = list(features.names)
    names = all_names if folds is None else list(folds)
    missing = [n for n in names if n not in all_names]
    if missing:
        raise FitError(f"no recording named {missing}; expected some of {all_names}")
    out = []
    for name in tqdm(names, desc="leave-one-out", disable=not progress):
        i = all_names.index(name)
        keep = [j for j in range(features.n_recordings) if j != i]
        train, held = _fold_features(rs, features, keep, i, settings)
        post = fit_hybrid(train, criticality, seed=seed, settings=settings, progress=False)
        mu, branch = float(features.mu[i]), "unstable" if features.unstable[i] else "stable"
        control = None if held.control is None else held.control[0][None]
        preds = {m: predict_held_out(post, m, mu, branch, held.coeffs_se[0], control)
                 for m in methods}
        out.append(HeldOutFold(name=name, mu=mu, branch=branch,
                               measured=float(features.amplitude[i]),
                               measured_sd=float(features.amplitude_sd[i]), predictions=preds,
                               fit=post if keep_fits else None,
                               extrapolation_scale=post.extrapolation_scale
                               if settings.extrapolation else 0.0))
    return LeaveOneOut(folds=tuple(out), methods=methods)


def _fold_features(rs, features: HarmonicFeatures, keep: list, i: int,
                   settings: CollapsedSettings) -> tuple[HarmonicFeatures, HarmonicFeatures]:
    """The refit's features without recording ``i``, and recording ``i``'s in their frame.

    From recordings, the training features are extracted without the held-out
    recording (its frame, the centre and scale of the orbits, built from the
    others alone), and the held-out recording's standard errors and control are
    then expressed in that frame. From features, the common frame is kept.
    """
    if isinstance(rs, HarmonicFeatures):
        return features.subset(keep), features.subset([i])
    kw = dict(n_harmonics=settings.n_harmonics, segment_periods=settings.segment_periods)
    recs = tuple(rs.recordings)
    train = extract_harmonics(replace(rs, recordings=tuple(recs[j] for j in keep)), **kw)
    held = extract_harmonics(replace(rs, recordings=(recs[i],)), frame=train.frame, **kw)
    return train, held


def _scales_text(scales) -> str:
    """``"0.1"``, or ``"0.48–0.68"`` when the folds' refits chose different (rms) scales."""
    return f"{scales[0]:.2g}" if len(scales) == 1 else f"{scales[0]:.2g}–{scales[-1]:.2g}"
