"""The figure of :func:`bayeshopf.design.next_measurements`: gain against μ over the diagram."""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from bayeshopf.plotting._style import new_figure
from bayeshopf.plotting._units import convert, readable_length
from bayeshopf.plotting.diagram import plot_bifurcation

#: Colours of the branches, as in the diagram.
COLOURS = {"stable": "C0", "unstable": "C3"}
TARGET_TEXT = {"fold": "fold μ_SN", "hopf": "Hopf point μ0", "diagram": "diagram's band"}


def plot_design(result, fit=None, *, axes: tuple[Axes, Axes] | None = None,
                length_unit: str | None = "auto") -> Figure:
    """Expected gain of each candidate against μ, under the diagram with its bands.

    The upper panel is the fit's bifurcation diagram (when ``fit`` is given)
    with the recommended measurements marked at their predicted amplitude
    (numbered by rank, with the predicted band as error bars); the lower panel
    is each branch's expected gain (the current width of the target less its
    expected width after the measurement) with a band of two Monte Carlo
    standard errors, skipped candidates (where the branch may not exist, or its
    orbit is below the minimum amplitude) left out and the recommended ones
    starred; for the fold and the Hopf point a dotted line marks the
    resolution in μ where one was given. The amplitude axis is labelled with
    the fit's channel (``result.amplitude_label``) and units.

    Args:
        result: A :class:`~bayeshopf.design.DesignResult`.
        fit: The fit it was computed from (:class:`~bayeshopf.posterior.HybridPosterior`);
            without it only the gain panel is drawn.
        axes: ``(diagram_ax, gain_ax)`` to draw into (``diagram_ax`` may be ``None``).
        length_unit: Amplitude unit (``"mm"`` …), ``"auto"`` for a readable one,
            or ``None`` to keep the fit's.

    Returns:
        The figure holding the axes.
    """
    units = result.amplitude_units
    if length_unit == "auto":
        amps = [c.amplitude[2] for c in result.candidates if np.isfinite(c.amplitude[2])]
        length_unit = readable_length(units, max(amps)) if amps else None
    factor, shown_units = convert(units, length_unit)
    if axes is None:
        if fit is None:
            fig = new_figure(6.4, 3.0)
            ax_d, ax_g = None, fig.add_subplot()
        else:
            fig = new_figure(6.4, 7.0)
            grid = fig.add_gridspec(2, 1, height_ratios=(3, 2), hspace=0.08)
            ax_d = fig.add_subplot(grid[0])
            ax_g = fig.add_subplot(grid[1], sharex=ax_d)
    else:
        ax_d, ax_g = axes
        fig = ax_g.figure
    mu_unit = f" [{result.mu_units}]" if result.mu_units else ""
    if ax_d is not None and fit is not None:
        plot_bifurcation(fit.diagram(ci=result.ci), fit.ppc(ci=result.ci),
                         mu_label=result.mu_label, mu_units=result.mu_units,
                         amplitude_units=units, amplitude_label=result.amplitude_label,
                         ax=ax_d, p_exists=False, legend=False,
                         length_unit=length_unit)
        for rank, c in enumerate(result.recommended, start=1):
            a = np.asarray(c.amplitude) * factor
            ax_d.errorbar([c.mu], [a[0]], yerr=[[a[0] - a[1]], [a[2] - a[0]]], fmt="*",
                          ms=12, color=COLOURS[c.branch], mec="k", zorder=6)
            # beside the star, stable to the right and unstable to the left, so that both
            # branches' labels stay readable where the branches meet near the fold
            right = c.branch == "stable"
            ax_d.annotate(str(rank), (c.mu, a[0]), textcoords="offset points",
                          xytext=(9 if right else -9, 0), ha="left" if right else "right",
                          va="center", fontsize=9, fontweight="bold")
        ax_d.set_xlabel("")
        ax_d.tick_params(labelbottom=False)
        ax_d.set_title(f"next measurement for the {TARGET_TEXT[result.target]} "
                       f"(★ recommended, numbered by rank)", fontsize=10)
    for branch in ("stable", "unstable"):
        rows = [c for c in result.candidates if c.branch == branch]
        if not rows:
            continue
        mu = np.array([c.mu for c in rows])
        gain = np.array([np.nan if c.skipped else c.gain for c in rows])
        se = np.array([np.nan if c.skipped else c.gain_mcse for c in rows])
        if factor != 1.0 and result.target == "diagram":
            gain, se = gain * factor, se * factor
        ax_g.plot(mu, gain, "-" if branch == "stable" else "--", color=COLOURS[branch],
                  marker=".", label=f"{branch} branch")
        ax_g.fill_between(mu, np.maximum(gain - 2 * se, 0.0), gain + 2 * se,
                          color=COLOURS[branch], alpha=0.2, lw=0)
    for c in result.recommended:
        g = c.gain * (factor if result.target == "diagram" else 1.0)
        ax_g.plot([c.mu], [g], "*", ms=12, color=COLOURS[c.branch], mec="k", zorder=5)
    ax_g.axhline(0.0, color="0.6", lw=0.8)
    if result.target != "diagram" and result.resolution > 0:
        ax_g.axhline(result.resolution, color="0.3", lw=0.8, ls=":",
                     label=f"resolution {result.resolution:g} {result.mu_units}".rstrip())
    if result.target == "diagram":
        what = result.amplitude_label + (f" [{shown_units}]" if shown_units else "")
    else:
        what = f"{TARGET_TEXT[result.target]}{mu_unit}"
    ax_g.set_ylabel(f"expected gain in\n{what}\n(width now − after, ±2 MC se)")
    ax_g.set_xlabel(f"{result.mu_label}{mu_unit}")
    ax_g.legend(loc="best", fontsize=8, frameon=False)
    return fig
