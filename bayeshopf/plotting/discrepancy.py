"""Figures of a discrepancy analysis: bifurcation diagram before and after, orbit residuals."""

from __future__ import annotations

import os
import textwrap
from pathlib import Path

import numpy as np

from bayeshopf.plotting._io import save_figure
from bayeshopf.plotting._style import (
    BRANCH_COLOURS,
    BRANCH_MARKERS,
    LABEL_SIZE,
    LEGEND_SIZE,
    TITLE_SIZE,
    new_figure,
    panels,
    style_axes,
)

__all__ = ["diagram_title", "plot_discrepancy", "plot_discrepancy_diagram", "plot_orbit_residuals"]


def _branch_curves(diagram, channel: str):
    for b in diagram.branches:
        yield b.kind, np.asarray(b.mu), np.asarray(b.amplitude[channel])


def plot_discrepancy_diagram(report, ax=None):
    """Peak-to-peak of the reference channel against μ: simulator, final model, recordings.

    The final model is the simulator with the most probable term or, after a
    calibration of its uncertain parameters, the calibrated simulator (with the
    term when one is missing; the calibrated simulator without it is then drawn
    too). The recordings' amplitudes are the measured ones (offsets do not
    change a peak-to-peak); the Bayesian hybrid fit's 90% band is drawn when the
    analysis ran it. ``ax``: the axes to draw into (a new figure when ``None``).
    """
    mf = report.extras["features"]
    ch = mf.layout.channels[0]
    system = report.system

    def make():
        f = new_figure(6.0, 4.0)
        return f, [f.add_subplot()]

    fig, (ax,) = panels(ax, 1, make)
    before, after = report.extras["before"], report.extras["after"]
    hyb = report.extras.get("hybrid")
    if hyb is not None:
        try:
            bd = hyb.diagram()
            for band, kind in ((bd.stable, "stable"), (bd.unstable, "unstable")):
                if band is None:
                    continue
                ax.fill_between(band.mu, band.quantiles[0], band.quantiles[-1], color="0.85",
                                lw=0, label="hybrid fit, 90% band" if kind == "stable" else None)
        except Exception:  # noqa: BLE001 - the band is an extra; the figure stands without it
            pass
    ex = report.extras
    b_label = ex.get("before_label", "simulator")
    for kind, mu, amp in _branch_curves(before["diagram"], ch):
        ax.plot(mu, amp, color="0.2", ls="-" if kind == "stable" else "--", lw=1.2,
                label=f"{b_label} (stable, unstable dashed)" if kind == "stable" else None)
    mid = ex.get("intermediate")
    if mid is not None and mid.get("diagram") is not None:
        for kind, mu, amp in _branch_curves(mid["diagram"], ch):
            ax.plot(mu, amp, color="C0", ls="-" if kind == "stable" else "--", lw=1.0,
                    alpha=0.8, label=mid["label"] if kind == "stable" else None)
    a_label = ex.get("after_label") or f"simulator + {report.data['fit']['after']['term']}"
    if after.get("diagram") is not None:
        for kind, mu, amp in _branch_curves(after["diagram"], ch):
            ax.plot(mu, amp, color="C2", ls="-" if kind == "stable" else "--", lw=1.5,
                    label=a_label if kind == "stable" else None)
    for b in ("stable", "unstable"):
        sel = np.array([x == b for x in mf.branch])
        if sel.any():
            ax.plot(mf.mu[sel], 2 * mf.amplitude[sel, 0], BRANCH_MARKERS[b], ms=6,
                    mfc=BRANCH_COLOURS[b] if b == "stable" else "none",
                    mec=BRANCH_COLOURS[b], label=f"recordings ({b})", ls="none")
    u = system.parameter_units
    ax.set_xlabel(f"{system.parameter_label} {system.parameter}" + (f" ({u})" if u else ""),
                  fontsize=LABEL_SIZE)
    cu = system.observed_units.get(ch, "")
    ax.set_ylabel(f"{ch} peak-to-peak" + (f" ({cu})" if cu else ""), fontsize=LABEL_SIZE)
    ax.set_title(diagram_title(report.data["verdict"]), fontsize=TITLE_SIZE)
    lo = min([mf.mu.min()] + [p["fold"] for p in (before, after) if p.get("fold")]) - 0.5
    hi = max([mf.mu.max()] + [p["hopf"] for p in (before, after) if p.get("hopf")]) + 0.5
    ax.set_xlim(lo, hi)
    ax.set_ylim(0, 1.3 * 2 * mf.amplitude[:, 0].max())
    style_axes(ax)
    # below the axes: inside, the key covered the largest recorded orbit on the rig
    ax.legend(fontsize=LEGEND_SIZE, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2,
              frameon=False)
    return fig


