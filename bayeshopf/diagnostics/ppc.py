"""Posterior predictive checks of the training recordings.

The check converts to xarray (:meth:`PosteriorPredictiveCheck.to_dataset`) and
pandas (:meth:`PosteriorPredictiveCheck.to_dataframe`).
"""

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
        measured_se: Standard error of each measured amplitude, from the spread
            of its segments' amplitudes (``sd/√n_segments``; 0 for a record of
            one segment), or ``None`` when unknown. The figures draw the
            measurement's own interval from it.
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
    measured_se: np.ndarray | None = None

    @property
    def ci(self) -> float:
        """Probability mass of the intervals (0.9 by default)."""
        return float(self.predictive[0].mass) if self.predictive else 0.9

    @property
    def covered(self) -> np.ndarray:
        """Whether each measured amplitude lies in its predictive interval (mass :attr:`ci`)."""
        pairs = zip(self.predictive, self.measured, strict=True)
        return np.array([iv.contains(a) for iv, a in pairs])

    @property
    def coeff_coverage(self) -> float:
        """Fraction of measured coefficients inside their central predictive intervals.

        The intervals have mass :attr:`ci` (90% by default).
        """
        tail = (1 - self.ci) / 2
        return float(np.mean((self.coeff_p > tail) & (self.coeff_p < 1 - tail)))

    def to_dataset(self):
        """The check as an :class:`xarray.Dataset` over ``recording`` (and ``coefficient``).

        Variables: ``mu``, ``branch``, ``measured``, ``measured_se``,
        ``curve_median``/``curve_lower``/``curve_upper``,
        ``predictive_median``/``predictive_lower``/``predictive_upper``,
        ``covered``, ``amplitude_p``, and ``coeff_p``, ``coeff_z`` over
        ``(recording, coefficient)`` (the frame's two axes' coefficients in
        turn); the level is the attribute ``ci``.
        """
        import xarray as xr

        def ends(ivs):
            return (np.array([iv.median for iv in ivs]), np.array([iv.lo for iv in ivs]),
                    np.array([iv.hi for iv in ivs]))

        cm, clo, chi = ends(self.curve)
        pm, plo, phi = ends(self.predictive)
        n = len(self.names)
        se = (np.full(n, np.nan) if self.measured_se is None
              else np.asarray(self.measured_se, float))
        r = ("recording",)
        data = {
            "mu": (r, np.asarray(self.mu, float)),
            "branch": (r, np.where(np.asarray(self.unstable, bool), "unstable", "stable")),
            "measured": (r, np.asarray(self.measured, float)), "measured_se": (r, se),
            "curve_median": (r, cm), "curve_lower": (r, clo), "curve_upper": (r, chi),
            "predictive_median": (r, pm), "predictive_lower": (r, plo),
            "predictive_upper": (r, phi),
            "covered": (r, self.covered), "amplitude_p": (r, np.asarray(self.amplitude_p)),
            "coeff_p": (("recording", "coefficient"), np.asarray(self.coeff_p, float)),
            "coeff_z": (("recording", "coefficient"), np.asarray(self.coeff_z, float)),
        }
        return xr.Dataset(data, coords={"recording": list(self.names)},
                          attrs={"ci": self.ci})

    def to_dataframe(self):
        """One row per recording (:meth:`to_dataset` without the coefficients), pandas."""
        return self.to_dataset().drop_vars(["coeff_p", "coeff_z"]).to_dataframe()
