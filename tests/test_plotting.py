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
def fitted(fast_demo_fit):
    """The fast demo fit with its recordings, truth, diagram and predictive check."""
    f, rs, truth = fast_demo_fit
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
    assert isinstance(fig, Figure) and len(fig.axes) == 2  # the diagram and P(exists) above it
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
    # without the fit's names the axes say what they are, not a placeholder channel
    assert ax.get_ylabel() == "amplitude (peak-to-peak)"
    assert ax.get_xlabel() == "bifurcation parameter"
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
    assert len(fig.axes) == 2
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
        (draws,) = _by_gid(ax.collections, "orbit-draws")      # one collection of 12 orbits
        assert len(draws.get_segments()) == 12
        assert all(np.array_equal(seg[0], seg[-1]) for seg in draws.get_segments())  # closed
        assert len(_by_gid(ax.lines, "orbit-median")) == 1
        assert len(_by_gid(ax.lines, "truth")) == 1
        (measured,) = _by_gid(ax.lines, "measured")
        assert 0 < len(measured.get_xdata()) <= 150
        assert ax.get_title() == f"μ = {rec.mu:.4g} m/s, {rec.branch}"
    assert fig.axes[0].get_title() == "μ = 15.3 m/s, stable"
    assert fig.axes[0].get_ylabel() == "Δalpha [rad]"   # each recording's mean removed
    assert fig.axes[-1].get_xlabel() == "Δh [m]"
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


def test_plot_all_with_a_figure_process_writes_the_same_files(fitted, tmp_path) -> None:
    """The figures drawn in the spawned worker are byte for byte those drawn here."""
    from bayeshopf.plotting import figure_worker

    # the worker draws the predictive check, the phase portraits (from orbits and a
    # truth computed here) and the time series; this process the diagram and frequency
    kw = dict(truth=fitted["truth"], dpi=40)
    here = plot_all(fitted["fit"], fitted["rs"], tmp_path / "here", **kw)
    with figure_worker() as ex:
        there = plot_all(fitted["fit"], fitted["rs"], tmp_path / "there", executor=ex, **kw)
    assert [p.name for p in there] == [p.name for p in here]
    assert "phase_portraits.png" in [p.name for p in there]
    for a, b in zip(here, there, strict=True):
        assert a.read_bytes() == b.read_bytes(), a.name
    assert sorted(os.listdir(tmp_path / "there")) == sorted(p.name for p in here)


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


# -- journal options: ax=, offsets, units, vector output, branches to the Hopf point ----


def _public_plot_functions():
    import inspect

    from bayeshopf.plotting import (
        channels,
        diagram,
        discrepancy,
        pair_invariant,
        phase,
        ppc,
        timeseries,
        truth,
        validation,
    )

    mods = (channels, diagram, discrepancy, pair_invariant, phase, ppc, timeseries, truth,
            validation)
    return [fn for m in mods for name, fn in inspect.getmembers(m, inspect.isfunction)
            if name.startswith("plot_") and fn.__module__ == m.__name__
            and name != "plot_discrepancy"]       # plot_discrepancy writes files


def test_every_plotting_function_takes_ax() -> None:
    import inspect

    fns = _public_plot_functions()
    assert len(fns) >= 10
    assert [fn.__name__ for fn in fns if "ax" not in inspect.signature(fn).parameters] == []


