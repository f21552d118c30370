"""Figures of a fit: structure, atomic saving, and purity (no input or global state changes)."""

from __future__ import annotations

import copy
import dataclasses
import os

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from bayeshopf.data.synthetic import demo_system  # noqa: E402
from bayeshopf.inference.collapsed import CollapsedSettings  # noqa: E402
from bayeshopf.plotting import (  # noqa: E402
    FIGURE_NAMES,
    FREQUENCY_FIGURE_NAMES,
    coefficient_labels,
    default_zoom,
    diagram_grid,
    plot_all,
    plot_bifurcation,
    plot_phase_portraits,
    plot_ppc,
    save_figure,
)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def fitted():
    """The fast demo fit with its recordings, truth, diagram and predictive check."""
    rs, truth = demo_system(seed=0, fast=True)
    from bayeshopf.posterior import fit_hybrid

    f = fit_hybrid(rs, "subcritical", seed=0, settings=CollapsedSettings.fast(), progress=False)
    return dict(fit=f, rs=rs, truth=truth, diagram=f.diagram(diagram_grid(f)), ppc=f.ppc())


def _by_gid(artists, gid: str) -> list:
    return [a for a in artists if a.get_gid() == gid]


def _snapshot(obj):
    """Deep copy of arrays inside dicts, tuples and dataclasses (for equality checks)."""
    if isinstance(obj, dict):
        return {k: _snapshot(v) for k, v in obj.items()}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: _snapshot(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, list | tuple):
        return [_snapshot(v) for v in obj]
    if hasattr(obj, "__array__") and not isinstance(obj, str | float | int):
        return np.array(obj, copy=True)
    return copy.deepcopy(obj)


def _assert_same(a, b) -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for k in a:
            _assert_same(a[k], b[k])
    elif isinstance(a, list):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _assert_same(x, y)
    elif isinstance(a, np.ndarray):
        assert a.shape == b.shape and a.dtype == b.dtype
        assert np.array_equal(a, b, equal_nan=a.dtype.kind in "fc")
    elif isinstance(a, float) and np.isnan(a):
        assert np.isnan(b)
    else:
        assert a == b


def _assert_png(path, min_bytes: int = 20_000) -> None:
    assert path.is_file()
    assert path.stat().st_size > min_bytes
    assert path.read_bytes()[:8] == PNG_MAGIC


# -- saving ---------------------------------------------------------------------------


def test_save_figure_is_atomic(tmp_path) -> None:
    fig = Figure()
    fig.add_subplot().plot([0, 1], [1, 0])
    path = save_figure(fig, tmp_path / "a" / "b" / "line.png", dpi=80)
    assert path == tmp_path / "a" / "b" / "line.png"
    _assert_png(path, min_bytes=1_000)
    assert os.listdir(path.parent) == ["line.png"]  # no temporary file left
    assert not fig.axes  # closed (cleared)
    umask = os.umask(0o022)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask  # ordinary permissions

    # overwriting replaces the file in one step
    fig2 = Figure()
    fig2.add_subplot().plot([0, 1], [0, 1])
    save_figure(fig2, path, dpi=60)
    _assert_png(path, min_bytes=1_000)
    assert os.listdir(path.parent) == ["line.png"]


def test_save_figure_failure_leaves_nothing(tmp_path) -> None:
    fig = Figure()
    fig.add_subplot()
    with pytest.raises(ValueError):
        save_figure(fig, tmp_path / "out" / "bad.notaformat")
    assert os.listdir(tmp_path / "out") == []


def test_coefficient_labels() -> None:
    assert coefficient_labels(5) == ["a0", "a1", "a2", "b1", "b2"]
    assert len(coefficient_labels(17)) == 17
    with pytest.raises(ValueError):
        coefficient_labels(4)


# -- figures --------------------------------------------------------------------------


