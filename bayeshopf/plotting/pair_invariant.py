"""The map-free pair invariant against μ: the normal form's line, and what two pairs predict."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from bayeshopf.diagnostics.pair_invariant import (
    PairInvariant,
    invariant_line,
    leave_one_pair_out,
)
from bayeshopf.diagnostics.summaries import CI
from bayeshopf.model.collapsed import unfolding
from bayeshopf.plotting._style import (
    BRANCH_COLOURS,
    LABEL_SIZE,
    LEGEND_SIZE,
    axis_label,
    new_figure,
    panels,
    style_axes,
)

_Q = [(1 - CI) / 2, 0.5, (1 + CI) / 2]
#: Colours of the leave-one-pair-out lines (clear of the branch colours C0, C3).
_HELD_COLOURS = ("C2", "C4", "C1", "C5", "C6", "C8", "C9")


def plot_pair_invariant(pairs: list[PairInvariant], *, fit=None, mu_label: str = "airspeed",
                        mu_units: str = "m/s", ax=None) -> Figure:
    """``x = (A_s A_u)²/(A_s² + A_u²)²`` of each pair, with the lines the normal form allows.

    Draws the measured ``x`` with 90% intervals (per-segment spreads), the
    least-squares line ``x = (μ0 − μ)/a2²`` through all pairs with its 90%
    band, and, for each pair, the line through the others (dashed) with its
    prediction at that pair's μ (open marker, 90% interval). With ``fit``, the
    hybrid fit's own curve ``x = −β(μ)/a2²`` from its posterior draws is drawn
    too: ``β(μ) = μ − μ0`` (a straight line) for the linear unfolding, and the
    curved unfolding :func:`~bayeshopf.model.collapsed.unfolding` of a
    :class:`~bayeshopf.posterior.HybridPosterior` fitted with it (draws of ``w``).
    ``x`` is 1/4 at the fold and 0 at the Hopf point.

    Args:
        pairs: From :func:`~bayeshopf.diagnostics.pair_invariant.pair_invariants`
            (two or more at distinct μ).
        fit: Optional subcritical fit with posterior ``samples`` of ``mu0`` and
            ``a2`` (and ``w_unfold``, ``mu_fold`` for the curved unfolding), e.g. a
            :class:`~bayeshopf.posterior.HybridPosterior`.
        mu_label: Name of μ (axis label).
        mu_units: Unit of μ.
        ax: Axes to draw into; a new figure when ``None``.

    Returns:
        The figure.
    """
    line = invariant_line(pairs)
    mu = np.array([p.mu for p in pairs])
    lo_mu = min(mu.min(), line.mu_fold) - 0.1 * np.ptp(mu)
    hi_mu = max(mu.max(), line.mu0) + 0.1 * np.ptp(mu)
    grid = np.linspace(lo_mu, hi_mu, 200)
    def make():
        f = new_figure(5.2, 3.6)
        return f, [f.add_subplot()]

    fig, (ax,) = panels(ax, 1, make)
    style_axes(ax)
    band = np.quantile(line.x_draws(grid), _Q, axis=0)
    ax.fill_between(grid, band[0], band[2], color="0.8", lw=0, label="all pairs: line, 90% band",
                    gid="all-pairs-band")
    ax.plot(grid, line.x_at(grid), color="k", lw=1.2, gid="all-pairs-line")
    if fit is not None:
        s = fit.samples
        mu0, a2 = np.asarray(s["mu0"])[:, None], np.asarray(s["a2"])[:, None]
        if "w_unfold" in s:
            beta = np.asarray(unfolding(grid, mu0, np.asarray(s["w_unfold"])[:, None],
                                        np.asarray(s["mu_fold"])[:, None]))
            label = "hybrid fit: −β(μ)/a2² (curved)"
        else:
            beta, label = grid - mu0, "hybrid fit: (μ0 − μ)/a2²"
        q = np.quantile(-beta / a2**2, _Q, axis=0)
        ax.plot(grid, q[1], color=BRANCH_COLOURS["stable"], lw=1.0, label=label, gid="fit-line")
        ax.fill_between(grid, q[0], q[2], color=BRANCH_COLOURS["stable"], alpha=0.2, lw=0,
                        gid="fit-band")
    for k, (held, other) in enumerate(leave_one_pair_out(pairs)):
        ax.plot(grid, other.x_at(grid), color=_HELD_COLOURS[k % 7], lw=0.9, ls="--",
                label=f"without {held.mu:g} {mu_units}".rstrip(), gid=f"without-{k}")
        pred = np.quantile(other.x_draws(held.mu), _Q)
        ax.errorbar(held.mu + 0.012 * np.ptp(grid), pred[1], yerr=[[pred[1] - pred[0]],
                    [pred[2] - pred[1]]], fmt="o", mfc="white", color=_HELD_COLOURS[k % 7], ms=5,
                    capsize=2, lw=0.9, gid=f"predicted-{k}")
    x = np.array([p.x for p in pairs])
    iv = np.array([[p.interval.lo, p.interval.hi] for p in pairs])
    ax.errorbar(mu, x, yerr=[x - iv[:, 0], iv[:, 1] - x], fmt="s",
                color=BRANCH_COLOURS["unstable"], ms=5, capsize=2, lw=1.0, zorder=5,
                label="measured pairs, 90%", gid="measured")
    ax.axhline(0.25, color="0.5", lw=0.6, ls=":")
    ax.axhline(0.0, color="0.5", lw=0.6, ls=":")
    for y, name in ((0.25, "fold"), (0.0, "Hopf")):  # beside the axes, clear of the lines
        ax.text(1.01, y, name, transform=ax.get_yaxis_transform(), va="center", ha="left",
                fontsize=LEGEND_SIZE, color="0.4")
    ax.set_xlim(grid[0], grid[-1])
    ax.set_ylim(-0.02, 0.31)
    ax.set_xlabel(axis_label(mu_label, mu_units), fontsize=LABEL_SIZE)
    ax.set_ylabel(r"$x = (A_s A_u)^2 / (A_s^2 + A_u^2)^2$", fontsize=LABEL_SIZE)
    ax.legend(fontsize=LEGEND_SIZE, frameon=False, loc="lower left")
    return fig
