"""Shared look of the bayeshopf figures (applied per axes; no global rcParams)."""

from __future__ import annotations

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


def style_axes(ax: Axes, grid: bool = True) -> None:
    """Ticks inside on all sides, small labels, a light grid behind the data."""
    ax.tick_params(direction="in", which="both", top=True, right=True, labelsize=TICK_SIZE)
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
