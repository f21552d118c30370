"""Bifurcation diagram with credible bands: amplitude against μ on each branch."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayeshopf.diagnostics.summaries import Interval

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


def quantiles(amp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quantiles at :data:`LEVELS` of amplitude draws ``(n, n_mu)`` and the share that exist.

    ``nan`` (no LCO in a draw) is left out; where fewer than 5% of draws have
    an LCO the quantiles are ``nan``.
    """
    exists = np.isfinite(amp)
    p = exists.mean(axis=0)
    q = np.full((len(LEVELS), amp.shape[1]), np.nan)
    for j in np.flatnonzero(p >= 0.05):
        q[:, j] = np.quantile(amp[exists[:, j], j], LEVELS)
    return q, p
