"""The posterior bifurcation diagram: amplitude against μ with credible bands."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerBase, HandlerTuple
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from bayeshopf.diagnostics.bifurcation import BranchBand, DiagramBands
from bayeshopf.diagnostics.ppc import PosteriorPredictiveCheck
from bayeshopf.errors import DataError
from bayeshopf.plotting import _style
from bayeshopf.plotting._units import convert, scale_diagram, scale_ppc

#: Callable giving the true amplitude, ``truth(mu, branch) -> amplitude``.
AmplitudeTruth = Callable[[np.ndarray, str], np.ndarray]

_LINESTYLES = {"stable": "-", "unstable": "--"}
#: Opacity of the 90% and 50% credible bands.
_ALPHA_90, _ALPHA_50 = 0.18, 0.38
_MEDIAN_LW = 2.0
#: Default axis texts when the caller names neither (``fit.plot.bifurcation`` names both).
DEFAULT_MU_LABEL = "bifurcation parameter"
DEFAULT_AMPLITUDE_LABEL = "amplitude (peak-to-peak)"
#: An automatic inset is drawn when the outer band at its centre is thinner than
#: this share of the diagram's height (thinner reads as a line at full scale).
THIN_BAND = 0.05


def gap_colour(colour: str) -> tuple[float, float, float]:
    """The colour seen where both bands of ``colour`` overlap on white.

    The dashed median's gaps take this colour, so that the band looks continuous
    through them and the dotted predictive lines close by do not show in them
    (which made the dashed line read as dash-dot); its legend key is drawn alike.
    """
    a = 1.0 - (1.0 - _ALPHA_90) * (1.0 - _ALPHA_50)
    return tuple(float(a * c + (1.0 - a)) for c in to_rgb(colour))


def _median_style(branch: str) -> dict:
    """Line style of a branch's median, shared by the axes and the legend key."""
    ls = _LINESTYLES[branch]
    out = dict(color=_style.BRANCH_COLOURS[branch], lw=_MEDIAN_LW, ls=ls)
    if ls != "-":
        out["gapcolor"] = gap_colour(_style.BRANCH_COLOURS[branch])
    return out


class _BandKey:
    """Legend key of a branch: 90% band, 50% band and the median line."""

    def __init__(self, branch: str):
        self.branch = branch
        self.colour = _style.BRANCH_COLOURS[branch]
        self.linestyle = _LINESTYLES[branch]


class _BandHandler(HandlerBase):
    """Draws a :class:`_BandKey` as nested rectangles with the median line across."""

    def create_artists(self, legend, orig_handle, xdescent, ydescent, width, height, fontsize,
                       trans):
        """Artists of one legend key (matplotlib's legend handler protocol)."""
        x0, y0 = -xdescent, -ydescent
        c = orig_handle.colour
        outer = Rectangle((x0, y0 - 0.15 * height), width, 1.3 * height, facecolor=c,
                          alpha=_ALPHA_90, lw=0, transform=trans)
        inner = Rectangle((x0, y0 + 0.2 * height), width, 0.6 * height, facecolor=c,
                          alpha=_ALPHA_50, lw=0, transform=trans)
        line = Line2D([x0, x0 + width], [y0 + 0.5 * height] * 2, transform=trans,
                      **_median_style(orig_handle.branch))
        return [outer, inner, line]


def _branches(diagram: DiagramBands) -> list[tuple[str, BranchBand]]:
    out = [("stable", diagram.stable)]
    if diagram.unstable is not None:
        out.append(("unstable", diagram.unstable))
    return out


def _masked(values: np.ndarray, keep: np.ndarray) -> np.ndarray:
    return np.where(keep, values, np.nan)


def _next_to(alive: np.ndarray) -> np.ndarray:
    """Points next to an ``alive`` point (either side)."""
    out = np.zeros_like(alive)
    out[1:] |= alive[:-1]
    out[:-1] |= alive[1:]
    return out


