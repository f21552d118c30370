"""Shared look of the bayeshopf figures (applied per axes; no global rcParams)."""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

#: Colour of each branch.
BRANCH_COLOURS = {"stable": "C0", "unstable": "C3"}
#: Marker of each branch's measurements (filled circle, open square).
BRANCH_MARKERS = {"stable": "o", "unstable": "s"}
#: Font sizes (points).
LABEL_SIZE = 9.0
TICK_SIZE = 8.0
LEGEND_SIZE = 7.5
TITLE_SIZE = 9.0
#: Colour of measured data.
MEASURED_GREY = "0.45"


def new_figure(width: float, height: float) -> Figure:
    """A figure that is not registered with pyplot (no global state)."""
    return Figure(figsize=(width, height), layout="constrained")


def style_axes(ax: Axes, grid: bool = True, minor: bool = True) -> None:
    """Ticks inside on all sides, small labels, a light grid behind the data.

    ``minor=False`` leaves out the minor ticks: in a grid of many small panels
    they add little to read and most of the drawing's time.
    """
    ax.tick_params(direction="in", which="both", top=True, right=True, labelsize=TICK_SIZE)
    if minor:
        ax.minorticks_on()
    if grid:
        ax.grid(True, which="major", color="0.9", linewidth=0.6)
        ax.set_axisbelow(True)


def axis_label(name: str, units: str = "") -> str:
    """``"name [units]"``, or just ``name`` when the unit is unknown."""
    return f"{name} [{units}]" if units else name


def tag(container, gid: str) -> None:
    """Set ``gid`` on every artist of a container (e.g. an errorbar's lines)."""
    for artist in container.get_children():
        if artist is not None:
            artist.set_gid(gid)


def marker_face(branch: str) -> str:
    """Face colour of a branch's measurement marker (open for unstable)."""
    return BRANCH_COLOURS[branch] if branch == "stable" else "white"


def panels(ax, n: int, make) -> tuple[Figure, list[Axes]]:
    """The figure and ``n`` axes to draw into.

    Args:
        ax: ``None`` (new axes from ``make()``, which returns ``(figure, axes)``),
            one :class:`~matplotlib.axes.Axes` (for ``n == 1``), or a sequence or
            array of at least ``n`` axes of one figure (any beyond ``n`` are hidden).
        n: Panels needed.
        make: Makes a new figure and its axes.

    Raises:
        ValueError: When ``ax`` holds fewer than ``n`` axes.
    """
    if ax is None:
        fig, axes = make()
        return fig, list(np.ravel(np.asarray(axes, dtype=object)))
    if isinstance(ax, Axes):
        axes = [ax]
    else:
        axes = list(np.ravel(np.asarray(ax, dtype=object)))
    if len(axes) < n or not all(isinstance(a, Axes) for a in axes):
        raise ValueError(f"ax: expected {n} matplotlib Axes (one per panel); got {len(axes)}")
    for a in axes[n:]:
        a.set_visible(False)
    return axes[0].figure, axes


def z_value(ci: float) -> float:
    """Half-width in standard deviations of the central ``ci`` interval of a normal."""
    # norm.ppf is ndtri; importing scipy.stats for it is slow in the figure process
    from scipy.special import ndtri

    return float(ndtri(0.5 + ci / 2))


def ci_label(ci: float) -> str:
    """``"90%"`` for 0.9 (one decimal where needed: ``"97.5%"``)."""
    return f"{100 * ci:.3g}%"