def test_plot_bifurcation(fitted, tmp_path) -> None:
    f, d, ppc, truth = fitted["fit"], fitted["diagram"], fitted["ppc"], fitted["truth"]
    fig = plot_bifurcation(d, ppc, mu_label=f.mu_label, mu_units=f.mu_units,
                           amplitude_units=f.amplitude_units, amplitude_label="heave peak-to-peak",
                           truth=truth.amplitude)
    assert isinstance(fig, Figure) and len(fig.axes) == 1
    ax = fig.axes[0]
    for branch in ("stable", "unstable"):
        assert len(_by_gid(ax.lines, f"{branch}-median")) == 1
        assert len(_by_gid(ax.lines, f"{branch}-predictive")) == 2
        assert len(_by_gid(ax.collections, f"{branch}-band90")) == 1
        assert len(_by_gid(ax.collections, f"{branch}-band50")) == 1
        (points,) = _by_gid(ax.lines, f"{branch}-measured")
        n_branch = int(np.sum(ppc.unstable == (branch == "unstable")))
        assert len(points.get_xdata()) == n_branch
        assert _by_gid(ax.collections, f"{branch}-measured-interval")
    # the median line is masked where the unstable branch does not exist
    (unstable_median,) = _by_gid(ax.lines, "unstable-median")
    y = np.asarray(unstable_median.get_ydata(), float)
    assert np.isnan(y[d.unstable.p_exists < 0.05]).all()
    assert len(_by_gid(ax.lines, "truth")) == 2
    assert _by_gid(ax.lines, "hopf") and _by_gid(ax.lines, "fold")
    assert ax.get_xlabel() == "airspeed [m/s]"
    assert ax.get_ylabel() == "heave peak-to-peak [m]"
    assert ax.get_legend() is not None
    lo, hi = ax.get_ylim()
    assert lo < 0 < max(ppc.measured) < hi < 2 * max(ppc.measured)
    _assert_png(save_figure(fig, tmp_path / "bifurcation.png"))


def test_plot_bifurcation_defaults_and_given_axes(fitted) -> None:
    d = fitted["diagram"]
    fig = Figure()
    ax = fig.add_subplot(1, 2, 2)
    assert plot_bifurcation(d, ax=ax, legend=False) is fig
    assert ax.get_legend() is None
    assert ax.get_ylabel() == "peak-to-peak of z1" and ax.get_xlabel() == "μ"
    assert not _by_gid(ax.lines, "stable-measured") and not _by_gid(ax.lines, "truth")

    # a supercritical diagram: one branch, no fold
    sup = dataclasses.replace(d, unstable=None, mu_fold=None, fold_amplitude=None)
    ax = plot_bifurcation(sup).axes[0]
    assert _by_gid(ax.lines, "stable-median") and not _by_gid(ax.lines, "unstable-median")
    assert _by_gid(ax.lines, "hopf") and not _by_gid(ax.lines, "fold")


def test_plot_bifurcation_zoom_inset(fitted) -> None:
    f, d, ppc, truth = fitted["fit"], fitted["diagram"], fitted["ppc"], fitted["truth"]
    window = default_zoom(f, d.stable.mu)
    assert window[0] < max(ppc.mu[~ppc.unstable]) <= window[1]
    fig = plot_bifurcation(d, ppc, truth=truth.amplitude, zoom=window)
    assert len(fig.axes) == 1
    (inset,) = fig.axes[0].child_axes
    assert inset.get_xlim() == pytest.approx(window)
    lo, hi = inset.get_ylim()
    assert 0 < lo < hi and (hi - lo) < 0.2 * fig.axes[0].get_ylim()[1]  # magnified
    assert _by_gid(inset.lines, "stable-median") and _by_gid(inset.collections, "stable-band90")
    # the automatic placement keeps the inset off the curves: the Hopf point and
    # every measured point lie outside it (in axes fractions)
    ax = fig.axes[0]
    fig.draw_without_rendering()
    (x0, y0), (x1, y1) = ax.transAxes.inverted().transform(inset.get_window_extent())
    w, h = x1 - x0, y1 - y0
    assert 0.15 < w < 0.5 and 0.15 < h < 0.5
    (xa, xb), (ya, yb) = ax.get_xlim(), ax.get_ylim()
    fx = (np.append(ppc.mu, d.mu0.median) - xa) / (xb - xa)
    fy = (np.append(ppc.measured, 0.0) - ya) / (yb - ya)
    assert not np.any((fx > x0) & (fx < x0 + w) & (fy > y0) & (fy < y0 + h))
    # an explicit position is used as given
    fig = plot_bifurcation(d, ppc, zoom=window, zoom_bounds=(0.1, 0.6, 0.2, 0.2))
    ax = fig.axes[0]
    fig.draw_without_rendering()
    box = ax.transAxes.inverted().transform(ax.child_axes[0].get_window_extent())
    assert box.ravel() == pytest.approx([0.1, 0.6, 0.3, 0.8], abs=1e-6)