def test_given_axes_are_drawn_into(fitted) -> None:
    f, rs, ppc = fitted["fit"], fitted["rs"], fitted["ppc"]
    from bayeshopf.plotting import plot_frequency, plot_time_series
    from bayeshopf.plotting.truth import plot_diagram_vs_truth

    fig = Figure()
    axes = fig.subplots(2, 4).ravel()
    assert plot_phase_portraits(f, rs, n_orbits=3, max_points=50, ax=axes) is fig
    assert all(_by_gid(a.lines, "orbit-median") for a in axes[: len(rs)])
    assert not axes[-1].get_visible()            # one axes more than recordings: hidden
    with pytest.raises(ValueError, match="expected 7 matplotlib Axes"):
        plot_phase_portraits(f, rs, ax=axes[:3])

    fig = Figure()
    ax = fig.add_subplot()
    assert plot_ppc(ppc, ax=ax) is fig and len(fig.axes) == 1   # panel (a) only
    assert _by_gid(ax.lines, "stable-points")
    fig = Figure()
    pair = fig.subplots(1, 2)
    assert plot_ppc(ppc, ax=pair) is fig and pair[1].images

    fig = Figure()
    ax = fig.add_subplot()
    mu = f.default_mu_grid(30)
    assert plot_frequency([f.frequency_band(mu, "stable")], ax=ax) is fig
    assert _by_gid(ax.lines, "stable-median")
    bands = f.time_series_bands(rs)[:2]
    fig = Figure()
    two = fig.subplots(1, 2)
    assert plot_time_series(bands, ax=two) is fig and _by_gid(two[1].lines, "measured")
    fig = Figure()
    ax = fig.add_subplot()
    assert plot_diagram_vs_truth(f, fitted["truth"], mu=mu, zoom=False, ax=ax) is fig
    assert _by_gid(ax.lines, "stable-median") and _by_gid(ax.lines, "truth")


def _with_offsets(rs, shift: dict):
    """The recordings with constant sensor offsets added (a rig's h ≈ 0.6 m, α ≈ 0.7 rad)."""
    recs = tuple(dataclasses.replace(r, channels={k: np.asarray(v) + shift.get(k, 0.0)
                                                  for k, v in r.channels.items()})
                 for r in rs)
    return dataclasses.replace(rs, recordings=recs)


def test_offsets_removed_or_kept(fitted) -> None:
    f = fitted["fit"]
    rs = _with_offsets(fitted["rs"], {"h": 0.6, "alpha": 0.7})
    rec = next(iter(rs))
    z = rec.planar(rs.planar)
    centre, scale = z.mean(axis=0), np.ptp(z, axis=0)
    removed = plot_phase_portraits(f, rs, n_orbits=2).axes[0]
    kept = plot_phase_portraits(f, rs, n_orbits=2, offsets="keep").axes[0]
    (m,) = _by_gid(removed.lines, "measured")
    xy = np.column_stack([m.get_xdata(), m.get_ydata()])
    assert np.all(np.abs(xy.mean(axis=0)) < 0.02 * scale)       # centred on the recording
    (mk,) = _by_gid(kept.lines, "measured")
    assert np.mean(mk.get_xdata()) == pytest.approx(centre[0], rel=0.01)   # 0.6 m kept
    # the model orbit is shifted by the same amount, so a mismatch of centres still shows
    (a,), (b,) = _by_gid(removed.lines, "orbit-median"), _by_gid(kept.lines, "orbit-median")
    np.testing.assert_allclose(a.get_xdata(), np.asarray(b.get_xdata()) - centre[0])
    np.testing.assert_allclose(a.get_ydata(), np.asarray(b.get_ydata()) - centre[1])
    assert removed.get_ylabel() == "Δalpha [rad]" and kept.get_ylabel() == "alpha [rad]"
    with pytest.raises(ValueError, match="offsets"):
        plot_phase_portraits(f, rs, offsets="subtract")

    from bayeshopf.plotting import plot_time_series

    band = f.time_series_bands(rs)[0]
    assert np.mean(band.measured) > 0.5                          # the offset is in the band
    ax = plot_time_series([band]).axes[0]
    (m,) = _by_gid(ax.lines, "measured")
    assert abs(np.mean(m.get_ydata())) < 1e-9
    (med,) = _by_gid(ax.lines, "median")
    np.testing.assert_allclose(med.get_ydata(), band.median - np.mean(band.measured))
    assert ax.get_ylabel() == "Δh [m]"
    ax = plot_time_series([band], offsets="keep").axes[0]
    (m,) = _by_gid(ax.lines, "measured")
    np.testing.assert_allclose(m.get_ydata(), band.measured)


