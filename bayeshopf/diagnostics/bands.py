"""Frequency and time-series bands: posterior summaries over μ and over time (immutable).

Made by :class:`~bayeshopf.posterior.HybridPosterior` (``frequency_band``,
``time_series_bands``, through :func:`time_series_bands`); drawn by
:mod:`bayeshopf.plotting.timeseries`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from bayeshopf.diagnostics.summaries import CI
from bayeshopf.features.harmonics import time_design


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


def time_series_bands(post, recordings, n_periods: float = 4.0, channel: int = 0,
                      ci: float = CI) -> list[TimeSeriesBand]:
    """:meth:`~bayeshopf.posterior.HybridPosterior.time_series_bands` of the fit ``post``.

    Per recording, the measured channel on a uniform grid of about 60 points
    per period over its first ``n_periods``, and the quantiles of
    ``post.time_series`` started at the recording's phase at its first sample,
    of the orbit as the recording's control held it (as the phase portraits').
    """
    out = []
    f = post.features
    for i, r in enumerate(recordings):
        z = r.planar(recordings.planar)
        t = r.t - r.t[0]
        om = float(f.omega[i])
        t_end = n_periods * 2 * np.pi / om
        window = t <= t_end
        w = post.spec.frame.to_frame(z[window])
        ab = np.linalg.lstsq(time_design(t[window], om, 1), w[:, 0], rcond=None)[0]
        phase0 = -float(np.arctan2(ab[2], ab[1]))
        # a uniform grid of about 60 points per period; the measured value is the
        # sample at each grid time, NaN where a sensor had no reading (left out of
        # the recording), so that the drawn line breaks there
        step = max(1, int(round(2 * np.pi / (om * 60 * r.dt)))) * r.dt
        tg = np.arange(0.0, t_end + 0.5 * step, step)
        idx = np.clip(np.searchsorted(t, tg), 0, t.size - 1)
        near = np.where(np.abs(t[idx - 1] - tg) < np.abs(t[idx] - tg), idx - 1, idx)
        meas = np.where(np.abs(t[near] - tg) <= 0.5 * r.dt, z[near, channel], np.nan)
        pred = post.time_series(r.mu, r.branch, tg, phase0,
                                control=post.recording_control(i))[..., channel]
        q = np.nanquantile(pred, [0.5, 0.5 - ci / 2, 0.5 + ci / 2], axis=0)
        name = recordings.planar[channel]
        out.append(TimeSeriesBand(r.name, r.mu, r.branch, name, r.units[name], tg,
                                  meas, q[0], q[1], q[2]))
    return out
