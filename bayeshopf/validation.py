"""Leave-one-out refits: how well each fit predicts a recording it has not seen.

For each recording i the model is refitted on the others, and the held-out
amplitude ``A_i`` is compared with the prediction at its μ and branch:

* Bayesian (:func:`bayeshopf.pipeline.fit`): the posterior median and the 90%
  band of a new recording (posterior predictive, with the scatter σ);
* MAP (the same fit's optimum, no posterior) and maximum likelihood
  (:func:`bayeshopf.pipeline.fit_point` without priors, the paper's fit): the
  point prediction, and a plug-in band (parameters fixed at the optimum, only
  the fitted scatter random).

Robustness is then the held-out error ``|Â_i − A_i| / A_i``, the coverage of the
90% bands, and how far the fold ``μ_SN`` moves from fold to fold. With few
folds the coverage is a coarse measure, so the summary also gives the binomial
probability of so few held-out recordings inside if the bands were calibrated:
``P(X ≤ k)``, ``X ~ Binomial(n, 0.9)`` (the folds share data, so this treats
them as more independent than they are).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import binom
from tqdm.auto import tqdm

from bayeshopf.data.recording import RecordingSet
from bayeshopf.diagnostics.summaries import CI, interval
from bayeshopf.features.orbits import extract_features
from bayeshopf.pipeline import FitSettings, HopfFit, PointFit, fit, fit_point

#: The fits compared, in the order reported.
METHODS = ("bayes", "map", "ml")
METHOD_LABELS = {
    "bayes": "Bayesian (posterior)",
    "map": "MAP only",
    "ml": "maximum likelihood (paper)",
}


@dataclass(frozen=True)
class HeldOut:
    """One method's prediction of one held-out recording.

    Attributes:
        median: Predicted amplitude (posterior median, or the point prediction).
        lo: Lower end of the 90% band (plug-in band for point fits).
        hi: Upper end of the 90% band.
        p_exists: Share of draws with an LCO on that branch at that μ.
        mu_fold: ``(median, lo, hi)`` of the fold (``lo = hi = median`` for point fits).
        mu0: ``(median, lo, hi)`` of the Hopf point.
    """

    median: float
    lo: float
    hi: float
    p_exists: float
    mu_fold: tuple[float, float, float]
    mu0: tuple[float, float, float]


@dataclass(frozen=True)
class Fold:
    """One leave-one-out fold.

    Attributes:
        name: Held-out recording.
        mu: Its μ.
        branch: ``"stable"`` or ``"unstable"``.
        measured: Its measured amplitude (peak-to-peak of z1).
        measured_sd: Spread of the measured amplitude over segments.
        predictions: Method name → :class:`HeldOut`.
        fits: Method name → the fit (kept only when asked).
    """

    name: str
    mu: float
    branch: str
    measured: float
    measured_sd: float
    predictions: dict
    fits: dict | None = None

    def inside(self, method: str) -> bool:
        """Whether the measured amplitude lies in ``method``'s 90% band."""
        p = self.predictions[method]
        return bool(p.lo <= self.measured <= p.hi)

    def relative_error(self, method: str) -> float:
        """``|Â − A| / A`` of ``method``'s median prediction."""
        return float(abs(self.predictions[method].median - self.measured) / self.measured)


@dataclass(frozen=True)
class LeaveOneOut:
    """All folds, and the full-data fits they are compared with.

    Attributes:
        folds: One :class:`Fold` per recording.
        methods: Methods compared.
        full: Method name → fit on all recordings (kept only when asked).
    """

    folds: tuple[Fold, ...]
    methods: tuple[str, ...]
    full: dict | None = None

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
        return float(binom.cdf(self.coverage(method), len(self.folds), CI))

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
                "mu_fold_sd": float(np.nanstd(fold_mu, ddof=1)),
                "mu_fold_range": [float(np.nanmin(fold_mu)), float(np.nanmax(fold_mu))],
                "mean_band_width": float(np.nanmean(width)),
            }
        return out

    def table(self) -> list[dict]:
        """One row per fold (JSON-ready)."""
        rows = []
        for f in self.folds:
            row = {"file": f.name, "mu": f.mu, "branch": f.branch, "measured": f.measured}
            for m in self.methods:
                p = f.predictions[m]
                row[m] = {"median": p.median, "ci90": [p.lo, p.hi], "inside": f.inside(m),
                          "relative_error": f.relative_error(m),
                          "mu_fold": {"median": p.mu_fold[0], "ci90": list(p.mu_fold[1:])}}
            rows.append(row)
        return rows


