"""Phase portraits: measured orbits against the posterior's predicted orbits."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerTuple
from matplotlib.lines import Line2D

from bayeshopf.data.recording import RecordingSet
from bayeshopf.plotting._style import (
    BRANCH_COLOURS,
    LABEL_SIZE,
    LEGEND_SIZE,
    MEASURED_GREY,
    TITLE_SIZE,
    axis_label,
    new_figure,
    panels,
    style_axes,
)
from bayeshopf.plotting._units import convert

#: Callable giving the true orbit, ``truth(mu, branch) -> points (n, 2)``.
OrbitTruth = Callable[[float, str], np.ndarray]

#: Most panels per row of the grid.
MAX_COLUMNS = 4


def _closed(points: np.ndarray) -> np.ndarray:
    """The orbit with its first point appended (a closed curve)."""
    return np.concatenate([points, points[..., :1, :]], axis=-2)


def _pick(n: int, k: int) -> np.ndarray:
    """``k`` indices spread evenly over ``range(n)`` (deterministic)."""
    if k >= n:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max(k, 1)).round().astype(int))


def _format_mu(mu: float) -> str:
    return f"{mu:.4g}"


def check_offsets(offsets: str) -> None:
    """Raise ``ValueError`` unless ``offsets`` is ``"remove"`` or ``"keep"``."""
    if offsets not in ("remove", "keep"):
        raise ValueError(f"offsets must be 'remove' or 'keep'; got {offsets!r}")


def channel_label(name: str, units: str, removed: bool) -> str:
    """``"Δh [mm]"`` (offset removed) or ``"h [mm]"``."""
    return axis_label(f"Δ{name}" if removed else name, units)


def plot_phase_portraits(
    fit,
    recordings: RecordingSet,
    *,
    n_orbits: int = 60,
    max_points: int = 4000,
    truth: OrbitTruth | None = None,
    mu_symbol: str = "μ",
    offsets: str = "remove",
    length_unit: str | None = None,
    angle_unit: str | None = None,
    ax=None,
) -> Figure:
    """Plot each recording's measured orbit over the posterior predicted orbits.

    One panel per recording (in the set's order), titled with its μ and branch.
    The measured (z1, z2) trajectory is a thin grey line; ``n_orbits`` posterior
    orbit draws at the recording's μ and branch are thin translucent lines in
    the branch colour, and their pointwise median (over all draws in which the
    orbit exists) is a bold line. With ``offsets="remove"`` (the default) each
    panel is centred on its recording: the recording's mean (z1, z2) is
    subtracted from the measured trajectory, the predicted orbits and the
    truth alike (so a mismatch of centres still shows), and the axes read
    ``Δz1``, ``Δz2``; sensor offsets of a rig (a heave of 0.6 m about which
    the orbit has millimetres) then no longer hide the orbits.

    Args:
        fit: A :class:`~bayeshopf.posterior.HybridPosterior`, or anything with
            ``orbits(mu, branch) -> draws (n, n_phi, 2)`` in physical units.
        recordings: The recordings to show (normally the training set).
        n_orbits: Posterior orbit draws drawn per panel.
        max_points: Most measured samples drawn per panel (the record is
            subsampled evenly).
        truth: Optional ``truth(mu, branch) -> points (n, 2)``, drawn as a thin
            black dashed closed curve.
        mu_symbol: Name of μ in the panel titles.
        offsets: ``"remove"`` (each recording's mean subtracted) or ``"keep"``.
        length_unit: Draw channels in a length unit in this one (``"mm"``, …).
        angle_unit: Draw channels in an angle unit in this one (``"deg"``, …).
        ax: Axes to draw into, one per recording (a sequence or array of one
            figure; extra axes are hidden); a new figure when ``None``.

    Returns:
        The figure, one axes per recording (and the legend: the figure's for a
        new figure, the first axes' otherwise).
    """
    check_offsets(offsets)
    recs = list(recordings)
    n = len(recs)
    ncols = min(MAX_COLUMNS, n)
    nrows = math.ceil(n / ncols)

    def make():
        f = new_figure(1.9 * ncols + 0.4, 1.85 * nrows + 0.55)
        grid = f.add_gridspec(nrows, ncols)
        return f, [f.add_subplot(grid[divmod(i, ncols)]) for i in range(n)]

    own = ax is None
    fig, axes = panels(ax, n, make)
    names, units = recordings.planar, recordings.units
    scale = [convert(u, length_unit, angle_unit) for u in units[:2]]
    factor = np.array([scale[0][0], scale[1][0]])
    shown_units = (scale[0][1], scale[1][1])
    mu_units = recordings.mu_units
    removed = offsets == "remove"

    branches = {rec.branch for rec in recs}
    for i, (rec, ax_i) in enumerate(zip(recs, axes, strict=False)):
        col = i % ncols
        style_axes(ax_i)
        ax_i.minorticks_off()
        colour = BRANCH_COLOURS[rec.branch]

        z = np.asarray(rec.planar(recordings.planar), float)
        centre = z.mean(axis=0) if removed else np.zeros(2)
        # broken where samples were left out (sensor dropouts), not joined across
        measured = (rec.trace(recordings.planar, max_points) - centre) * factor
        ax_i.plot(measured[:, 0], measured[:, 1], color=MEASURED_GREY, lw=0.5, alpha=0.8,
                  zorder=1, gid="measured")

        draws = np.asarray(fit.orbits(rec.mu, rec.branch), float)
        exists = np.all(np.isfinite(draws), axis=(1, 2))
        draws = (draws[exists] - centre) * factor
        if draws.shape[0]:
            shown = _closed(draws[_pick(draws.shape[0], n_orbits)])
            for orbit in shown:
                ax_i.plot(orbit[:, 0], orbit[:, 1], color=colour, lw=0.4, alpha=0.15, zorder=2,
                          gid="orbit-draw")
            median = _closed(np.median(draws, axis=0))
            ax_i.plot(median[:, 0], median[:, 1], color=colour, lw=1.8, zorder=3,
                      gid="orbit-median")
        else:
            ax_i.text(0.5, 0.5, "no predicted orbit", transform=ax_i.transAxes, ha="center",
                      va="center", fontsize=LEGEND_SIZE, color=colour)

        if truth is not None:
            true = np.asarray(truth(rec.mu, rec.branch), float)
            if true.ndim == 2 and np.isfinite(true).all():
                true = _closed((true - centre) * factor)
                ax_i.plot(true[:, 0], true[:, 1], color="k", lw=0.7, ls="--", zorder=4,
                          gid="truth")

        unit = f" {mu_units}" if mu_units else ""
        ax_i.set_title(f"{mu_symbol} = {_format_mu(rec.mu)}{unit}, {rec.branch}",
                       fontsize=TITLE_SIZE)
        if not own or i + ncols >= n:  # no panel below: label the x axis
            ax_i.set_xlabel(channel_label(names[0], shown_units[0], removed),
                            fontsize=LABEL_SIZE)
        if not own or col == 0:
            ax_i.set_ylabel(channel_label(names[1], shown_units[1], removed),
                            fontsize=LABEL_SIZE)
        ax_i.locator_params(nbins=4)

    colours = [BRANCH_COLOURS[b] for b in ("stable", "unstable") if b in branches]
    handles = [
        Line2D([], [], color=MEASURED_GREY, lw=0.8),
        tuple(Line2D([], [], color=c, lw=0.6, alpha=0.4) for c in colours),
        tuple(Line2D([], [], color=c, lw=1.8) for c in colours),
    ]
    labels = ["measured" + (" (Δ: its mean removed)" if removed else ""),
              f"posterior orbit draws ({n_orbits})", "pointwise posterior median"]
    if truth is not None:
        handles.append(Line2D([], [], color="k", lw=0.7, ls="--"))
        labels.append("true")
    where = dict(loc="outside lower center", ncol=len(handles)) if own else dict(loc="best")
    (fig if own else axes[0]).legend(
        handles, labels, fontsize=LEGEND_SIZE, frameon=False, handlelength=3.0,
        handler_map={tuple: HandlerTuple(ndivide=None, pad=0.3)}, **where)
    return fig
