"""Phase portraits: measured orbits against the posterior's predicted orbits."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from matplotlib.collections import LineCollection
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

#: Posterior orbit draws shown per panel, by default.
N_ORBITS = 60

#: What is done with each recording's offset (its mean), by default.
OFFSETS = "remove"


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


@dataclass(frozen=True)
class PhasePanel:
    """What one panel of :func:`plot_phase_portraits` shows, already computed (immutable).

    Plain arrays, so that the panels can be drawn in another process
    (:func:`~bayeshopf.plotting.plot_all`'s ``executor``). All in the recording's
    units, with its mean already subtracted where offsets are removed.

    Attributes:
        mu: The recording's μ.
        branch: ``"stable"`` or ``"unstable"``.
        measured: The measured trajectory, ``(n_points, 2)`` (NaN rows at gaps).
        draws: The posterior orbit draws shown, closed, ``(n_shown, N_PHI + 1, 2)``
            (none where no draw has an orbit at this μ and branch).
        median: Their pointwise median over every draw with an orbit, closed,
            or ``None``.
        true: The true orbit, closed, or ``None``.
    """

    mu: float
    branch: str
    measured: np.ndarray
    draws: np.ndarray
    median: np.ndarray | None
    true: np.ndarray | None


def phase_panels(
    fit,
    recordings: RecordingSet,
    *,
    n_orbits: int = N_ORBITS,
    max_points: int = 4000,
    truth: OrbitTruth | None = None,
    offsets: str = OFFSETS,
) -> list[PhasePanel]:
    """The panels of :func:`plot_phase_portraits`, one per recording, as plain arrays.

    Args:
        fit: A :class:`~bayeshopf.posterior.HybridPosterior`, or anything with
            ``orbits(mu, branch) -> draws (n, n_phi, 2)`` in physical units.
        recordings: The recordings to show (normally the training set).
        n_orbits: Posterior orbit draws shown per panel.
        max_points: Most measured samples per panel (the record is subsampled
            evenly).
        truth: Optional ``truth(mu, branch) -> points (n, 2)``, the true orbit.
        offsets: ``"remove"`` (each recording's mean subtracted) or ``"keep"``.
    """
    check_offsets(offsets)
    # a training recording's orbit as it was held, with its control's response
    names = list(getattr(getattr(fit, "features", None), "names", ()))
    held = {n: fit.recording_control(i) for i, n in enumerate(names)
            if hasattr(fit, "recording_control")}
    out = []
    for rec in recordings:
        z = np.asarray(rec.planar(recordings.planar), float)
        centre = z.mean(axis=0) if offsets == "remove" else np.zeros(2)
        # broken where samples were left out (sensor dropouts), not joined across
        measured = rec.trace(recordings.planar, max_points) - centre
        draws = np.asarray(fit.orbits(rec.mu, rec.branch, control=held.get(rec.name)), float)
        draws = draws[np.all(np.isfinite(draws), axis=(1, 2))] - centre
        shown, median = np.zeros((0, draws.shape[1] + 1, 2)), None
        if draws.shape[0]:
            shown = _closed(draws[_pick(draws.shape[0], n_orbits)])
            median = _closed(np.median(draws, axis=0))
        true = None
        if truth is not None:
            t = np.asarray(truth(rec.mu, rec.branch), float)
            if t.ndim == 2 and np.isfinite(t).all():
                true = _closed(t - centre)
        out.append(PhasePanel(float(rec.mu), rec.branch, measured, shown, median, true))
    return out


def plot_phase_portraits(
    fit,
    recordings: RecordingSet,
    *,
    mu_symbol: str = "μ",
    length_unit: str | None = None,
    angle_unit: str | None = None,
    ax=None,
    **panel_options,
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

    The panels' data are :func:`phase_panels`; :func:`draw_phase_panels` draws
    them.

    Args:
        fit: The fit, as for :func:`phase_panels`.
        recordings: The recordings to show (normally the training set).
        mu_symbol: Name of μ in the panel titles.
        length_unit: Draw channels in a length unit in this one (``"mm"``, …).
        angle_unit: Draw channels in an angle unit in this one (``"deg"``, …).
        ax: Axes to draw into, one per recording (a sequence or array of one
            figure; extra axes are hidden); a new figure when ``None``.
        **panel_options: What the panels show, :func:`phase_panels`' keywords:
            ``n_orbits`` (posterior orbit draws per panel, default 60),
            ``max_points`` (most measured samples per panel, default 4000),
            ``truth`` (``truth(mu, branch) -> points (n, 2)``, drawn as a thin
            black dashed closed curve) and ``offsets`` (``"remove"``, the
            default, or ``"keep"``).

    Returns:
        The figure, one axes per recording (and the legend: the figure's for a
        new figure, the first axes' otherwise).
    """
    data = phase_panels(fit, recordings, **panel_options)
    return draw_phase_panels(data, recordings.planar, recordings.units[:2],
                             mu_units=recordings.mu_units,
                             n_orbits=panel_options.get("n_orbits", N_ORBITS),
                             offsets=panel_options.get("offsets", OFFSETS),
                             mu_symbol=mu_symbol, length_unit=length_unit,
                             angle_unit=angle_unit, ax=ax)


def draw_phase_panels(
    data: list[PhasePanel],
    names: tuple[str, str],
    units: tuple[str, str],
    *,
    mu_units: str = "",
    n_orbits: int = N_ORBITS,
    mu_symbol: str = "μ",
    offsets: str = OFFSETS,
    length_unit: str | None = None,
    angle_unit: str | None = None,
    ax=None,
) -> Figure:
    """Draw :func:`phase_panels`' panels (:func:`plot_phase_portraits`, whose arguments these are).

    Args:
        data: The panels.
        names: The planar channels' names (z1, z2).
        units: Their units.
        mu_units: Unit of μ in the panel titles.
        n_orbits: The number of draws named in the legend.
        mu_symbol: Name of μ in the panel titles.
        offsets: Whether the panels' offsets were ``"remove"``-d (the axis labels).
        length_unit: Draw channels in a length unit in this one (``"mm"``, …).
        angle_unit: Draw channels in an angle unit in this one (``"deg"``, …).
        ax: Axes to draw into, one per panel; a new figure when ``None``.
    """
    check_offsets(offsets)
    n = len(data)
    ncols = min(MAX_COLUMNS, n)
    nrows = math.ceil(n / ncols)

    def make():
        f = new_figure(1.9 * ncols + 0.4, 1.85 * nrows + 0.55)
        grid = f.add_gridspec(nrows, ncols)
        return f, [f.add_subplot(grid[divmod(i, ncols)]) for i in range(n)]

    own = ax is None
    fig, axes = panels(ax, n, make)
    scale = [convert(u, length_unit, angle_unit) for u in units[:2]]
    factor = np.array([scale[0][0], scale[1][0]])
    shown_units = (scale[0][1], scale[1][1])
    removed = offsets == "remove"

    branches = {p.branch for p in data}
    truth = any(p.true is not None for p in data)
    for i, (p, ax_i) in enumerate(zip(data, axes, strict=False)):
        col = i % ncols
        style_axes(ax_i)
        ax_i.minorticks_off()
        colour = BRANCH_COLOURS[p.branch]
        measured = p.measured * factor
        ax_i.plot(measured[:, 0], measured[:, 1], color=MEASURED_GREY, lw=0.5, alpha=0.8,
                  zorder=1, gid="measured")
        if p.median is not None:
            # one collection, not a line per draw: the same picture, a third of the time
            ax_i.add_collection(LineCollection(p.draws * factor, colors=colour, linewidths=0.4,
                                               alpha=0.15, zorder=2, gid="orbit-draws"))
            median = p.median * factor
            ax_i.plot(median[:, 0], median[:, 1], color=colour, lw=1.8, zorder=3,
                      gid="orbit-median")
        else:
            ax_i.text(0.5, 0.5, "no predicted orbit", transform=ax_i.transAxes, ha="center",
                      va="center", fontsize=LEGEND_SIZE, color=colour)
        if p.true is not None:
            true = p.true * factor
            ax_i.plot(true[:, 0], true[:, 1], color="k", lw=0.7, ls="--", zorder=4,
                      gid="truth")

        unit = f" {mu_units}" if mu_units else ""
        ax_i.set_title(f"{mu_symbol} = {_format_mu(p.mu)}{unit}, {p.branch}",
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
    if truth:
        handles.append(Line2D([], [], color="k", lw=0.7, ls="--"))
        labels.append("true")
    where = dict(loc="outside lower center", ncol=len(handles)) if own else dict(loc="best")
    (fig if own else axes[0]).legend(
        handles, labels, fontsize=LEGEND_SIZE, frameon=False, handlelength=3.0,
        handler_map={tuple: HandlerTuple(ndivide=None, pad=0.3)}, **where)
    return fig