def test_length_unit_scales_lengths_only(fitted) -> None:
    d, ppc, f, rs = fitted["diagram"], fitted["ppc"], fitted["fit"], fitted["rs"]
    base = plot_bifurcation(d, ppc, amplitude_units="m").axes[0]
    mm = plot_bifurcation(d, ppc, amplitude_units="m", length_unit="mm").axes[0]
    (a,), (b,) = _by_gid(base.lines, "stable-median"), _by_gid(mm.lines, "stable-median")
    np.testing.assert_allclose(b.get_ydata(), 1000 * np.asarray(a.get_ydata()), equal_nan=True)
    (a,), (b,) = _by_gid(base.lines, "stable-measured"), _by_gid(mm.lines, "stable-measured")
    np.testing.assert_allclose(b.get_ydata(), 1000 * np.asarray(a.get_ydata()))
    assert mm.get_ylabel() == "amplitude (peak-to-peak) [mm]"
    assert mm.get_ylim()[1] == pytest.approx(1000 * base.get_ylim()[1])
    # phase portraits: h (m) in mm, alpha (rad) in degrees
    ax = plot_phase_portraits(f, rs, n_orbits=2, length_unit="mm", angle_unit="deg",
                              offsets="keep").axes[0]
    (m,) = _by_gid(ax.lines, "measured")
    z = next(iter(rs)).planar(rs.planar)
    assert np.max(m.get_xdata()) == pytest.approx(1000 * z[:, 0].max(), rel=1e-9)
    assert np.max(m.get_ydata()) == pytest.approx(np.degrees(z[:, 1].max()), rel=1e-9)
    assert ax.get_ylabel() == "alpha [deg]"
    fig = plot_ppc(ppc, amplitude_units="m", amplitude_label="A", length_unit="mm")
    assert fig.axes[0].get_xlabel() == "measured A [mm]"
    with pytest.raises(ValueError, match="length_unit"):
        plot_bifurcation(d, amplitude_units="m", length_unit="furlong")


def test_unstable_branch_is_drawn_to_the_hopf_point(fitted) -> None:
    d = fitted["diagram"]
    fig = plot_bifurcation(d)
    ax = fig.axes[0]
    (line,) = _by_gid(ax.lines, "unstable-median")
    x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
    ok = np.isfinite(y)
    end = np.flatnonzero(ok)[-1]
    step = np.max(np.diff(d.unstable.mu))
    assert y[end] == 0.0 and abs(x[end] - d.mu0.median) <= step   # it meets the Hopf marker
    assert np.all(y[ok][:-1] > 0)                # positive all along, zero only at the end
    assert not np.isfinite(y[end + 1:]).any()    # nothing drawn past the Hopf point
    # where the branch exists in every draw the drawn band is the conditional one
    full = d.unstable.p_exists == 1.0
    np.testing.assert_allclose(y[full], d.unstable.median[full])
    # the outer band fans over the Hopf point's interval: its top reaches 0 past the median
    (band,) = _by_gid(ax.collections, "unstable-band90")
    xs = np.concatenate([p.vertices[:, 0] for p in band.get_paths()])
    assert xs.max() >= d.mu0.median
    # P(exists) above the diagram, sharing μ
    p_ax = fig.axes[1]
    (p,) = _by_gid(p_ax.lines, "unstable-p-exists")
    np.testing.assert_allclose(p.get_ydata(), d.unstable.p_exists)
    assert p_ax.get_ylabel() == "P(exists)"


