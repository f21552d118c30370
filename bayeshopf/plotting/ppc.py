"""Posterior predictive check figure: amplitudes and Fourier-coefficient residuals."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from bayeshopf.diagnostics.ppc import PosteriorPredictiveCheck
from bayeshopf.features.harmonics import coefficient_names
from bayeshopf.plotting import _style
from bayeshopf.plotting._units import convert, scale_ppc

#: Colour scale limit of the standardised residuals.
Z_CLIP = 3.0


def coefficient_labels(n_c: int) -> list[str]:
    """Names ``a0, a1..an, b1..bn`` of the ``n_c = 2n + 1`` Fourier coefficients."""
    if n_c < 1 or n_c % 2 == 0:
        raise ValueError(f"expected an odd number of coefficients (2 n_h + 1); got {n_c}")
    return coefficient_names((n_c - 1) // 2)


def _bars(ivs) -> tuple[np.ndarray, np.ndarray]:
    med = np.array([iv.median for iv in ivs], float)
    err = np.array([[iv.median - iv.lo for iv in ivs], [iv.hi - iv.median for iv in ivs]], float)
    return med, np.clip(err, 0.0, None)


def plot_ppc(
    ppc: PosteriorPredictiveCheck,
    *,
    amplitude_units: str = "",
    amplitude_label: str = "amplitude",
    length_unit: str | None = None,
    channels: tuple[str, str] = ("z1", "z2"),
    ax=None,
) -> Figure:
    """Plot the posterior predictive check of the training recordings.

    ``fit.plot.ppc(ax=ax)`` (:class:`~bayeshopf.plotting.fit.FitPlots`) draws
    this with the fit's names and units.

    Panel (a): against each recording's measured amplitude ``A``, the
    differences from it, so that the intervals, small beside the amplitudes,
    can be seen: the posterior predictive amplitude ``Ã − A`` (median and
    interval at the check's level, 90% by default, thin bars with the marker),
    the model curve's interval (thick bars beside it) and the measurement's
    own interval (the mean over its segments, ``±z·ppc.measured_se``, grey
    bars about 0, on the other side), with the line y = 0. Panel (b): heatmap
    of the standardised residuals of the Fourier coefficients,
    ``(Φ − mean Φ̃)/sd Φ̃`` (measured minus the mean of the replicated
    recordings, in their standard deviations), per recording and coefficient,
    on a diverging scale clipped at ±3.

    Args:
        ppc: The check (:meth:`~bayeshopf.posterior.HybridPosterior.ppc`).
        amplitude_units: Unit of the amplitude.
        amplitude_label: Name of the amplitude in the axis labels (e.g.
            ``"peak-to-peak of h"``).
        length_unit: Draw the amplitudes in this length unit (``"mm"``, …).
        channels: Names of the two planar channels, for the coefficients' labels.
        ax: ``None`` (a new figure with both panels, titled (a) and (b)), one
            Axes (panel (a) only, untitled), or two Axes (both panels, titled;
            the colour bar is taken from the second's space).

    Returns:
        The figure: the panels and the colour bar.
    """
    factor, amplitude_units = convert(amplitude_units, length_unit)
    if factor != 1.0:
        ppc = scale_ppc(ppc, factor)
    if ax is None:
        fig = _style.new_figure(8.0, 3.4)
        grid = fig.add_gridspec(1, 2, width_ratios=(1.3, 1.7), wspace=0.08)
        ax_a = fig.add_subplot(grid[0, 0])
        ax_b = fig.add_subplot(grid[0, 1])
    else:
        from matplotlib.axes import Axes

        axes = [ax] if isinstance(ax, Axes) else list(np.ravel(np.asarray(ax, dtype=object)))
        if not 1 <= len(axes) <= 2 or not all(isinstance(a, Axes) for a in axes):
            raise ValueError(f"ax: expected one or two matplotlib Axes; got {ax!r}")
        ax_a, ax_b = axes[0], (axes[1] if len(axes) == 2 else None)
        fig = ax_a.figure

    level = _style.ci_label(ppc.ci)
    measured = np.asarray(ppc.measured, float)
    meas_err = (None if ppc.measured_se is None
            else _style.z_value(ppc.ci) * np.asarray(ppc.measured_se, float))
    unstable = np.asarray(ppc.unstable, bool)
    _style.style_axes(ax_a)
    span = float(np.ptp(measured)) or max(float(np.max(np.abs(measured))), 1.0)
    dx = 0.012 * span       # the three bars of a recording side by side
    handles, labels = [], []
    for branch, mask in (("stable", ~unstable), ("unstable", unstable)):
        if not mask.any():
            continue
        c = _style.BRANCH_COLOURS[branch]
        idx = np.flatnonzero(mask)
        x = measured[idx]
        med, err = _bars([ppc.predictive[i] for i in idx])
        cmed, cerr = _bars([ppc.curve[i] for i in idx])
        if meas_err is not None:
            meas_bars = ax_a.errorbar(x - dx, np.zeros_like(x), yerr=meas_err[idx], fmt="none",
                                      ecolor=_style.MEASURED_GREY, elinewidth=2.0, capsize=0,
                                      zorder=3)
            _style.tag(meas_bars, f"{branch}-measured-interval")
        pred_bars = ax_a.errorbar(x, med - x, yerr=err, fmt="none", ecolor=c,
                                  elinewidth=0.9, capsize=2.5, capthick=0.9, zorder=3)
        _style.tag(pred_bars, f"{branch}-predictive")
        curve_bars = ax_a.errorbar(x + dx, cmed - x, yerr=cerr, fmt="none", ecolor=c,
                                   elinewidth=3.0, alpha=0.6, zorder=4)
        _style.tag(curve_bars, f"{branch}-curve")
        ax_a.plot(x, med - x, ls="none", marker=_style.BRANCH_MARKERS[branch], ms=4.5,
                  mfc=_style.marker_face(branch), mec=c, mew=1.1, zorder=5, gid=f"{branch}-points")
        handles.append(Line2D([], [], ls="none", marker=_style.BRANCH_MARKERS[branch], ms=4.5,
                              mfc=_style.marker_face(branch), mec=c, mew=1.1))
        labels.append(f"{branch}, predicted median")
    ax_a.axhline(0.0, color="0.35", lw=0.8, ls="--", zorder=1, gid="identity")
    handles += [Line2D([], [], color="0.35", lw=0.8, ls="--"),
                Line2D([], [], color="0.3", lw=0.9),
                Line2D([], [], color="0.3", lw=3.0, alpha=0.6)]
    labels += ["predicted = measured", f"{level} predictive", f"{level} model curve"]
    if meas_err is not None:
        handles.append(Line2D([], [], color=_style.MEASURED_GREY, lw=2.0))
        labels.append(f"{level} measured")
    ax_a.set_xlim(float(np.min(measured)) - 0.08 * span, float(np.max(measured)) + 0.08 * span)
    ax_a.set_xlabel(_style.axis_label(f"measured {amplitude_label}", amplitude_units),
                    fontsize=_style.LABEL_SIZE)
    ax_a.set_ylabel(_style.axis_label("predicted − measured", amplitude_units),
                    fontsize=_style.LABEL_SIZE)
    if ax_b is not None:      # panel titles only where there are two panels to tell apart
        ax_a.set_title("(a) amplitude", fontsize=_style.TITLE_SIZE, loc="left")
    # below the axes: inside, a six-entry key covers amplitudes along y = x in a small panel
    ax_a.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2,
                fontsize=_style.LEGEND_SIZE, frameon=False)
    if ax_b is None:
        return fig

    z = np.asarray(ppc.coeff_z, float)
    n_rec, n_c = z.shape
    im = ax_b.imshow(np.clip(z, -Z_CLIP, Z_CLIP), cmap="RdBu_r", vmin=-Z_CLIP, vmax=Z_CLIP,
                     aspect="auto", interpolation="nearest", gid="coeff-z")
    half = coefficient_labels(n_c // 2)     # the time harmonics of both channels of the frame
    labels = [f"{c}:{k}" for c in channels for k in half]
    what = f"time-Fourier coefficient of {channels[0]}, {channels[1]} (phase-aligned)"
    ax_b.set_xticks(np.arange(n_c), labels, fontsize=_style.TICK_SIZE - 1,
                    rotation=90 if n_c > 12 else 0)
    ax_b.set_yticks(np.arange(n_rec), list(ppc.names), fontsize=_style.TICK_SIZE - 1)
    ax_b.tick_params(length=0)
    ax_b.set_xticks(np.arange(-0.5, n_c), minor=True)
    ax_b.set_yticks(np.arange(-0.5, n_rec), minor=True)
    ax_b.grid(True, which="minor", color="white", linewidth=0.8)
    ax_b.tick_params(which="minor", length=0)
    for spine in ax_b.spines.values():
        spine.set_visible(False)
    ax_b.set_xlabel(what, fontsize=_style.LABEL_SIZE)
    ax_b.set_title("(b) standardised coefficient residuals", fontsize=_style.TITLE_SIZE, loc="left")
    cbar = fig.colorbar(im, ax=ax_b, extend="both", shrink=0.9, pad=0.02)
    cbar.set_label("measured − predicted mean,\nin predictive standard deviations",
                   fontsize=_style.LABEL_SIZE)
    cbar.ax.tick_params(labelsize=_style.TICK_SIZE)
    return fig
