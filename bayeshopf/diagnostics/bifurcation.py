"""Bifurcation diagram with credible bands: amplitude against μ on each branch."""

from __future__ import annotations

from dataclasses import dataclass

import jax
import numpy as np

from bayeshopf.diagnostics.predictive import (
    amplitude_draws,
    fold_amplitude_draws,
    predictive_amplitude_draws,
)
from bayeshopf.diagnostics.summaries import Interval, interval
from bayeshopf.model import normal_form
from bayeshopf.model.hybrid import ModelSpec

#: Quantile levels stored per μ: 90% band, 50% band and the median.
LEVELS = (0.05, 0.25, 0.5, 0.75, 0.95)


@dataclass(frozen=True)
class BranchBand:
    """Posterior of one branch of the diagram on a μ grid.

    Attributes:
        sign: +1 stable, −1 unstable.
        mu: The μ grid, shape ``(n_mu,)``.
        quantiles: Amplitude quantiles at :data:`LEVELS`, shape ``(5, n_mu)``,
            over the draws in which the branch exists there (``nan`` where it
            exists in fewer than 5% of draws).
        p_exists: Posterior probability that the branch exists at each μ.
        predictive: Quantiles of the posterior predictive amplitude of a new
            recording at each μ (the curve's uncertainty plus the measurement
            and model-error scatter σ), shape ``(5, n_mu)``.
    """

    sign: int
    mu: np.ndarray
    quantiles: np.ndarray
    p_exists: np.ndarray
    predictive: np.ndarray

    @property
    def median(self) -> np.ndarray:
        """Posterior median amplitude."""
        return self.quantiles[2]


@dataclass(frozen=True)
class BifurcationDiagram:
    """Bands of both branches with the Hopf and fold points.

    Attributes:
        stable: The stable branch.
        unstable: The unstable branch, or ``None`` (supercritical).
        mu0: Interval of the Hopf point μ0.
        mu_fold: Interval of the fold μ, or ``None`` (supercritical).
        fold_amplitude: Interval of the amplitude at the fold, or ``None``.
    """

    stable: BranchBand
    unstable: BranchBand | None
    mu0: Interval
    mu_fold: Interval | None
    fold_amplitude: Interval | None


def _quantiles(amp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    exists = np.isfinite(amp)
    p = exists.mean(axis=0)
    q = np.full((len(LEVELS), amp.shape[1]), np.nan)
    for j in np.flatnonzero(p >= 0.05):
        q[:, j] = np.quantile(amp[exists[:, j], j], LEVELS)
    return q, p


#: Draws used for the predictive band (it needs a Fourier projection per draw and μ).
N_PREDICTIVE_DRAWS = 300


#: Draws used for the curve bands (5%–95% quantiles are stable with 500).
N_CURVE_DRAWS = 500


def _band(samples, spec, mu, sign, key) -> BranchBand:
    some = {k: np.asarray(v)[:N_CURVE_DRAWS] for k, v in samples.items()}
    q, p = _quantiles(amplitude_draws(some, spec, mu, sign))
    few = {k: np.asarray(v)[:N_PREDICTIVE_DRAWS] for k, v in samples.items()}
    qp, _ = _quantiles(predictive_amplitude_draws(few, spec, mu, sign, key))
    return BranchBand(int(sign), mu, q, p, qp)


def default_mu_grid(spec: ModelSpec, samples: dict, n: int = 120) -> np.ndarray:
    """A μ grid from below the fold (or Hopf point) to beyond the training data."""
    lo = min(spec.mu_min, float(np.quantile(samples["mu0"], 0.01)))
    if spec.criticality == "subcritical":
        lo = min(lo, float(np.quantile(normal_form.fold_point(samples["mu0"], samples["a2"]),
                                       0.01)))
    hi = max(spec.mu_min + spec.mu_span, float(np.quantile(samples["mu0"], 0.99)))
    pad = 0.05 * (hi - lo)
    return np.linspace(lo - pad, hi + pad, n)


def bifurcation_diagram(
    samples: dict, spec: ModelSpec, mu: np.ndarray | None = None, *, seed: int = 0
) -> BifurcationDiagram:
    """Posterior bifurcation diagram.

    The amplitude (peak-to-peak of z1) is computed for every draw at every μ
    on each branch, ``r² = (a2 ± √(a2² + 4(μ − μ0)))/2`` mapped by U12.

    Args:
        samples: Posterior draws.
        spec: Model structure.
        mu: μ grid; by default :func:`default_mu_grid`.
        seed: Seed of the predictive noise draws.
    """
    mu = default_mu_grid(spec, samples) if mu is None else np.asarray(mu, float)
    k_s, k_u = jax.random.split(jax.random.PRNGKey(seed))
    stable = _band(samples, spec, mu, normal_form.STABLE, k_s)
    if spec.criticality == "subcritical":
        unstable = _band(samples, spec, mu, normal_form.UNSTABLE, k_u)
        mu_fold = interval(normal_form.fold_point(samples["mu0"], samples["a2"]))
        fold_amp = interval(fold_amplitude_draws(samples, spec))
    else:
        unstable, mu_fold, fold_amp = None, None, None
    return BifurcationDiagram(stable, unstable, interval(samples["mu0"]), mu_fold, fold_amp)