def test_measured_points_carry_the_measured_spread(fitted) -> None:
    from bayeshopf.plotting._style import z_value

    d, ppc = fitted["diagram"], fitted["ppc"]
    assert ppc.measured_se is not None and np.all(ppc.measured_se > 0)
    ax = plot_bifurcation(d, ppc).axes[0]
    stable = ~np.asarray(ppc.unstable, bool)
    (bars,) = [c for c in _by_gid(ax.collections, "stable-measured-interval")
               if hasattr(c, "get_segments")]
    seg = np.array(bars.get_segments())                       # (n, 2, 2)
    half = (seg[:, 1, 1] - seg[:, 0, 1]) / 2
    np.testing.assert_allclose(np.sort(half), np.sort(z_value(0.9) * ppc.measured_se[stable]))
    np.testing.assert_allclose(np.sort(seg.mean(axis=1)[:, 1]), np.sort(ppc.measured[stable]))
    # the old bars, the model's predictive intervals, on request
    ax = plot_bifurcation(d, ppc, bars="predictive").axes[0]
    (bars,) = [c for c in _by_gid(ax.collections, "stable-measured-interval")
               if hasattr(c, "get_segments")]
    lo = np.array([iv.lo for iv, s in zip(ppc.predictive, stable, strict=True) if s])
    np.testing.assert_allclose(np.sort(np.array(bars.get_segments())[:, 0, 1]), np.sort(lo))


@pytest.mark.parametrize("fmt,magic", [("pdf", b"%PDF"), ("svg", b"<svg")])
def test_vector_output(fitted, tmp_path, fmt, magic) -> None:
    path = save_figure(plot_bifurcation(fitted["diagram"], fitted["ppc"]),
                       tmp_path / f"bifurcation.{fmt}")
    data = path.read_bytes()
    assert path.suffix == f".{fmt}" and len(data) > 5_000 and magic in data[:2_000]
    assert os.listdir(tmp_path) == [f"bifurcation.{fmt}"]


def test_plot_all_vector_without_recordings(fitted, tmp_path) -> None:
    paths = plot_all(fitted["fit"], None, tmp_path, fmt="svg", ci=0.5)
    assert [p.name for p in paths] == ["bifurcation.svg", "ppc.svg", "frequency.svg"]
    assert all(p.stat().st_size > 5_000 for p in paths)
    text = paths[0].read_text()
    assert 'id="unstable-median"' in text and 'id="stable-p-exists"' in text


def test_time_series_legend_keys_show_each_branch_colour(fitted) -> None:
    """The band's and the median's keys carry the colours of the branches drawn, no other."""
    import matplotlib.colors as mcolors

    from bayeshopf.plotting import plot_time_series
    from bayeshopf.plotting._style import BRANCH_COLOURS

    bands = fitted["fit"].time_series_bands(fitted["rs"])
    assert {b.branch for b in bands} == {"stable", "unstable"}

    def key_colours(fig):
        (leg,) = fig.legends
        assert [t.get_text() for t in leg.get_texts()] == ["measured", "90% band",
                                                           "posterior median"]
        # HandlerTuple draws each key's artists into the legend's handle box
        box = leg.get_children()[0].get_children()[1]   # VPacker of (key, label) rows
        rows = [r.get_children()[0] for c in box.get_children() for r in c.get_children()]
        cols = []
        for area in rows:
            arts = area.get_children()
            cols.append({mcolors.to_hex(a.get_facecolor() if hasattr(a, "get_height")
                                        else a.get_color()) for a in arts})
        return cols

    both = key_colours(plot_time_series(bands))
    hexes = {k: mcolors.to_hex(v) for k, v in BRANCH_COLOURS.items()}
    assert both[1] == both[2] == {hexes["stable"], hexes["unstable"]}
    stable_only = key_colours(plot_time_series([b for b in bands if b.branch == "stable"]))
    assert stable_only[1] == stable_only[2] == {hexes["stable"]}


# -- the figures' faults (issue 52) ---------------------------------------------------


def _band_width_at(band, mu: float) -> float:
    """Width of the outer band at the grid point nearest ``mu`` (from the record)."""
    i = int(np.argmin(np.abs(np.asarray(band.mu, float) - mu)))
    q = np.asarray(band.quantiles, float)
    return float(q[4, i] - q[0, i])


