"""Time series and frequency of the speed model Ω (the paper's Fig. ts_exp, with bands)."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure

from bayeshopf.plotting._style import (
    BRANCH_COLOURS,
    BRANCH_MARKERS,
    LEGEND_SIZE,
    MEASURED_GREY,
    TITLE_SIZE,
    new_figure,
    style_axes,
)


def plot_time_series(bands, *, mu_label: str = "mu", mu_units: str = "",
                     max_columns: int = 2) -> Figure:
    """Measured vs predicted time series with 90% bands, one panel per recording.

    Args:
        bands: :class:`~bayeshopf.diagnostics.bands.TimeSeriesBand` records
            (from :meth:`SpeedFit.time_series_bands`).
        mu_label: Name of μ for the panel titles.
        mu_units: Unit of μ.
        max_columns: Panels per row.

    Returns:
        A new figure.
    """
    n = len(bands)
    if n == 0:
        raise ValueError("bands must hold at least one TimeSeriesBand; got none")
    cols = min(max_columns, n)
    rows = math.ceil(n / cols)
    fig = new_figure(4.0 * cols, 2.2 * rows)
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for ax, b in zip(axes, bands, strict=False):
        c = BRANCH_COLOURS[b.branch]
        ax.plot(b.t, b.measured, color=MEASURED_GREY, lw=1.0, label="measured")
        ax.fill_between(b.t, b.lo, b.hi, color=c, alpha=0.3, lw=0, label="90% band")
        ax.plot(b.t, b.median, color=c, lw=1.0, ls="--", label="posterior median")
        unit = f" [{b.units}]" if b.units else ""
        ax.set_xlabel("t [s]")
        ax.set_ylabel(f"{b.channel}{unit}")
        ax.set_title(f"{b.branch}, {mu_label} = {b.mu:g} {mu_units}".strip(), fontsize=TITLE_SIZE)
        style_axes(ax)
    for ax in axes[n:]:
        ax.set_visible(False)
    axes[0].legend(fontsize=LEGEND_SIZE, loc="upper right")
    return fig


def plot_frequency(bands, measured=None, *, predictive=None, mu_label: str = "mu",
                   mu_units: str = "") -> Figure:
    """Oscillation frequency against μ: posterior median and 90% band per branch.

    Args:
        bands: :class:`~bayeshopf.diagnostics.bands.FrequencyBand` records (the curve).
        measured: Optional ``(mu, frequency_hz, branch)`` triples of the recordings.
        predictive: Optional predictive :class:`~bayeshopf.diagnostics.bands.FrequencyBand`
            records (``frequency_band(..., predictive=True)``), drawn as dotted edges:
            where a new recording's frequency is expected.
        mu_label: Name of μ.
        mu_units: Unit of μ.

    Returns:
        A new figure.
    """
    fig = new_figure(4.5, 3.0)
    ax = fig.subplots()
    for b in bands:
        c = BRANCH_COLOURS[b.branch]
        ax.fill_between(b.mu, b.lo, b.hi, color=c, alpha=0.25, lw=0)
        ax.plot(b.mu, b.median, color=c, lw=1.2, label=f"{b.branch} (median, 90%)")
    for b in predictive or ():
        c = BRANCH_COLOURS[b.branch]
        ax.plot(b.mu, b.lo, ":", color=c, lw=1.0, label=f"{b.branch}, new recording (90%)")
        ax.plot(b.mu, b.hi, ":", color=c, lw=1.0)
    for mu, f, branch in measured or ():
        ax.plot([mu], [abs(f)], BRANCH_MARKERS[branch], color=BRANCH_COLOURS[branch],
                mfc="none" if branch == "unstable" else BRANCH_COLOURS[branch], ms=5)
    unit = f" [{mu_units}]" if mu_units else ""
    ax.set_xlabel(f"{mu_label}{unit}")
    ax.set_ylabel("frequency [Hz]")
    ax.legend(fontsize=LEGEND_SIZE)
    style_axes(ax)
    return fig
