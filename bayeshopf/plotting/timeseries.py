"""Time series and frequency of the speed model Ω (the paper's Fig. ts_exp, with bands)."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerTuple
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from bayeshopf.plotting._style import (
    BRANCH_COLOURS,
    BRANCH_MARKERS,
    LABEL_SIZE,
    LEGEND_SIZE,
    MEASURED_GREY,
    TITLE_SIZE,
    axis_label,
    ci_label,
    marker_face,
    new_figure,
    panels,
    style_axes,
    z_value,
)
from bayeshopf.plotting._units import convert
from bayeshopf.plotting.phase import channel_label, check_offsets

#: Widths of the measured trace (drawn on top) and the dashed median beneath it, which
#: shows on either side of the measured trace where the two agree.
MEASURED_LW, MEDIAN_LW = 0.9, 1.8
#: Default name of μ when the caller names none (``fit.plot.*`` passes the fit's).
DEFAULT_MU_LABEL = "bifurcation parameter"
#: A band whose typical (median) width is below this share of the axes' height reads
#: as its median line; it is not listed in the legend.
VISIBLE_BAND = 0.02


def plot_time_series(bands, *, mu_label: str = DEFAULT_MU_LABEL, mu_units: str = "",
                     max_columns: int = 2, offsets: str = "remove",
                     length_unit: str | None = None, angle_unit: str | None = None,
                     ci: float = 0.9, ax=None) -> Figure:
    """Measured vs predicted time series with credible bands, one panel per recording.

    The measured trace (grey) is drawn on top of the posterior median (dashed,
    wider, in the branch's colour). ``fit.plot.time_series(recordings, ax=)``
    passes the fit's names and units.

    Args:
        bands: :class:`~bayeshopf.diagnostics.bands.TimeSeriesBand` records
            (from :meth:`~bayeshopf.posterior.HybridPosterior.time_series_bands`).
        mu_label: Name of μ for the panel titles.
        mu_units: Unit of μ.
        max_columns: Panels per row.
        offsets: ``"remove"`` (default: the measured series' mean over the
            window is subtracted from it and from the prediction, and the axis
            reads ``Δz1``) or ``"keep"``.
        length_unit: Draw a length channel in this unit (``"mm"``, …).
        angle_unit: Draw an angle channel in this unit (``"deg"``, …).
        ci: Level of the bands (for the legend; the bands carry it).
        ax: Axes to draw into, one per band (a sequence or array; extra ones
            hidden); a new figure when ``None``.

    Returns:
        The figure.
    """
    check_offsets(offsets)
    n = len(bands)
    if n == 0:
        raise ValueError("bands must hold at least one TimeSeriesBand; got none")
    cols = min(max_columns, n)
    rows = math.ceil(n / cols)

    def make():
        f = new_figure(4.0 * cols, 2.2 * rows)
        axes = np.atleast_1d(f.subplots(rows, cols, squeeze=False)).ravel()
        for a in axes[n:]:
            a.set_visible(False)
        return f, axes[:n]

    fig, axes = panels(ax, n, make)
    removed = offsets == "remove"
    for ax_i, b in zip(axes, bands, strict=False):
        c = BRANCH_COLOURS[b.branch]
        factor, unit = convert(b.units, length_unit, angle_unit)
        shift = float(np.nanmean(b.measured)) if removed else 0.0
        ax_i.fill_between(b.t, (np.asarray(b.lo) - shift) * factor,
                          (np.asarray(b.hi) - shift) * factor, color=c, alpha=0.3, lw=0,
                          label=f"{ci_label(ci)} band", gid="band")
        ax_i.plot(b.t, (np.asarray(b.median) - shift) * factor, color=c, lw=MEDIAN_LW, ls="--",
                  label="posterior median", gid="median", zorder=2)
        # the measured trace on top of the median, which it would otherwise hide under
        ax_i.plot(b.t, (np.asarray(b.measured) - shift) * factor, color=MEASURED_GREY,
                  lw=MEASURED_LW, label="measured", gid="measured", zorder=3)
        ax_i.set_xlabel("t [s]", fontsize=LABEL_SIZE)
        ax_i.set_ylabel(channel_label(b.channel, unit, removed), fontsize=LABEL_SIZE)
        ax_i.set_title(f"{b.branch}, {mu_label} = {b.mu:g} {mu_units}".strip(),
                       fontsize=TITLE_SIZE)
        style_axes(ax_i)
        # major ticks only, as the phase portraits: the minor ones' tick objects took
        # much of this figure's drawing time
        ax_i.minorticks_off()
    # one key per artist, in every branch colour the panels use (stable blue, unstable red)
    colours = [BRANCH_COLOURS[k] for k in ("stable", "unstable")
               if any(b.branch == k for b in bands)]
    handles = [Line2D([], [], color=MEASURED_GREY, lw=MEASURED_LW),
               tuple(Patch(color=c, alpha=0.3, lw=0) for c in colours),
               tuple(Line2D([], [], color=c, lw=MEDIAN_LW, ls="--") for c in colours)]
    labels = ["measured", f"{ci_label(ci)} band", "posterior median"]
    kw = dict(fontsize=LEGEND_SIZE, handlelength=3.0,
              handler_map={tuple: HandlerTuple(ndivide=None, pad=0.3)})
    if ax is None:     # below the panels, where it hides no crest
        fig.legend(handles, labels, frameon=False, loc="outside lower center", ncol=3, **kw)
    else:
        axes[0].legend(handles, labels, loc="upper right", **kw)
    return fig


def plot_frequency(bands, measured=None, *, predictive=None, mu_label: str = DEFAULT_MU_LABEL,
                   mu_units: str = "", ci: float = 0.9, ax=None) -> Figure:
    """Oscillation frequency against μ: posterior median and credible band per branch.

    The legend lists a band (credible or predictive) only where it is drawn
    visibly: a median width over μ of at least :data:`VISIBLE_BAND` of the
    axes' height; a narrower credible band lies under its median line (the
    legend says so) and a narrower predictive band is not drawn. ``fit.plot.frequency(ax=)``
    passes the fit's bands, recordings, names and units.

    Args:
        bands: :class:`~bayeshopf.diagnostics.bands.FrequencyBand` records (the curve).
        measured: Optional ``(mu, frequency_hz, branch)`` triples of the recordings,
            or ``(mu, frequency_hz, branch, se_hz)`` with the standard error of
            each frequency, drawn as its ``ci`` interval.
        predictive: Optional predictive :class:`~bayeshopf.diagnostics.bands.FrequencyBand`
            records (``frequency_band(..., predictive=True)``), drawn as dotted edges:
            where a new recording's frequency is expected.
        mu_label: Name of μ.
        mu_units: Unit of μ.
        ci: Level of the bands (for the legend) and of the measured intervals.
        ax: Axes to draw into; a new figure when ``None``.

    Returns:
        The figure.
    """
    def make():
        f = new_figure(4.5, 3.0)
        return f, [f.subplots()]

    fig, (ax,) = panels(ax, 1, make)
    level = ci_label(ci)
    for b in bands:
        c = BRANCH_COLOURS[b.branch]
        ax.fill_between(b.mu, b.lo, b.hi, color=c, alpha=0.25, lw=0, gid=f"{b.branch}-band")
        # above the predictive edges, which run under it where they are close
        ax.plot(b.mu, b.median, color=c, lw=1.2, gid=f"{b.branch}-median", zorder=2.5)
    for row in measured or ():
        mu, f, branch = row[:3]
        se = row[3] if len(row) > 3 else 0.0
        colour = BRANCH_COLOURS[branch]
        ax.errorbar([mu], [abs(f)], yerr=[z_value(ci) * se] if se else None,
                    fmt=BRANCH_MARKERS[branch], color=colour, mfc=marker_face(branch),
                    mec=colour, ms=5, capsize=2, elinewidth=0.9, gid=f"{branch}-measured")
    ax.set_xlabel(axis_label(mu_label, mu_units), fontsize=LABEL_SIZE)
    ax.set_ylabel("frequency [Hz]", fontsize=LABEL_SIZE)
    style_axes(ax)
    lo, hi = ax.get_ylim()
    height = abs(hi - lo) or 1.0
    # a predictive band narrower than that would only fuzz its median line with dots
    shown = [b for b in predictive or () if _typical_width(b) >= VISIBLE_BAND * height]
    for b in shown:
        c = BRANCH_COLOURS[b.branch]
        ax.plot(b.mu, b.lo, ":", color=c, lw=1.0, gid=f"{b.branch}-predictive")
        ax.plot(b.mu, b.hi, ":", color=c, lw=1.0, gid=f"{b.branch}-predictive")
    ax.legend(*_frequency_legend(bands, shown, level, height), fontsize=LEGEND_SIZE)
    return fig


def _typical_width(b) -> float:
    """Median width over μ of a frequency band (0 where it has none)."""
    w = np.abs(np.asarray(b.hi, float) - np.asarray(b.lo, float))
    w = w[np.isfinite(w)]
    return float(np.median(w)) if w.size else 0.0


def _frequency_legend(bands, predictive, level: str, height: float
                      ) -> tuple[list, list[str]]:
    """Legend of :func:`plot_frequency`: its medians, bands wide enough to see, predictive drawn.

    A credible band is seen when its typical width is :data:`VISIBLE_BAND` of ``height``.
    """
    handles, labels = [], []
    for b in bands:
        c = BRANCH_COLOURS[b.branch]
        seen = _typical_width(b) >= VISIBLE_BAND * height
        handles.append((Patch(color=c, alpha=0.25, lw=0), Line2D([], [], color=c, lw=1.2))
                       if seen else Line2D([], [], color=c, lw=1.2))
        labels.append(f"{b.branch}, median and {level} CI" if seen
                      else f"{b.branch}, median ({level} CI narrower than the line)")
    for b in predictive:
        handles.append(Line2D([], [], ls=":", color=BRANCH_COLOURS[b.branch], lw=1.0))
        labels.append(f"{b.branch}, new recording ({level})")
    return handles, labels