def drawn_quantiles(band: BranchBand, min_p_exists: float = 0.5) -> np.ndarray:
    """The band's quantile rows as drawn, ``(5, n_mu)``, ``nan`` where not drawn.

    Where the branch exists in at least ``min_p_exists`` of the draws, its
    quantiles; a branch that ends at the Hopf point is continued there with
    :attr:`~bayeshopf.diagnostics.bifurcation.BranchBand.to_hopf` (the draws
    past their Hopf point at amplitude 0), each band ending at the first μ
    where its upper edge, and the median where it, reaches 0.
    """
    if band.to_hopf is None or band.p_to_hopf is None:
        keep = np.asarray(band.p_exists) >= min_p_exists
        return _masked(np.asarray(band.quantiles, float), keep)
    h = np.asarray(band.to_hopf, float)
    keep = np.asarray(band.p_to_hopf) >= min_p_exists
    out = np.full_like(h, np.nan)
    for rows, ref in (((0, 4), 4), ((1, 3), 3), ((2,), 2)):
        alive = keep & (h[ref] > 0)
        ends = keep & (h[ref] == 0) & _next_to(alive)
        for r in rows:
            out[r] = np.where(alive | ends, h[r], np.nan)
    return out


def _draw_band(ax: Axes, branch: str, band: BranchBand, min_p_exists: float) -> None:
    colour = _style.BRANCH_COLOURS[branch]
    keep = np.asarray(band.p_exists) >= min_p_exists
    q = drawn_quantiles(band, min_p_exists)
    mu = np.asarray(band.mu, float)
    ok90 = np.isfinite(q[0]) & np.isfinite(q[4])
    ok50 = np.isfinite(q[1]) & np.isfinite(q[3])
    ax.fill_between(mu, q[0], q[4], where=ok90, color=colour, alpha=_ALPHA_90, lw=0,
                    gid=f"{branch}-band90")
    ax.fill_between(mu, q[1], q[3], where=ok50, color=colour, alpha=_ALPHA_50, lw=0,
                    gid=f"{branch}-band50")
    ax.plot(mu, q[2], gid=f"{branch}-median", zorder=2.5, **_median_style(branch))
    pred = _masked(np.asarray(band.predictive, float), keep)
    for row in (pred[0], pred[4]):
        ax.plot(mu, row, color=colour, lw=0.8, ls=":", gid=f"{branch}-predictive")


def _draw_measured(ax: Axes, ppc: PosteriorPredictiveCheck, bars: str = "measured") -> None:
    mu = np.asarray(ppc.mu, float)
    unstable = np.asarray(ppc.unstable, bool)
    measured = np.asarray(ppc.measured, float)
    for branch, mask in (("stable", ~unstable), ("unstable", unstable)):
        if not mask.any():
            continue
        colour = _style.BRANCH_COLOURS[branch]
        if bars == "predictive":
            ivs = [iv for iv, m in zip(ppc.predictive, mask, strict=True) if m]
            centre = np.array([iv.median for iv in ivs])
            err = np.array([[iv.median - iv.lo for iv in ivs],
                            [iv.hi - iv.median for iv in ivs]])
        elif ppc.measured_se is not None:
            centre = measured[mask]
            err = _style.z_value(ppc.ci) * np.asarray(ppc.measured_se, float)[mask]
        else:
            centre = err = None
        if centre is not None:
            eb = ax.errorbar(mu[mask], centre, yerr=err, fmt="none", ecolor=colour,
                             elinewidth=1.0, capsize=2.5, capthick=1.0, zorder=4)
            _style.tag(eb, f"{branch}-measured-interval")
        ax.plot(mu[mask], measured[mask], ls="none", marker=_style.BRANCH_MARKERS[branch], ms=5,
                mfc=_style.marker_face(branch), mec=colour, mew=1.2, zorder=5,
                gid=f"{branch}-measured")


def _edges(f: Callable[[np.ndarray], np.ndarray], mu: np.ndarray) -> np.ndarray:
    """Points where ``f`` changes between finite and nan, located by bisection."""
    finite = np.isfinite(f(mu))
    out = []
    for j in np.flatnonzero(finite[1:] != finite[:-1]):
        lo, hi = float(mu[j]), float(mu[j + 1])
        flo = finite[j]
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            if bool(np.isfinite(f(np.array([mid])))[0]) == flo:
                lo = mid
            else:
                hi = mid
        out.append(lo if flo else hi)
    return np.asarray(out)


