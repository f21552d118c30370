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
    style_axes,
)

#: Callable giving the true orbit, ``truth(mu, branch) -> points (n, 2)``.
OrbitTruth = Callable[[float, str], np.ndarray]

#: Most panels per row of the grid.
MAX_COLUMNS = 4


def _closed(points: np.ndarray) -> np.ndarray:
    """The orbit with its first point appended (a closed curve)."""
    return np.concatenate([points, points[..., :1, :]], axis=-2)


def _subsample(points: np.ndarray, max_points: int) -> np.ndarray:
    """Every k-th sample so that at most ``max_points`` remain (whole record kept)."""
    step = max(1, math.ceil(len(points) / max(int(max_points), 1)))
    return points[::step]


def _pick(n: int, k: int) -> np.ndarray:
    """``k`` indices spread evenly over ``range(n)`` (deterministic)."""
    if k >= n:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max(k, 1)).round().astype(int))


def _format_mu(mu: float) -> str:
    return f"{mu:.4g}"


def plot_phase_portraits(
    fit,
    recordings: RecordingSet,
    *,
    n_orbits: int = 60,
    max_points: int = 4000,
    truth: OrbitTruth | None = None,
    mu_symbol: str = "μ",
) -> Figure:
    """Plot each recording's measured orbit over the posterior predicted orbits.

    One panel per recording (in the set's order), titled with its μ and branch.
    The measured (z1, z2) trajectory is a thin grey line; ``n_orbits`` posterior
    orbit draws at the recording's μ and branch are thin translucent lines in
    the branch colour, and their pointwise median (over all draws in which the
    orbit exists) is a bold line.

    Args:
        fit: A :class:`~bayeshopf.posterior.HybridPosterior`, or anything with
            ``orbits(mu, branch) -> draws (n, n_phi, 2)`` in physical units.
        recordings: The recordings to show (normally the training set).
        n_orbits: Posterior orbit draws drawn per panel.
        max_points: Most measured samples drawn per panel (the record is
            subsampled evenly).
        truth: Optional ``truth(mu, branch) -> points (n, 2)``, drawn as a thin
            black dashed closed curve.
        mu_symbol: Symbol of μ in the panel titles.

    Returns:
        The figure, one axes per recording.
    """
    recs = list(recordings)
    n = len(recs)
    ncols = min(MAX_COLUMNS, n)
    nrows = math.ceil(n / ncols)
    fig = new_figure(1.9 * ncols + 0.4, 1.85 * nrows + 0.55)
    grid = fig.add_gridspec(nrows, ncols)
    names, units = recordings.planar, recordings.units
    mu_units = recordings.mu_units

    branches = {rec.branch for rec in recs}
    for i, rec in enumerate(recs):
        row, col = divmod(i, ncols)
        ax = fig.add_subplot(grid[row, col])
        style_axes(ax)
        ax.minorticks_off()
        colour = BRANCH_COLOURS[rec.branch]

        measured = _subsample(np.asarray(rec.planar(recordings.planar), float), max_points)
        ax.plot(measured[:, 0], measured[:, 1], color=MEASURED_GREY, lw=0.5, alpha=0.8, zorder=1,
                gid="measured")

        draws = np.asarray(fit.orbits(rec.mu, rec.branch), float)
        exists = np.all(np.isfinite(draws), axis=(1, 2))
        draws = draws[exists]
        if draws.shape[0]:
            shown = _closed(draws[_pick(draws.shape[0], n_orbits)])
            for orbit in shown:
                ax.plot(orbit[:, 0], orbit[:, 1], color=colour, lw=0.4, alpha=0.15, zorder=2,
                        gid="orbit-draw")
            median = _closed(np.median(draws, axis=0))
            ax.plot(median[:, 0], median[:, 1], color=colour, lw=1.8, zorder=3,
                    gid="orbit-median")
        else:
            ax.text(0.5, 0.5, "no predicted orbit", transform=ax.transAxes, ha="center",
                    va="center", fontsize=LEGEND_SIZE, color=colour)

        if truth is not None:
            true = np.asarray(truth(rec.mu, rec.branch), float)
            if true.ndim == 2 and np.isfinite(true).all():
                true = _closed(true)
                ax.plot(true[:, 0], true[:, 1], color="k", lw=0.7, ls="--", zorder=4,
                        gid="truth")

        unit = f" {mu_units}" if mu_units else ""
        ax.set_title(f"{mu_symbol} = {_format_mu(rec.mu)}{unit}, {rec.branch}",
                     fontsize=TITLE_SIZE)
        if i + ncols >= n:  # no panel below: label the x axis
            ax.set_xlabel(axis_label(names[0], units[0]), fontsize=LABEL_SIZE)
        if col == 0:
            ax.set_ylabel(axis_label(names[1], units[1]), fontsize=LABEL_SIZE)
        ax.locator_params(nbins=4)

    colours = [BRANCH_COLOURS[b] for b in ("stable", "unstable") if b in branches]
    handles = [
        Line2D([], [], color=MEASURED_GREY, lw=0.8),
        tuple(Line2D([], [], color=c, lw=0.6, alpha=0.4) for c in colours),
        tuple(Line2D([], [], color=c, lw=1.8) for c in colours),
    ]
    labels = ["measured", f"posterior orbit draws ({n_orbits})", "pointwise posterior median"]
    if truth is not None:
        handles.append(Line2D([], [], color="k", lw=0.7, ls="--"))
        labels.append("true")
    fig.legend(handles, labels, loc="outside lower center", ncol=len(handles),
               fontsize=LEGEND_SIZE, frameon=False, handlelength=3.0,
               handler_map={tuple: HandlerTuple(ndivide=None, pad=0.3)})
    return fig