def test_inset_shows_the_bands_where_they_are_thin(fitted) -> None:
    f, d, ppc = fitted["fit"], fitted["diagram"], fitted["ppc"]
    centre = float(np.max(ppc.mu[~ppc.unstable]))
    width = _band_width_at(d.stable, centre)
    fig = plot_bifurcation(d, ppc)                   # no window asked for: an inset anyway
    ax = fig.axes[0]
    assert width < 0.02 * ax.get_ylim()[1]          # a line at full scale
    (inset,) = ax.child_axes
    lo, hi = inset.get_xlim()
    assert lo < centre < hi
    y0, y1 = inset.get_ylim()
    # the band fills a visible share of the inset: a few band widths tall
    assert width < y1 - y0 < 6 * width
    i = int(np.argmin(np.abs(d.stable.mu - centre)))
    assert y0 < d.stable.quantiles[0, i] < d.stable.quantiles[4, i] < y1
    # the window fit.plot passes (default_zoom) also gets an inset scaled to the band
    window = default_zoom(f, d.stable.mu)
    (inset,) = plot_bifurcation(d, ppc, zoom=window).axes[0].child_axes
    y0, y1 = inset.get_ylim()
    q = d.stable.quantiles[:, (d.stable.mu >= window[0]) & (d.stable.mu <= window[1])]
    assert y1 - y0 < 1.5 * (q[4].max() - q[0].min())   # not the predictive band's range
    assert not plot_bifurcation(d, ppc, zoom=None).axes[0].child_axes
    # bands wide enough to see at full scale need no inset
    wide = dataclasses.replace(d.stable, quantiles=d.stable.quantiles[2]
                               * np.array([0.7, 0.85, 1.0, 1.15, 1.3])[:, None])
    assert not plot_bifurcation(dataclasses.replace(d, stable=wide)).axes[0].child_axes


def test_dashed_median_looks_as_its_legend_key(fitted) -> None:
    """The dashes' gaps show the band, not the dotted predictive edges (read as dash-dot)."""
    import matplotlib.colors as mcolors

    from bayeshopf.plotting.diagram import _BandHandler, _BandKey

    d = fitted["diagram"]
    fig = plot_bifurcation(d, fitted["ppc"])
    ax = fig.axes[0]
    (median,) = _by_gid(ax.lines, "unstable-median")
    assert median.get_linestyle() == "--"
    for edge in _by_gid(ax.lines, "unstable-predictive"):
        assert edge.get_zorder() < median.get_zorder()
    # the gaps take the colour of both bands laid over white
    (b90,), (b50,) = (_by_gid(ax.collections, f"unstable-band{k}") for k in (90, 50))
    rgb = np.array(mcolors.to_rgb(median.get_color()))
    seen = 1 - (1 - b90.get_alpha()) * (1 - b50.get_alpha())
    assert median.get_gapcolor() is not None
    np.testing.assert_allclose(mcolors.to_rgb(median.get_gapcolor()), seen * rgb + 1 - seen)
    leg = ax.get_legend()
    arts = _BandHandler().create_artists(leg, _BandKey("unstable"), 0, 0, 30, 10, 8,
                                         ax.transAxes)
    (key,) = [a for a in arts if hasattr(a, "get_linestyle") and hasattr(a, "get_xdata")]
    assert key.get_linestyle() == median.get_linestyle()
    assert key.get_linewidth() == median.get_linewidth()
    assert mcolors.to_rgb(key.get_gapcolor()) == mcolors.to_rgb(median.get_gapcolor())


