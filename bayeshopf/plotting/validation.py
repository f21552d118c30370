"""The leave-one-out figure (the paper's Fig. exp_val), with bands, on the collapsed core."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from bayeshopf.errors import DataError
from bayeshopf.plotting import _style
from bayeshopf.plotting._units import convert, scale_diagram
from bayeshopf.plotting.diagram import _draw_band
from bayeshopf.validation import plug_in_amplitude

#: Colour and line style of the MAP plug-in curve.
POINT_COLOUR = "#555555"
POINT_STYLE = ":"


def plot_leave_one_out(loo, features, *, mu_grid=None, mu_label: str = "airspeed",
                       mu_units: str = "m/s", amplitude_units: str = "m",
                       n_cols: int = 4, ax=None, length_unit: str | None = None) -> Figure:
    """One panel per held-out recording, and a last panel with the fold per fold.

    Each panel shows the Bayesian fit without that recording (median, 50% and
    90% bands of both branches, dotted 90% band of a new recording), the MAP
    plug-in curve, the training recordings and the held-out one (a star;
    filled where it lies inside the Bayesian 90% band). The last panel shows
    μ_SN of every fold: Bayesian median with its 90% interval, and the MAP's.

    Args:
        loo: A :class:`~bayeshopf.validation.LeaveOneOut` made with ``keep_fits=True``.
        features: Features of all recordings (``mu``, ``unstable``, ``amplitude``,
            ``names``; :class:`~bayeshopf.features.harmonics.HarmonicFeatures`).
        mu_grid: μ grid of the curves (default: the data's range widened).
        mu_label: Name of μ (axis label).
        mu_units: Unit of μ.
        amplitude_units: Unit of the amplitude.
        n_cols: Panels per row.
        ax: Axes to draw into, one per fold and one for the folds' fold points
            (a sequence or array; extra ones hidden; the legend then goes on the
            first); a new figure when ``None``.
        length_unit: Draw the amplitudes in this length unit (``"mm"``, …) when
            ``amplitude_units`` is a length (as :func:`~bayeshopf.plotting.plot_diagram`).

    Returns:
        The figure.

    Raises:
        DataError: If the folds' fits were not kept.
    """
    if any(f.fit is None for f in loo.folds):
        raise DataError("plot_leave_one_out needs the folds' fits; got a LeaveOneOut made "
                        "without keep_fits=True")
    mu_all = np.asarray(features.mu, float)
    if mu_grid is None:
        span = mu_all.max() - mu_all.min()
        mu_grid = np.linspace(mu_all.min() - 0.3 * span, mu_all.max() + 0.45 * span, 160)
    n_panels = len(loo.folds) + 1
    n_rows = int(np.ceil(n_panels / n_cols))

    def make():
        f = _style.new_figure(3.1 * n_cols, 2.7 * n_rows)
        return f, f.subplots(n_rows, n_cols, squeeze=False).ravel()

    own = ax is None
    fig, axes = _style.panels(ax, n_panels, make)
    names = list(features.names)
    factor, amplitude_units = convert(amplitude_units, length_unit)
    amplitude = factor * np.asarray(features.amplitude, float)
    y_max = 1.25 * float(np.nanmax(amplitude))
    for ax, fold in zip(axes, loo.folds, strict=False):
        _style.style_axes(ax)
        post = fold.fit
        branches = ("stable", "unstable") if post.criticality == "subcritical" else ("stable",)
        if "bayes" in loo.methods:
            diag = scale_diagram(post.diagram(mu_grid), factor)
            for branch, band in (("stable", diag.stable), ("unstable", diag.unstable)):
                if band is not None:
                    _draw_band(ax, branch, band, 0.5)
        if "map" in loo.methods:
            for branch in branches:
                ax.plot(mu_grid, factor * plug_in_amplitude(post, mu_grid, branch),
                        color=POINT_COLOUR, ls=POINT_STYLE, lw=1.1, gid=f"map-{branch}")
        keep = np.array([n != fold.name for n in names])
        for branch, mask in (("stable", ~features.unstable), ("unstable", features.unstable)):
            sel = keep & mask
            ax.plot(mu_all[sel], amplitude[sel], ls="none", marker=_style.BRANCH_MARKERS[branch],
                    ms=4.5, mfc=_style.marker_face(branch), mec=_style.BRANCH_COLOURS[branch],
                    mew=1.0, zorder=5)
        inside = fold.inside("bayes") if "bayes" in fold.predictions else False
        ax.plot([fold.mu], [factor * fold.measured], ls="none", marker="*", ms=13, mec="k", mew=1.0,
                mfc="gold" if inside else "white", zorder=6)
        ax.set_title(f"without {fold.mu:g} {mu_units} ({fold.branch})",
                     fontsize=_style.LABEL_SIZE - 1)
        ax.set_xlim(mu_grid[0], mu_grid[-1])
        ax.set_ylim(0, y_max)
        ax.tick_params(labelsize=_style.TICK_SIZE - 1)
    for ax in axes[: len(loo.folds)]:
        ax.set_xlabel(_style.axis_label(mu_label, mu_units), fontsize=_style.LABEL_SIZE - 1)
        ax.set_ylabel(_style.axis_label("amplitude", amplitude_units),
                      fontsize=_style.LABEL_SIZE - 1)
    ax = axes[len(loo.folds)]
    _style.style_axes(ax)
    x = np.arange(len(loo.folds))
    if "bayes" in loo.methods:
        fm = np.array([f.predictions["bayes"].mu_fold for f in loo.folds])
        ax.errorbar(x, fm[:, 0], yerr=[fm[:, 0] - fm[:, 1], fm[:, 2] - fm[:, 0]], fmt="o",
                    color=_style.BRANCH_COLOURS["stable"], capsize=3, ms=4, label="Bayesian, 90%")
    if "map" in loo.methods:
        v = [f.predictions["map"].mu_fold[0] for f in loo.folds]
        ax.plot(x + 0.15, v, ls="none", marker="s", color=POINT_COLOUR, ms=5, label="MAP")
    ax.set_xticks(x, [f"{f.mu:g}{f.branch[0]}" for f in loo.folds], fontsize=_style.TICK_SIZE - 2,
                  rotation=45)
    ax.set_xlim(-0.5, len(loo.folds) - 0.2)
    ax.margins(y=0.1)            # an interval's end on the axis would lose its cap
    ax.set_xlabel("held-out recording (s: stable, u: unstable)", fontsize=_style.LABEL_SIZE - 2)
    ax.set_ylabel(_style.axis_label("fold μ_SN", mu_units), fontsize=_style.LABEL_SIZE - 1)
    ax.set_title("fold per fold", fontsize=_style.LABEL_SIZE - 1)
    ax.legend(fontsize=_style.LEGEND_SIZE - 2, loc="best")
    for ax in axes[n_panels:]:
        ax.set_visible(False)
    handles = [
        Patch(color=_style.BRANCH_COLOURS["stable"], alpha=0.35, label="Bayesian stable (50/90%)"),
        Patch(color=_style.BRANCH_COLOURS["unstable"], alpha=0.35,
              label="Bayesian unstable (50/90%)"),
        Line2D([], [], color="k", ls=":", lw=0.8, label="90% band of a new recording"),
        *([Line2D([], [], color=POINT_COLOUR, ls=POINT_STYLE, label="MAP plug-in")]
          if "map" in loo.methods else []),      # drawn only where the folds have it
        Line2D([], [], ls="none", marker="*", ms=11, mfc="gold", mec="k",
               label="held out (filled: inside 90%)"),
    ]
    if own:
        fig.legend(handles=handles, loc="outside lower center", ncol=3,
                   fontsize=_style.LEGEND_SIZE - 1, frameon=False)
    else:
        axes[0].legend(handles=handles, loc="upper left", fontsize=_style.LEGEND_SIZE - 2)
    return fig