def diagram_title(verdict: dict, width: int = 70) -> str:
    """The verdict in a title: its kind and terms, then the parameters named off.

    Lines are wrapped at ``width`` characters, e.g. ``"term missing:
    quadratic damping in heave + cubic damping in heave"`` over ``"7 parameters
    off: k_h, k_alpha, …"``.
    """
    from bayeshopf.discrepancy.terms import plain_name

    terms = " + ".join(plain_name(t) for t in verdict.get("terms") or [])
    params = list(verdict.get("parameters") or [])
    head = verdict["kind"] + (f": {terms}" if terms else "")
    lines = [head]
    if params:
        n = len(params)
        lines.append(f"{n} parameter{'s' if n > 1 else ''} off: " + ", ".join(params))
    elif not terms:
        lines[0] += ": no term named" if verdict["kind"] != "none" else ""
    return "\n".join(textwrap.fill(x, width) for x in lines)


def plot_orbit_residuals(report, ax=None):
    """Residual along the orbit (measured − simulated, offsets removed), before and after.

    "After" is the final model of the analysis (``extras["after_orbits"]``: the
    simulator with the most probable term, or the calibrated simulator, with
    the term when one is missing; the calibrated simulator without the term is
    then drawn too); older reports without it use the best term.

    One row per recording, one column per channel; the residual is in units of
    the channel and the grey band is ± the model-error floor plus noise of the
    first harmonic. ``ax``: the axes to draw into, rows × columns (an array of
    that shape or a flat sequence in row order; the legend then goes on the
    first), or ``None`` for a new figure.
    """
    from bayeshopf.discrepancy.locate import N_THETA, curve

    mf = report.extras["features"]
    fitter = report.extras["fitter"]
    lay = mf.layout
    base = report.extras["base"]
    after = report.extras.get("after_orbits")
    label = report.extras.get("after_label")
    if after is None:
        after, label = report.fits[0].orbits, f"+ {report.fits[0].term.plain}"
    ys0 = fitter.features(base)
    ys1 = fitter.features(after)
    off0, off1 = fitter.offsets(base), fitter.offsets(after)
    mid = report.extras.get("intermediate") or {}
    mid_ob = mid.get("orbits")
    if mid_ob is not None:
        ysm, offm = fitter.features(mid_ob), fitter.offsets(mid_ob)
    b_label = report.extras.get("before_label", "simulator")
    R, C = len(mf.names), len(lay.channels)

    def make():
        f = new_figure(2.6 * C + 0.5, 1.05 * R + 0.6)
        return f, f.subplots(R, C, sharex=True, squeeze=False)

    own = ax is None
    fig, flat = panels(ax, R * C, make)
    axes = np.asarray(flat[: R * C], dtype=object).reshape(R, C)
    th = 360.0 * np.arange(N_THETA) / N_THETA
    for r in range(R):
        for j, c in enumerate(lay.channels):
            ax = axes[r, j]
            zm = curve(lay, mf.y[r], c)
            s = fitter.sigma[r, lay.labels.index(f"{c}:Re1")]
            ax.axhspan(-2 * s, 2 * s, color="0.88", lw=0)
            if base.ok[r]:
                ax.plot(th, zm - off0[c] - curve(lay, ys0[r], c), color="0.3", lw=1,
                        label=b_label)
            if mid_ob is not None and mid_ob.ok[r]:
                ax.plot(th, zm - offm[c] - curve(lay, ysm[r], c), color="C0", lw=0.9,
                        label=mid["label"])
            if after.ok[r]:
                ax.plot(th, zm - off1[c] - curve(lay, ys1[r], c), color="C2", lw=1.2,
                        label=label)
            if not base.ok[r] and not after.ok[r]:
                ax.text(0.5, 0.5, "no LCO of the simulator here", transform=ax.transAxes,
                        ha="center", va="center", fontsize=LEGEND_SIZE)
                ax.set_yticks([])
            ax.axhline(0, color="0.6", lw=0.5)
            style_axes(ax, grid=False, minor=False)
            if r == 0:
                u = report.system.observed_units.get(c, "")
                ax.set_title(f"{c} residual" + (f" ({u})" if u else ""), fontsize=TITLE_SIZE)
            if j == 0:
                ax.set_ylabel(f"{mf.branch[r][0]} {mf.mu[r]:g}", fontsize=LABEL_SIZE - 1)
            ax.tick_params(labelsize=6.5)
    for ax in axes[-1]:
        ax.set_xlabel("phase (°)", fontsize=LABEL_SIZE)
        ax.set_xticks([0, 90, 180, 270, 360])
    handles, labels = [], []
    for ax in axes.ravel():
        for h_, l_ in zip(*ax.get_legend_handles_labels(), strict=True):
            if l_ not in labels:
                handles.append(h_)
                labels.append(l_)
    if own:
        fig.legend(handles, labels, fontsize=LEGEND_SIZE, loc="outside upper center",
                   ncols=min(len(labels), 3))
    else:
        axes[0, 0].legend(handles, labels, fontsize=LEGEND_SIZE)
    return fig


def plot_discrepancy(report, folder: str | os.PathLike[str]) -> list[Path]:
    """Write ``bifurcation_diagram.png`` and ``orbit_residuals.png`` into ``folder``."""
    folder = Path(folder)
    return [save_figure(plot_discrepancy_diagram(report), folder / "bifurcation_diagram.png"),
            save_figure(plot_orbit_residuals(report), folder / "orbit_residuals.png")]