def _bayes_prediction(fit_: HopfFit, mu: float, branch: str) -> HeldOut:
    amp = fit_.amplitude([mu], branch, predictive=True)[:, 0]
    ok = np.isfinite(amp)
    iv = interval(amp[ok]) if ok.any() else None
    fold = fit_.interval("mu_fold")
    mu0 = fit_.interval("mu0")
    nan3 = (np.nan, np.nan, np.nan)
    return HeldOut(
        median=iv.median if iv else np.nan, lo=iv.lo if iv else np.nan,
        hi=iv.hi if iv else np.nan, p_exists=float(ok.mean()),
        mu_fold=(fold.median, fold.lo, fold.hi) if fold else nan3,
        mu0=(mu0.median, mu0.lo, mu0.hi),
    )


def _point_prediction(fit_: PointFit, mu: float, branch: str) -> HeldOut:
    point = float(fit_.amplitude([mu], branch)[0, 0])
    band = fit_.amplitude([mu], branch, predictive=True)[:, 0]
    band = band[np.isfinite(band)]
    lo, hi = (np.quantile(band, [0.05, 0.95]) if band.size else (np.nan, np.nan))
    fold, mu0 = fit_.value("mu_fold"), fit_.value("mu0")
    return HeldOut(median=point, lo=float(lo), hi=float(hi), p_exists=float(np.isfinite(point)),
                   mu_fold=(fold, fold, fold), mu0=(mu0, mu0, mu0))


def _point_from_bayes(fit_: HopfFit) -> PointFit:
    """The Bayesian fit's own MAP as a :class:`PointFit` (no extra optimisation)."""
    return PointFit(spec=fit_.spec, features=fit_.features, map=fit_.map, regularised=True,
                    settings=fit_.settings, seed=fit_.seed)


def fit_methods(rs: RecordingSet, criticality: str, methods, *, seed: int,
                settings: FitSettings) -> dict:
    """Fit ``rs`` by each method (``"bayes"``, ``"map"``, ``"ml"``)."""
    out = {}
    if "bayes" in methods or "map" in methods:
        bayes = fit(rs, criticality, seed=seed, settings=settings, progress=False)
        if "bayes" in methods:
            out["bayes"] = bayes
        if "map" in methods:
            out["map"] = _point_from_bayes(bayes)
    if "ml" in methods:
        out["ml"] = fit_point(rs, criticality, regularised=False, seed=seed, settings=settings,
                              progress=False)
    return out


def predict_held_out(fit_, method: str, mu: float, branch: str) -> HeldOut:
    """Prediction of a recording at ``(μ, branch)`` by a fit of the given method."""
    if method == "bayes":
        return _bayes_prediction(fit_, mu, branch)
    return _point_prediction(fit_, mu, branch)


def leave_one_out(
    rs: RecordingSet,
    criticality: str = "subcritical",
    *,
    methods=METHODS,
    seed: int = 0,
    settings: FitSettings | None = None,
    folds=None,
    keep_fits: bool = False,
    progress: bool = True,
) -> LeaveOneOut:
    """Refit without each recording in turn and predict it.

    Args:
        rs: All recordings.
        criticality: Normal form of every fit.
        methods: Any of ``"bayes"``, ``"map"``, ``"ml"``.
        seed: Seed of every fit.
        settings: Fit settings (the same for every fold).
        folds: Names of the recordings to hold out (default: all).
        keep_fits: Keep every fold's fits (for figures; memory grows with folds).
        progress: Show a progress bar over folds.

    Returns:
        A :class:`LeaveOneOut`.
    """
    settings = settings or FitSettings()
    unknown = set(methods) - set(METHODS)
    if unknown or not methods:
        raise ValueError(f"methods must be among {METHODS}; got {tuple(methods)!r}")
    methods = tuple(m for m in METHODS if m in methods)
    features = extract_features(rs, n_h=settings.n_h)
    names = list(rs.names) if folds is None else list(folds)
    out = []
    for name in tqdm(names, desc="leave-one-out", disable=not progress):
        i = list(rs.names).index(name)
        fits = fit_methods(rs.without(i), criticality, methods, seed=seed, settings=settings)
        mu, branch = float(features.mu[i]), "unstable" if features.unstable[i] else "stable"
        preds = {m: predict_held_out(fits[m], m, mu, branch) for m in methods}
        out.append(Fold(name=name, mu=mu, branch=branch, measured=float(features.amplitude[i]),
                        measured_sd=float(features.amplitude_sd[i]), predictions=preds,
                        fits=fits if keep_fits else None))
    return LeaveOneOut(folds=tuple(out), methods=methods)