def _truth_curve(truth: AmplitudeTruth, branch: str, lo: float, hi: float):
    """Dense μ grid (refined near the ends of the branch) and the true amplitude there."""

    def f(m):
        return np.asarray(truth(m, branch), float).reshape(np.shape(m))

    mu = np.linspace(lo, hi, 1501)
    try:
        edges = _edges(f, mu)
    except (DataError, ValueError):  # a truth without this branch
        return None
    step = mu[1] - mu[0]
    extra = [e + s * np.geomspace(1e-9 * step, step, 40) for e in edges for s in (-1.0, 1.0)]
    mu = np.unique(np.concatenate([mu, edges, *extra]))
    mu = mu[(mu >= lo) & (mu <= hi)]
    amp = f(mu)
    if not np.isfinite(amp).any():
        return None
    return mu, amp


def _draw_points(ax: Axes, diagram: DiagramBands) -> None:
    """The Hopf point at amplitude 0 and the fold at its amplitude, with 90% intervals."""
    style = dict(color="k", mfc="white", mew=1.2, ms=6, elinewidth=1.0, capsize=3,
                 capthick=1.0, zorder=7, ls="none")
    h0 = diagram.mu0
    hopf = ax.errorbar([h0.median], [0.0], xerr=[[h0.median - h0.lo], [h0.hi - h0.median]],
                       marker="D", **style)
    _style.tag(hopf, "hopf")
    if diagram.mu_fold is not None and diagram.fold_amplitude is not None:
        f, fa = diagram.mu_fold, diagram.fold_amplitude
        fold = ax.errorbar([f.median], [fa.median], xerr=[[f.median - f.lo], [f.hi - f.median]],
                           yerr=[[fa.median - fa.lo], [fa.hi - fa.median]], marker="^", **style)
        _style.tag(fold, "fold")


def _draw_all(ax, diagram, ppc, truth_curves, min_p_exists, bars="measured") -> None:
    for branch, band in _branches(diagram):
        _draw_band(ax, branch, band, min_p_exists)
    if ppc is not None:
        _draw_measured(ax, ppc, bars)
    for mu, amp in truth_curves:
        ax.plot(mu, amp, color="k", lw=0.6, zorder=6, gid="truth")
    _draw_points(ax, diagram)


def _legend_entries(diagram, ppc, truth_curves, mu_units, bars="measured"
                    ) -> tuple[list, list[str]]:
    handles: list = []
    labels: list[str] = []
    branches = _branches(diagram)
    ci = _style.ci_label(diagram.stable.ci)
    for branch, _ in branches:
        handles.append(_BandKey(branch))
        labels.append(f"{branch} branch: median, 50% and {ci} CI")
    handles.append(tuple(Line2D([], [], color=_style.BRANCH_COLOURS[b], lw=0.8, ls=":")
                         for b, _ in branches))
    labels.append(f"{ci} predictive band, new recording")
    if ppc is not None:
        what = (f"{_style.ci_label(ppc.ci)} predictive interval" if bars == "predictive"
                else f"{_style.ci_label(ppc.ci)} CI over segments"
                if ppc.measured_se is not None else "")
        unstable = np.asarray(ppc.unstable, bool)
        for branch, present in (("stable", (~unstable).any()), ("unstable", unstable.any())):
            if not present:
                continue
            c = _style.BRANCH_COLOURS[branch]
            handles.append(Line2D([], [], ls="-" if what else "none", lw=1.0, color=c,
                                  marker=_style.BRANCH_MARKERS[branch], ms=5,
                                  mfc=_style.marker_face(branch),
                                  mec=c, mew=1.2))
            labels.append(f"measured, {branch}" + (f" ({what})" if what else ""))
    if truth_curves:
        handles.append(Line2D([], [], color="k", lw=0.6))
        labels.append("true")
    point = dict(color="k", mfc="white", mew=1.2, ms=6, ls="none")
    handles.append(Line2D([], [], marker="D", **point))
    labels.append(f"Hopf point ({_style.ci_label(diagram.mu0.mass)} CI): "
                  f"{_fmt_interval(diagram.mu0, mu_units)}")
    if diagram.mu_fold is not None and diagram.fold_amplitude is not None:
        handles.append(Line2D([], [], marker="^", **point))
        labels.append(f"fold ({_style.ci_label(diagram.mu_fold.mass)} CI): "
                      f"{_fmt_interval(diagram.mu_fold, mu_units)}")
    return handles, labels


