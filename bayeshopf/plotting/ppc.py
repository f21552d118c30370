"""Posterior predictive check figure: amplitudes and Fourier-coefficient residuals."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from bayeshopf.diagnostics.ppc import PosteriorPredictiveCheck
from bayeshopf.plotting._style import (
    BRANCH_COLOURS,
    BRANCH_MARKERS,
    LABEL_SIZE,
    LEGEND_SIZE,
    TICK_SIZE,
    TITLE_SIZE,
    axis_label,
    ci_label,
    marker_face,
    new_figure,
    style_axes,
    tag,
    z_value,
)
from bayeshopf.plotting._units import convert

#: Colour scale limit of the standardised residuals.
Z_CLIP = 3.0


def coefficient_labels(n_c: int) -> list[str]:
    """Names ``a0, a1..an, b1..bn`` of the ``n_c = 2n + 1`` Fourier coefficients."""
    if n_c < 1 or n_c % 2 == 0:
        raise ValueError(f"expected an odd number of coefficients (2 n_h + 1); got {n_c}")
    n_h = (n_c - 1) // 2
    return ["a0", *(f"a{k}" for k in range(1, n_h + 1)), *(f"b{k}" for k in range(1, n_h + 1))]


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
    ax=None,
) -> Figure:
    """Plot the posterior predictive check of the training recordings.

    Panel (a): each recording's posterior predictive amplitude (median and
    interval at the check's level, 90% by default, thin bars) and the model
    curve's interval (thick inner bars) against its measured amplitude, whose
    own interval (the mean over its segments, ``ppc.measured_se``) is the
    horizontal bar, with the line y = x. Panel (b): heatmap of the standardised
    residuals of the Fourier coefficients, ``(Φ − mean Φ̃)/sd Φ̃``, per
    recording and coefficient, on a diverging scale clipped at ±3.

    Args:
        ppc: The check (:meth:`~bayeshopf.posterior.HybridPosterior.ppc`).
        amplitude_units: Unit of the amplitude.
        amplitude_label: Name of the amplitude in the axis labels (e.g.
            ``"peak-to-peak of h"``).
        length_unit: Draw the amplitudes in this length unit (``"mm"``, …).
        ax: ``None`` (a new figure with both panels), one Axes (panel (a)
            only), or two Axes (both panels; the colour bar is taken from the
            second's space).

    Returns:
        The figure: the panels and the colour bar.
    """
    from bayeshopf.plotting.diagram import scale_ppc

    factor, amplitude_units = convert(amplitude_units, length_unit)
    if factor != 1.0:
        ppc = scale_ppc(ppc, factor)
    if ax is None:
        fig = new_figure(7.2, 3.3)
        grid = fig.add_gridspec(1, 2, width_ratios=(1.0, 1.7), wspace=0.08)
        ax_a = fig.add_subplot(grid[0, 0])
        ax_b = fig.add_subplot(grid[0, 1])
    else:
        from matplotlib.axes import Axes

        axes = [ax] if isinstance(ax, Axes) else list(np.ravel(np.asarray(ax, dtype=object)))
        if not 1 <= len(axes) <= 2 or not all(isinstance(a, Axes) for a in axes):
            raise ValueError(f"ax: expected one or two matplotlib Axes; got {ax!r}")
        ax_a, ax_b = axes[0], (axes[1] if len(axes) == 2 else None)
        fig = ax_a.figure

    level = ci_label(ppc.ci)
    measured = np.asarray(ppc.measured, float)
    xerr = (None if ppc.measured_se is None
            else z_value(ppc.ci) * np.asarray(ppc.measured_se, float))
    unstable = np.asarray(ppc.unstable, bool)
    style_axes(ax_a)
    handles, labels = [], []
    for branch, mask in (("stable", ~unstable), ("unstable", unstable)):
        if not mask.any():
            continue
        c = BRANCH_COLOURS[branch]
        idx = np.flatnonzero(mask)
        med, err = _bars([ppc.predictive[i] for i in idx])
        cmed, cerr = _bars([ppc.curve[i] for i in idx])
        if xerr is not None:
            meas_bars = ax_a.errorbar(measured[idx], med, xerr=xerr[idx], fmt="none", ecolor=c,
                                      elinewidth=0.9, capsize=2.0, capthick=0.9, zorder=3)
            tag(meas_bars, f"{branch}-measured-interval")
        pred_bars = ax_a.errorbar(measured[idx], med, yerr=err, fmt="none", ecolor=c,
                                  elinewidth=0.9, capsize=2.5, capthick=0.9, zorder=3)
        tag(pred_bars, f"{branch}-predictive")
        curve_bars = ax_a.errorbar(measured[idx], cmed, yerr=cerr, fmt="none", ecolor=c,
                                   elinewidth=3.0, alpha=0.6, zorder=4)
        tag(curve_bars, f"{branch}-curve")
        ax_a.plot(measured[idx], med, ls="none", marker=BRANCH_MARKERS[branch], ms=4.5,
                  mfc=marker_face(branch), mec=c, mew=1.1, zorder=5, gid=f"{branch}-points")
        handles.append(Line2D([], [], ls="none", marker=BRANCH_MARKERS[branch], ms=4.5,
                              mfc=marker_face(branch), mec=c, mew=1.1))
        labels.append(branch)
    spread = np.zeros_like(measured) if xerr is None else xerr
    lo = min(float(np.min(measured - spread)), min(iv.lo for iv in ppc.predictive))
    hi = max(float(np.max(measured + spread)), max(iv.hi for iv in ppc.predictive))
    pad = 0.08 * (hi - lo if hi > lo else max(abs(hi), 1.0))
    lim = (max(lo - pad, 0.0) if lo >= 0 else lo - pad, hi + pad)
    ax_a.plot(lim, lim, color="0.35", lw=0.8, ls="--", zorder=1, gid="identity")
    handles += [Line2D([], [], color="0.35", lw=0.8, ls="--"),
                Line2D([], [], color="0.3", lw=0.9),
                Line2D([], [], color="0.3", lw=3.0, alpha=0.6)]
    labels += ["y = x", f"{level} predictive", f"{level} model curve"]
    if xerr is not None:
        handles.append(Line2D([], [], color="0.3", lw=0.9, marker="|", ms=6))
        labels.append(f"{level} measured")
    ax_a.set_xlim(lim)
    ax_a.set_ylim(lim)
    ax_a.set_xlabel(axis_label(f"measured {amplitude_label}", amplitude_units),
                    fontsize=LABEL_SIZE)
    ax_a.set_ylabel(axis_label(f"predicted {amplitude_label}", amplitude_units),
                    fontsize=LABEL_SIZE)
    ax_a.set_title("(a) amplitude", fontsize=TITLE_SIZE, loc="left")
    # below the axes: inside, a six-entry key covers amplitudes along y = x in a small panel
    ax_a.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2,
                fontsize=LEGEND_SIZE, frameon=False)
    if ax_b is None:
        return fig

    z = np.asarray(ppc.coeff_z, float)
    n_rec, n_c = z.shape
    im = ax_b.imshow(np.clip(z, -Z_CLIP, Z_CLIP), cmap="RdBu_r", vmin=-Z_CLIP, vmax=Z_CLIP,
                     aspect="auto", interpolation="nearest", gid="coeff-z")
    half = coefficient_labels(n_c // 2)     # the time harmonics of both channels of the frame
    labels = [f"{c}:{k}" for c in ("z1", "z2") for k in half]
    what = "time-Fourier coefficient of z1, z2 (phase-aligned)"
    ax_b.set_xticks(np.arange(n_c), labels, fontsize=TICK_SIZE - 1,
                    rotation=90 if n_c > 12 else 0)
    ax_b.set_yticks(np.arange(n_rec), list(ppc.names), fontsize=TICK_SIZE - 1)
    ax_b.tick_params(length=0)
    ax_b.set_xticks(np.arange(-0.5, n_c), minor=True)
    ax_b.set_yticks(np.arange(-0.5, n_rec), minor=True)
    ax_b.grid(True, which="minor", color="white", linewidth=0.8)
    ax_b.tick_params(which="minor", length=0)
    for spine in ax_b.spines.values():
        spine.set_visible(False)
    ax_b.set_xlabel(what, fontsize=LABEL_SIZE)
    ax_b.set_title("(b) standardised coefficient residuals", fontsize=TITLE_SIZE, loc="left")
    cbar = fig.colorbar(im, ax=ax_b, extend="both", shrink=0.9, pad=0.02)
    cbar.set_label(r"$(\Phi - \mathrm{mean}\,\tilde{\Phi})\,/\,\mathrm{sd}\,\tilde{\Phi}$",
                   fontsize=LABEL_SIZE)
    cbar.ax.tick_params(labelsize=TICK_SIZE)
    return fig
