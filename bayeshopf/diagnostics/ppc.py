"""Posterior predictive checks of the training recordings."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayeshopf.diagnostics.summaries import Interval


@dataclass(frozen=True)
class PosteriorPredictiveCheck:
    """How well the posterior reproduces each training recording.

    Attributes:
        names: Recording names.
        mu: μ of each recording.
        unstable: Branch mask.
        measured: Measured amplitudes (peak-to-peak of z1).
        curve: Interval of the model curve's amplitude at each recording.
        predictive: Interval of the replicated recording's amplitude (posterior
            predictive: the model plus the scatter σ and the recording's
            segment spread).
        amplitude_p: Posterior predictive p-value ``P(Ã ≤ A)`` per recording.
        coeff_p: Posterior predictive p-values ``P(Φ̃ ≤ Φ)``, shape ``(n_rec, n_c)``.
        coeff_z: Standardised residuals ``(Φ − mean Φ̃)/sd Φ̃``, same shape.
    """

    names: tuple[str, ...]
    mu: np.ndarray
    unstable: np.ndarray
    measured: np.ndarray
    curve: tuple[Interval, ...]
    predictive: tuple[Interval, ...]
    amplitude_p: np.ndarray
    coeff_p: np.ndarray
    coeff_z: np.ndarray

    @property
    def covered(self) -> np.ndarray:
        """Whether each measured amplitude lies in its 90% predictive interval."""
        pairs = zip(self.predictive, self.measured, strict=True)
        return np.array([iv.contains(a) for iv, a in pairs])

    @property
    def coeff_coverage(self) -> float:
        """Fraction of measured coefficients inside their 90% predictive intervals."""
        return float(np.mean((self.coeff_p > 0.05) & (self.coeff_p < 0.95)))