def _bar_ends(ppc: PosteriorPredictiveCheck, bars: str) -> np.ndarray:
    """Lower and upper ends of the measured points' bars, ``(2, n_rec)``."""
    if bars == "predictive":
        return np.array([[iv.lo for iv in ppc.predictive], [iv.hi for iv in ppc.predictive]])
    m = np.asarray(ppc.measured, float)
    if ppc.measured_se is None:
        return np.array([m, m])
    e = _style.z_value(ppc.ci) * np.asarray(ppc.measured_se, float)
    return np.array([m - e, m + e])


def _zoom_ylim(diagram, ppc, truth_curves, window, bars="measured", min_p_exists=0.5
               ) -> tuple[float, float] | None:
    """The y range of the credible bands, data and truth inside the μ window.

    The predictive band is left out (its dotted edges run off the inset), so
    that the credible bands, the point of the inset, fill a visible share of it.
    """
    lo, hi = window
    ys = []
    for _, band in _branches(diagram):
        inside = (band.mu >= lo) & (band.mu <= hi)
        ys.append(drawn_quantiles(band, min_p_exists)[:, inside].ravel())
    if ppc is not None:
        inside = (ppc.mu >= lo) & (ppc.mu <= hi)
        ys.append(np.asarray(ppc.measured, float)[inside])
        ys.append(_bar_ends(ppc, bars)[:, inside].ravel())
    for mu, amp in truth_curves:
        ys.append(amp[(mu >= lo) & (mu <= hi)])
    y = np.concatenate(ys) if ys else np.array([])
    y = y[np.isfinite(y)]
    if y.size == 0:
        return None
    pad = 0.12 * max(float(y.max() - y.min()), 1e-12 * max(abs(float(y.max())), 1.0))
    return float(y.min()) - pad, float(y.max()) + pad


#: Candidate inset positions (axes fractions), in order of preference: the
#: lower-right corner first (right of the Hopf point, under the stable branch),
#: then the other corners, each at decreasing sizes.
_CORNERS = tuple(
    (x, y, w, h)
    for w, h in ((0.30, 0.38), (0.26, 0.34), (0.22, 0.30))
    for x, y in ((0.97 - w, 0.09), (0.09, 0.95 - h), (0.09, 0.09), (0.97 - w, 0.95 - h))
)


def auto_zoom(diagram: DiagramBands, ppc: PosteriorPredictiveCheck | None = None,
              min_p_exists: float = 0.5, max_change: float = 3.0
              ) -> tuple[float, float] | None:
    """μ window of the inset that shows the stable branch's bands where they are thin.

    Centred on the stable recording of largest μ (without recordings, on the
    largest μ where the stable branch is drawn), its half-width is the largest
    of 5%, 4%, …, 1% of the grid's span over which the median changes by at most
    ``max_change`` widths of the outer band at the centre, so the band fills a
    visible share of the inset's height. ``None`` (no inset) where the band is
    already visible at full scale: at least :data:`THIN_BAND` of the highest
    band edge.
    """
    band = diagram.stable
    mu = np.asarray(band.mu, float)
    q = drawn_quantiles(band, min_p_exists)
    drawn = np.isfinite(q[0]) & np.isfinite(q[4]) & np.isfinite(q[2])
    if not drawn.any():
        return None
    centre = float(mu[drawn].max())
    if ppc is not None and (~np.asarray(ppc.unstable, bool)).any():
        centre = float(np.asarray(ppc.mu, float)[~np.asarray(ppc.unstable, bool)].max())
    i = int(np.argmin(np.where(drawn, np.abs(mu - centre), np.inf)))
    width = float(q[4, i] - q[0, i])
    top = max(_finite_max(drawn_quantiles(b, min_p_exists)[4]) for _, b in _branches(diagram))
    if not (top > 0 and width >= 0) or width >= THIN_BAND * top:
        return None
    span = float(mu.max() - mu.min())
    for share in (0.05, 0.04, 0.03, 0.02, 0.01):
        half = share * span
        inside = drawn & (np.abs(mu - centre) <= half)
        change = float(np.ptp(q[2, inside])) if inside.any() else 0.0
        if change <= max_change * max(width, 1e-300):
            break
    return max(centre - half, float(mu.min())), min(centre + half, float(mu.max()))