def test_plot_phase_portraits(fitted, tmp_path) -> None:
    f, rs, truth = fitted["fit"], fitted["rs"], fitted["truth"]
    fig = plot_phase_portraits(f, rs, n_orbits=12, max_points=150, truth=truth.orbit)
    assert len(fig.axes) == len(rs)
    assert len(fig.legends) == 1
    for ax, rec in zip(fig.axes, rs, strict=True):
        assert len(_by_gid(ax.lines, "orbit-draw")) == 12
        assert len(_by_gid(ax.lines, "orbit-median")) == 1
        assert len(_by_gid(ax.lines, "truth")) == 1
        (measured,) = _by_gid(ax.lines, "measured")
        assert 0 < len(measured.get_xdata()) <= 150
        assert ax.get_title() == f"μ = {rec.mu:.4g} m/s, {rec.branch}"
    assert fig.axes[0].get_title() == "μ = 15.3 m/s, stable"
    assert fig.axes[0].get_ylabel() == "alpha [rad]"
    assert fig.axes[-1].get_xlabel() == "h [m]"
    _assert_png(save_figure(fig, tmp_path / "phase.png"))


def test_plot_ppc(fitted, tmp_path) -> None:
    ppc = fitted["ppc"]
    fig = plot_ppc(ppc, amplitude_units="m", amplitude_label="peak-to-peak of h")
    assert len(fig.axes) == 3  # two panels and the colour bar
    ax_a, ax_b = fig.axes[:2]
    points = _by_gid(ax_a.lines, "stable-points") + _by_gid(ax_a.lines, "unstable-points")
    assert sum(len(p.get_xdata()) for p in points) == len(ppc.measured)
    assert _by_gid(ax_a.lines, "identity")
    assert _by_gid(ax_a.collections, "stable-curve") and _by_gid(ax_a.collections,
                                                                 "unstable-predictive")
    assert ax_a.get_xlabel() == "measured peak-to-peak of h [m]"
    (im,) = ax_b.images
    assert im.get_array().shape == ppc.coeff_z.shape
    assert im.get_clim() == (-3.0, 3.0)
    assert np.nanmax(np.abs(im.get_array())) <= 3.0
    ticks = [t.get_text() for t in ax_b.get_xticklabels()]
    half = coefficient_labels(ppc.coeff_z.shape[1] // 2)
    assert ticks == [f"z1:{k}" for k in half] + [f"z2:{k}" for k in half]
    assert [t.get_text() for t in ax_b.get_yticklabels()] == list(ppc.names)
    _assert_png(save_figure(fig, tmp_path / "ppc.png"))


def test_plot_all(fitted, tmp_path) -> None:
    out = tmp_path / "figures"
    paths = plot_all(fitted["fit"], fitted["rs"], out, truth=fitted["truth"], dpi=80)
    names = list(FIGURE_NAMES) + list(FREQUENCY_FIGURE_NAMES)
    assert [p.name for p in paths] == names
    for p in paths:
        _assert_png(p, min_bytes=10_000)
    assert sorted(os.listdir(out)) == sorted(names)  # no temporary files


def test_plotting_is_pure(fitted, tmp_path) -> None:
    f, rs, truth = fitted["fit"], fitted["rs"], fitted["truth"]
    d, ppc = fitted["diagram"], fitted["ppc"]
    before = _snapshot(dict(samples=f.samples, diagram=d, ppc=ppc,
                            recordings=[dict(r.channels) for r in rs]))
    rc_before = dict(matplotlib.rcParams)
    figs_before = plt.get_fignums()

    plot_bifurcation(d, ppc, truth=truth.amplitude)
    plot_phase_portraits(f, rs, n_orbits=5, truth=truth.orbit)
    plot_ppc(ppc)

    after = _snapshot(dict(samples=f.samples, diagram=d, ppc=ppc,
                           recordings=[dict(r.channels) for r in rs]))
    _assert_same(before, after)
    assert plt.get_fignums() == figs_before  # nothing registered with pyplot
    assert dict(matplotlib.rcParams) == rc_before
