"""Posterior predictive checks of the training recordings."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayeshopf.diagnostics.predictive import amplitude_draws
from bayeshopf.diagnostics.summaries import Interval, interval
from bayeshopf.features.orbits import OrbitFeatures, amplitude_from_coeffs
from bayeshopf.model.hybrid import ModelSpec, branch_signs


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


def posterior_predictive_check(
    samples: dict, spec: ModelSpec, features: OrbitFeatures
) -> PosteriorPredictiveCheck:
    """Compare the measured amplitudes and coefficients with their predictive draws.

    Args:
        samples: Posterior draws including ``coeffs_rep``, the replicated
            coefficients of every training recording, ``(n_draws, n_rec, n_c)``.
        spec: Model structure.
        features: The training features.
    """
    rep = np.asarray(samples["coeffs_rep"])
    curve = amplitude_draws(samples, spec, features.mu, branch_signs(features.unstable))
    amp_rep = amplitude_from_coeffs(rep, spec.frame)
    p_amp = np.mean(amp_rep <= features.amplitude[None, :], axis=0)
    p_c = np.mean(rep <= features.coeffs[None], axis=0)
    z = (features.coeffs - rep.mean(axis=0)) / rep.std(axis=0)
    return PosteriorPredictiveCheck(
        names=tuple(features.names),
        mu=features.mu,
        unstable=features.unstable,
        measured=features.amplitude,
        curve=tuple(interval(curve[:, i]) for i in range(curve.shape[1])),
        predictive=tuple(interval(amp_rep[:, i]) for i in range(amp_rep.shape[1])),
        amplitude_p=p_amp,
        coeff_p=p_c,
        coeff_z=z,
    )