def _drawn_points(diagram, ppc, truth_curves) -> np.ndarray:
    """(μ, amplitude) of the medians, bands, data and markers, shape ``(n, 2)``."""
    pts = []
    for _, band in _branches(diagram):
        q = np.asarray(band.quantiles, float)
        for row in q:
            pts.append(np.column_stack([band.mu, row]))
    if ppc is not None:
        pts.append(np.column_stack([ppc.mu, ppc.measured]))
    for mu, amp in truth_curves:
        pts.append(np.column_stack([mu, amp]))
    pts.append(np.array([[diagram.mu0.lo, 0.0], [diagram.mu0.hi, 0.0]]))
    if diagram.mu_fold is not None and diagram.fold_amplitude is not None:
        pts.append(np.array([[diagram.mu_fold.median, diagram.fold_amplitude.median]]))
    p = np.concatenate(pts)
    return p[np.isfinite(p).all(axis=1)]


def _free_corner(ax: Axes, points: np.ndarray):
    """The first of :data:`_CORNERS` whose box (with room for tick labels) holds no point."""
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    fx = (points[:, 0] - x0) / (x1 - x0)
    fy = (points[:, 1] - y0) / (y1 - y0)
    for bx, by, bw, bh in _CORNERS:
        left, bottom = bx - 0.07, by - 0.07  # room for the inset's tick labels
        inside = (fx >= left) & (fx <= bx + bw + 0.02) & (fy >= bottom) & (fy <= by + bh + 0.02)
        if not inside.any():
            return (bx, by, bw, bh)
    return None


def _draw_p_exists(ax: Axes, diagram: DiagramBands) -> None:
    """Each branch's posterior probability of existence against μ."""
    _style.style_axes(ax)
    for branch, band in _branches(diagram):
        ax.plot(band.mu, band.p_exists, color=_style.BRANCH_COLOURS[branch], lw=1.2,
                ls=_LINESTYLES[branch], gid=f"{branch}-p-exists")
    ax.set_ylim(-0.05, 1.05)
    ax.set_yticks([0, 1])
    ax.minorticks_off()
    ax.set_ylabel("P(exists)", fontsize=_style.LABEL_SIZE - 1)
    ax.tick_params(labelbottom=False)


