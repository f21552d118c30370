"""Frequency and time-series bands: posterior summaries over μ and over time (immutable).

Made by :class:`~bayeshopf.posterior.HybridPosterior` (``frequency_band``,
``time_series_bands``); drawn by :mod:`bayeshopf.plotting.timeseries`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TimeSeriesBand:
    """Measured and predicted time series of one planar channel of one recording.

    Attributes:
        name: Recording name.
        mu: μ of the recording.
        branch: Its branch.
        channel: Channel name.
        units: Channel unit.
        t: Times from the first sample (s), shape ``(n_t,)``.
        measured: Measured channel, shape ``(n_t,)``; NaN where the recording has no
            sample (a sensor dropout left out).
        median: Posterior median of the predicted channel.
        lo: 5% quantile.
        hi: 95% quantile.
    """

    name: str
    mu: float
    branch: str
    channel: str
    units: str
    t: np.ndarray
    measured: np.ndarray
    median: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


@dataclass(frozen=True)
class FrequencyBand:
    """Posterior frequency (Hz) on a μ grid for one branch.

    Attributes:
        branch: ``"stable"`` or ``"unstable"``.
        mu: μ grid, shape ``(n_mu,)``.
        median: Median over the draws that have an LCO (nan where < half do).
        lo: Lower end of the band (5% quantile at the default 90%).
        hi: Upper end (95% quantile at 90%).
    """

    branch: str
    mu: np.ndarray
    median: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    @classmethod
    def from_draws(cls, branch: str, mu, draws, ci: float = 0.9) -> FrequencyBand:
        """Median and ``ci`` band (90% by default) of frequency draws ``(n, n_mu)``.

        ``nan`` in a draw: no LCO there; ``nan`` in the band where fewer than
        half the draws have the branch.
        """
        draws = np.asarray(draws, dtype=float)
        ok = np.isfinite(draws).mean(axis=0) >= 0.5
        with warnings.catch_warnings():      # all-nan columns: no draw has the branch there
            warnings.simplefilter("ignore", RuntimeWarning)
            q = np.where(ok, np.nanquantile(draws, [0.5, 0.5 - ci / 2, 0.5 + ci / 2], axis=0),
                         np.nan)
        return cls(branch, np.asarray(mu, dtype=float), q[0], q[1], q[2])
