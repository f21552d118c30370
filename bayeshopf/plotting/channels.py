"""A further channel regressed on the normal-form state: waveforms and amplitudes with bands."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from bayeshopf.plotting import _style


def plot_channel(channel_fit, fit_, *, mu_grid=None, n_cols: int = 4,
                 max_points: int = 1500, ax=None) -> Figure:
    """Measured channel against normal-form phase per recording, and its amplitude against μ.

    Each recording's panel shows the measured samples placed on the predicted
    orbit (φ of the nearest point of the orbit in the frame), the posterior
    median waveform and the 90% band of a new recording's waveform. The last
    panel shows the channel's peak-to-peak against μ on both branches (median,
    90% band) with the measured values.

    Args:
        channel_fit: A :class:`~bayeshopf.inference.channels.ChannelFit`.
        fit_: The :class:`~bayeshopf.posterior.HybridPosterior` it was made from.
        mu_grid: μ grid of the amplitude panel.
        n_cols: Panels per row.
        max_points: Measured samples drawn per panel.
        ax: Axes to draw into, one per recording and one for the amplitudes
            (a sequence or array; extra ones hidden); a new figure when ``None``.

    Returns:
        The figure.
    """
    feats = fit_.features
    n_rec = len(feats.names)
    n_rows = int(np.ceil((n_rec + 1) / n_cols))

    def make():
        f = _style.new_figure(3.0 * n_cols, 2.5 * n_rows)
        return f, f.subplots(n_rows, n_cols, squeeze=False).ravel()

    fig, axes = _style.panels(ax, n_rec + 1, make)
    units = channel_fit.units
    phi = np.linspace(0.0, 2.0 * np.pi, 128, endpoint=False)
    for i, ax in enumerate(axes[:n_rec]):
        _style.style_axes(ax)
        branch = "unstable" if feats.unstable[i] else "stable"
        colour = _style.BRANCH_COLOURS[branch]
        ph, y = channel_fit.phases[i]
        step = max(1, ph.size // max_points)
        ax.plot(ph[::step], y[::step], ls="none", marker=".", ms=1.5, color=_style.MEASURED_GREY,
                alpha=0.5, rasterized=True)
        wave = channel_fit.waveform(fit_, float(feats.mu[i]), branch, predictive=True, seed=i)
        lo, med, hi = np.nanquantile(wave, [0.05, 0.5, 0.95], axis=0)
        ax.fill_between(phi, lo, hi, color=colour, alpha=0.25, lw=0)
        ax.plot(phi, med, color=colour, lw=1.6)
        ax.set_title(f"{feats.mu[i]:g} {fit_.mu_units} ({branch})", fontsize=_style.LABEL_SIZE - 1)
        ax.set_xlim(0, 2 * np.pi)
        ax.set_xticks([0, np.pi, 2 * np.pi], ["0", "π", "2π"])
        ax.tick_params(labelsize=_style.TICK_SIZE - 1)
        ax.set_xlabel("normal-form phase φ", fontsize=_style.LABEL_SIZE - 1)
        ax.set_ylabel(_style.axis_label(channel_fit.name, units), fontsize=_style.LABEL_SIZE - 1)
    ax = axes[n_rec]
    _style.style_axes(ax)
    mu = np.asarray(feats.mu, float)
    if mu_grid is None:
        span = mu.max() - mu.min()
        mu_grid = np.linspace(mu.min() - 0.05 * span, mu.max() + 0.05 * span, 30)
    for branch, mask in (("stable", ~feats.unstable), ("unstable", feats.unstable)):
        if not mask.any():
            continue
        colour = _style.BRANCH_COLOURS[branch]
        grid = mu_grid if branch == "stable" else mu_grid[mu_grid <= mu[mask].max() + 1e-9]
        amp = channel_fit.amplitude(fit_, grid, branch, predictive=True)
        lo, med, hi = np.nanquantile(amp, [0.05, 0.5, 0.95], axis=0)
        ax.fill_between(grid, lo, hi, color=colour, alpha=0.22, lw=0)
        ax.plot(grid, med, color=colour, lw=1.6, ls="-" if branch == "stable" else "--",
                label=f"{branch}: median, 90% band")
        ax.plot(mu[mask], channel_fit.measured_amplitude[mask], ls="none",
                marker=_style.BRANCH_MARKERS[branch], mfc=_style.marker_face(branch), mec=colour,
                ms=5)
    ax.set_xlabel(_style.axis_label(fit_.mu_label, fit_.mu_units), fontsize=_style.LABEL_SIZE - 1)
    ax.set_ylabel(_style.axis_label(f"{channel_fit.name} peak-to-peak", units),
                  fontsize=_style.LABEL_SIZE - 1)
    ax.legend(fontsize=_style.LEGEND_SIZE - 1)
    ax.tick_params(labelsize=_style.TICK_SIZE - 1)
    for ax in axes[n_rec + 1:]:
        ax.set_visible(False)
    return fig