def plot_bifurcation(
    diagram: DiagramBands,
    ppc: PosteriorPredictiveCheck | None = None,
    *,
    mu_label: str = DEFAULT_MU_LABEL,
    mu_units: str = "",
    amplitude_units: str = "",
    amplitude_label: str | None = None,
    truth: AmplitudeTruth | None = None,
    min_p_exists: float = 0.5,
    legend: bool = True,
    zoom: tuple[float, float] | str | None = "auto",
    zoom_bounds: tuple[float, float, float, float] | str = "auto",
    ax: Axes | None = None,
    p_exists: bool | Axes | str = "auto",
    bars: str = "measured",
    length_unit: str | None = None,
) -> Figure:
    """Plot the posterior bifurcation diagram (amplitude against μ).

    To draw a fit's diagram into axes of one's own, use
    ``fit.plot.bifurcation(ax=ax)`` (:class:`~bayeshopf.plotting.fit.FitPlots`):
    it passes the fit's names and units of μ and of the amplitude, which this
    function, taking result records only, does not know.

    Each branch is drawn in its own colour (stable C0, unstable C3): its
    posterior median as a line (solid stable, dashed unstable, the dashes' gaps
    in the bands' colour, as in the legend), its 50% credible
    band darker and its outer band (the diagram's level, 90% by default)
    lighter, and the predictive band of a new recording (curve uncertainty plus
    scatter) as thin dotted lines. A branch is drawn where it exists in at
    least ``min_p_exists`` of the draws (by default half, so it ends at the
    median fold), the quantiles there over the draws in which it exists; a
    branch that ends at the Hopf point (the unstable one of a subcritical
    system) is drawn on to amplitude 0 there, the draws past their own Hopf
    point counted at zero amplitude (:func:`drawn_quantiles`), so it meets the
    Hopf marker and its band fans out over the Hopf point's interval. The Hopf
    point is marked at amplitude zero and the fold at its amplitude, each with
    its interval as error bars. A thin panel above shows each branch's
    posterior probability of existence. The y range follows the credible
    bands and the data; predictive quantiles beyond it are clipped.

    Args:
        diagram: The posterior diagram (:meth:`~bayeshopf.posterior.HybridPosterior.diagram`).
        ppc: Posterior predictive check of the training recordings; when given,
            the measured amplitudes are drawn as markers (filled circles stable,
            open squares unstable) with error bars (``bars``).
        mu_label: Name of μ for the x axis (default :data:`DEFAULT_MU_LABEL`;
            ``fit.plot.bifurcation`` passes the fit's).
        mu_units: Unit of μ.
        amplitude_units: Unit of the amplitude (that of the first planar channel).
        amplitude_label: y-axis text; default :data:`DEFAULT_AMPLITUDE_LABEL`
            (``fit.plot.bifurcation`` passes ``"peak-to-peak of <channel>"``).
        truth: Optional ``truth(mu, branch) -> amplitude`` drawn as thin black
            lines (e.g. the planted system of a synthetic data set), in
            ``amplitude_units``.
        min_p_exists: Smallest posterior probability of existence at which a
            branch's band is drawn.
        legend: Whether to add a legend (below the axes).
        zoom: μ window ``(lo, hi)`` shown magnified in an inset, for bands too
            narrow to see at full scale; ``"auto"`` (default) the window of
            :func:`auto_zoom`, none where the bands are visible at full scale;
            ``None`` no inset. The inset's y range follows the credible bands,
            the data and the truth in the window, not the predictive band.
        zoom_bounds: Inset position ``(x0, y0, width, height)`` in axes
            fractions, or ``"auto"``: the first corner of the axes (lower right,
            upper left, lower left, upper right) clear of the curves and
            markers; no inset is drawn when none is clear.
        ax: Axes to draw into; a new figure is made when ``None``.
        p_exists: The panel of P(exists): ``"auto"`` (drawn above the diagram
            in a new figure, left out when ``ax`` is given), ``True``/``False``,
            or the axes to draw it into. ``True`` with ``ax`` given puts it in a
            strip above ``ax``.
        bars: Error bars of the measured points: ``"measured"`` (default) the
            measurement's own uncertainty, the interval of the mean over the
            recording's segments at the check's level (±z·``ppc.measured_se``;
            none for a record of one segment); ``"predictive"`` the model's
            predictive interval of that recording, centred on its median.
        length_unit: Draw the amplitudes in this length unit (``"mm"``, ``"cm"``,
            ``"µm"``, ``"m"``) when ``amplitude_units`` is a length.

    Returns:
        The figure holding the axes.
    """
    if bars not in ("measured", "predictive"):
        raise ValueError(f"bars must be 'measured' or 'predictive'; got {bars!r}")
    factor, amplitude_units = convert(amplitude_units, length_unit)
    if factor != 1.0:
        diagram = scale_diagram(diagram, factor)
        ppc = None if ppc is None else scale_ppc(ppc, factor)
        if truth is not None:
            truth_in_units = truth

            def truth(m, b):
                return np.asarray(truth_in_units(m, b), float) * factor
    p_ax = None
    if ax is None:
        if p_exists is False:
            fig = _style.new_figure(6.4, 5.0)
            ax = fig.add_subplot()
        else:
            fig = _style.new_figure(6.4, 5.6)
            grid = fig.add_gridspec(2, 1, height_ratios=(1, 6))
            ax = fig.add_subplot(grid[1])
            p_ax = fig.add_subplot(grid[0], sharex=ax)
    else:
        fig = ax.figure
        if isinstance(p_exists, Axes):
            p_ax = p_exists
        elif p_exists is True:
            p_ax = ax.inset_axes([0.0, 1.04, 1.0, 0.16], sharex=ax)
    _style.style_axes(ax)
    mu_all = np.asarray(diagram.stable.mu, float)
    mu_lo, mu_hi = float(mu_all.min()), float(mu_all.max())
    truth_curves = []
    if truth is not None:
        for branch, _ in _branches(diagram):
            curve = _truth_curve(truth, branch, mu_lo, mu_hi)
            if curve is not None:
                truth_curves.append(curve)

    _draw_all(ax, diagram, ppc, truth_curves, min_p_exists, bars)
    if p_ax is not None:
        _draw_p_exists(p_ax, diagram)

    # The y range follows the credible bands and the data, not the predictive
    # band, so that a few wild predictive quantiles cannot flatten the figure.
    top = max(_finite_max(np.asarray(b.quantiles, float)[4]) for _, b in _branches(diagram))
    if diagram.fold_amplitude is not None:
        top = max(top, _finite_max(np.array([diagram.fold_amplitude.hi])))
    if ppc is not None:
        top = max(top, float(np.max(ppc.measured)), _finite_max(_bar_ends(ppc, bars)[1]))
    top = float(top) if np.isfinite(top) and top > 0 else 1.0
    ax.set_xlim(mu_lo, mu_hi)
    ax.set_ylim(-0.04 * top, 1.08 * top)
    ax.set_xlabel(_style.axis_label(mu_label, mu_units), fontsize=_style.LABEL_SIZE)
    ax.set_ylabel(_style.axis_label(amplitude_label or DEFAULT_AMPLITUDE_LABEL, amplitude_units),
                  fontsize=_style.LABEL_SIZE)

    if isinstance(zoom, str):
        if zoom != "auto":
            raise ValueError(f"zoom must be 'auto', None or a (lo, hi) window; got {zoom!r}")
        zoom = auto_zoom(diagram, ppc, min_p_exists)
    if zoom is not None:
        ylim = _zoom_ylim(diagram, ppc, truth_curves, zoom, bars, min_p_exists)
        bounds = zoom_bounds
        if isinstance(zoom_bounds, str):
            bounds = _free_corner(ax, _drawn_points(diagram, ppc, truth_curves))
        if ylim is not None and bounds is not None:
            inset = ax.inset_axes(list(bounds))
            _draw_all(inset, diagram, ppc, truth_curves, min_p_exists, bars)
            _style.style_axes(inset, grid=False)
            inset.minorticks_off()
            inset.tick_params(labelsize=_style.TICK_SIZE - 1.5, pad=2)
            inset.locator_params(nbins=3)
            inset.set_xlim(*zoom)
            inset.set_ylim(*ylim)
            inset.set_facecolor("white")
            ax.indicate_inset_zoom(inset, edgecolor="0.4", alpha=0.8, lw=0.6)

    if legend:
        handles, labels = _legend_entries(diagram, ppc, truth_curves, mu_units, bars)
        ax.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2,
                  fontsize=_style.LEGEND_SIZE, frameon=False, handlelength=3.0, handleheight=1.5,
                  columnspacing=1.5,
                  handler_map={tuple: HandlerTuple(ndivide=None, pad=0.3),
                               _BandKey: _BandHandler()})
    return fig


def _finite_max(a: np.ndarray) -> float:
    a = a[np.isfinite(a)]
    return float(a.max()) if a.size else 0.0


def _fmt_interval(iv, units: str) -> str:
    """``"18.00 [17.99, 18.01] m/s"`` with enough digits to tell the ends apart."""
    width = abs(iv.hi - iv.lo)
    scale = max(abs(iv.median), 1e-300)
    digits = int(np.clip(np.ceil(-np.log10(max(width, 1e-12 * scale))) + 1, 0, 6))
    fmt = f"{{:.{digits}f}}"
    text = f"{fmt.format(iv.median)} [{fmt.format(iv.lo)}, {fmt.format(iv.hi)}]"
    return f"{text} {units}".rstrip()
