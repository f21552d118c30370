"""A fit of a simulated experiment drawn over the simulator's truth.

:func:`plot_diagram_vs_truth` is :func:`~bayeshopf.plotting.diagram.plot_bifurcation`
with the true branches of the continuation (thin black lines) and the held-out
orbits (black crosses at their true amplitude); the phase portraits take the
true orbit through ``truth.orbit``. Pure functions: new figures, no pyplot state.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from bayeshopf.plotting._style import LEGEND_SIZE
from bayeshopf.plotting.diagram import plot_bifurcation


def plot_diagram_vs_truth(
    fit,
    truth,
    held_out: list[dict] | None = None,
    *,
    mu: np.ndarray | None = None,
    zoom: bool = True,
    title: str | None = None,
    ax=None,
    **kwargs,
) -> Figure:
    """The posterior bifurcation diagram over the true one, with held-out orbits.

    Args:
        fit: A :class:`~bayeshopf.posterior.HybridPosterior` of a simulated
            experiment (it needs ``diagram``, ``ppc``, ``interval``,
            ``default_mu_grid``, ``features``, ``spec`` and the unit labels).
        truth: Its :class:`~bayeshopf.simulators.truth.SimulatedTruth` (or any
            object with ``amplitude(mu, branch)``).
        held_out: Rows of :func:`~bayeshopf.simulators.truth.held_out_check`;
            their true amplitudes are drawn as black crosses.
        mu: μ grid (default :func:`~bayeshopf.plotting.diagram_grid`).
        zoom: Add the inset about the stable recording of largest μ.
        title: Axes title.
        ax: Axes to draw into; a new figure when ``None``.
        **kwargs: More options of :func:`~bayeshopf.plotting.diagram.plot_bifurcation`
            (``length_unit``, ``p_exists``, ``bars``, …).

    Returns:
        The figure.
    """
    from bayeshopf.plotting import default_zoom, diagram_grid

    mu = diagram_grid(fit) if mu is None else np.asarray(mu, float)
    fig = plot_bifurcation(
        fit.diagram(mu), fit.ppc(), mu_label=fit.mu_label, mu_units=fit.mu_units,
        amplitude_units=fit.amplitude_units,
        amplitude_label=f"peak-to-peak of {fit.spec.frame.names[0]}",
        truth=truth.amplitude, zoom=default_zoom(fit, mu) if zoom else None, ax=ax, **kwargs,
    )
    ax = ax if ax is not None else _diagram_axes(fig)
    if held_out:
        x = [r["mu"] for r in held_out]
        y = [r["true"] for r in held_out]
        from bayeshopf.plotting._units import convert

        factor = convert(fit.amplitude_units, kwargs.get("length_unit"))[0]
        ax.plot(x, np.asarray(y, float) * factor, ls="none", marker="x", ms=6, mew=1.3,
                color="k", zorder=8, gid="held-out")
        n_in = sum(r["inside"] for r in held_out)
        main = ax.get_legend()  # plot_bifurcation's legend below the axes: keep it
        if main is not None:
            ax.add_artist(main)
        ax.legend([Line2D([], [], ls="none", marker="x", ms=6, mew=1.3, color="k")],
                  [f"held-out true orbits ({n_in}/{len(held_out)} inside 90% predictive)"],
                  loc="upper left", fontsize=LEGEND_SIZE, frameon=True, framealpha=0.9,
                  edgecolor="0.8")
    if title:
        ax.set_title(title, fontsize=LEGEND_SIZE + 1.5)
    return fig


def _diagram_axes(fig: Figure):
    """The diagram's axes of a figure made by ``plot_bifurcation`` (not the P(exists) panel)."""
    for a in fig.axes:
        if any(line.get_gid() == "stable-median" for line in a.lines):
            return a
    return fig.axes[0]