def test_ppc_bars_are_visible_and_named_from_the_fit(fitted) -> None:
    ppc = fitted["ppc"]
    fig = plot_ppc(ppc, amplitude_units="m", amplitude_label="peak-to-peak of h",
                   channels=("h", "alpha"))
    ax_a, ax_b = fig.axes[:2]
    height = np.ptp(ax_a.get_ylim())
    widest = max(iv.hi - iv.lo for iv in ppc.predictive)
    assert widest > 0.3 * height         # the predictive intervals span the panel
    (bars,) = [c for c in _by_gid(ax_a.collections, "stable-predictive")
               if hasattr(c, "get_segments")]
    seg = np.array(bars.get_segments())
    stable = ~ppc.unstable
    lo = np.array([iv.lo for iv in ppc.predictive])[stable] - ppc.measured[stable]
    np.testing.assert_allclose(np.sort(seg[:, 0, 1]), np.sort(lo))   # predicted − measured
    ticks = [t.get_text() for t in ax_b.get_xticklabels()]
    half = coefficient_labels(ppc.coeff_z.shape[1] // 2)
    assert ticks == [f"h:{k}" for k in half] + [f"alpha:{k}" for k in half]
    assert "z1" not in ax_b.get_xlabel() and "h, alpha" in ax_b.get_xlabel()
    cbar_label = fig.axes[2].get_ylabel()
    assert "Φ" not in cbar_label and "\\Phi" not in cbar_label and "measured" in cbar_label
    # one axes: panel (a) only, with no forced title
    one = Figure().add_subplot()
    plot_ppc(ppc, ax=one)
    assert one.get_title(loc="left") == "" and one.get_title() == ""
    assert "(a)" in ax_a.get_title(loc="left")     # both panels: told apart


def test_frequency_legend_lists_only_what_is_seen(fitted) -> None:
    from bayeshopf.plotting import plot_frequency

    f = fitted["fit"]
    mu = diagram_grid(f)
    bands = [f.frequency_band(mu, b) for b in ("stable", "unstable")]
    pred = [f.frequency_band(mu, b, predictive=True) for b in ("stable", "unstable")]
    fig = plot_frequency(bands, predictive=pred)
    ax = fig.axes[0]
    height = np.ptp(ax.get_ylim())
    assert all(np.nanmedian(b.hi - b.lo) < 0.01 * height for b in bands + pred)
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert len(texts) == 2 and not any("new recording" in t for t in texts)
    assert all("narrower than the line" in t for t in texts)
    assert not _by_gid(ax.lines, "stable-predictive")
    # bands widened to a tenth of the range are drawn and listed
    spread = 0.1 * height

    def widen(b):
        return dataclasses.replace(b, lo=b.median - spread, hi=b.median + spread)

    ax = plot_frequency([widen(b) for b in bands], predictive=[widen(b) for b in pred]).axes[0]
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "stable, median and 90% CI" in texts and "unstable, new recording (90%)" in texts
    assert len(_by_gid(ax.lines, "stable-predictive")) == 2


def test_measured_trace_is_drawn_over_the_median(fitted) -> None:
    from bayeshopf.plotting import plot_time_series

    bands = fitted["fit"].time_series_bands(fitted["rs"])[:2]
    fig = plot_time_series(bands)
    for ax in fig.axes[:2]:
        (measured,), (median,) = _by_gid(ax.lines, "measured"), _by_gid(ax.lines, "median")
        assert measured.get_zorder() > median.get_zorder()
        assert median.get_linewidth() > measured.get_linewidth()   # shows on either side


def test_default_labels_and_the_documented_route(fitted) -> None:
    from bayeshopf.plotting import plot_frequency, plot_time_series

    fig = plot_bifurcation(fitted["diagram"], fitted["ppc"], legend=False)
    ax = fig.axes[0]
    assert "z1" not in ax.get_ylabel() and ax.get_xlabel() != "μ"
    for fn, route in ((plot_bifurcation, "fit.plot.bifurcation"), (plot_ppc, "fit.plot.ppc"),
                      (plot_frequency, "fit.plot.frequency"),
                      (plot_time_series, "fit.plot.time_series")):
        assert route in fn.__doc__, fn.__name__
