"""Journal-quality figures of a fit: bifurcation diagram, phase portraits, predictive check.

Every plotting function is pure: it takes result records (a
:class:`~bayeshopf.diagnostics.bifurcation.DiagramBands`, posterior draws,
a :class:`~bayeshopf.diagnostics.ppc.PosteriorPredictiveCheck`, ...) and returns
a new :class:`matplotlib.figure.Figure` that is not registered with pyplot, so
no global matplotlib state (current figure, rcParams) is read or changed; or,
given ``ax=`` (one Axes, or one per panel), draws into those and returns their
figure. :func:`save_figure` writes a figure atomically in the format of its
suffix (``.png``, ``.pdf``, ``.svg``) and :func:`plot_all` draws the standard
set of a fit (:class:`~bayeshopf.posterior.HybridPosterior`, or
``load_fit(DIR).posterior``).

The measured points carry the measurement's own uncertainty (the interval of
the mean over a recording's segments), not the model's; phase portraits and
time series are drawn about each recording's mean (``offsets="remove"``);
``length_unit="mm"`` (``angle_unit="deg"``) rescales lengths (angles).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bayeshopf._lazy import submodule_getattr
from bayeshopf._preload import figure_worker
from bayeshopf.data.recording import RecordingSet
from bayeshopf.plotting._io import save_figure
from bayeshopf.plotting._units import readable_length
from bayeshopf.plotting.diagram import plot_bifurcation
from bayeshopf.plotting.phase import draw_phase_panels, phase_panels, plot_phase_portraits
from bayeshopf.plotting.ppc import coefficient_labels, plot_ppc
from bayeshopf.plotting.timeseries import plot_frequency, plot_time_series

__all__ = [
    "FIGURE_NAMES",
    "FigureOptions",
    "coefficient_labels",
    "default_zoom",
    "diagram_grid",
    "figure_worker",
    "plot_all",
    "plot_bifurcation",
    "plot_frequency",
    "plot_phase_portraits",
    "plot_ppc",
    "plot_time_series",
    "save_figure",
    "start_figures",
]

#: File names written by :func:`plot_all`, in order.
FIGURE_NAMES = ("bifurcation.png", "phase_portraits.png", "ppc.png")
#: ... then these for a fit with a frequency model (``fit.has_frequency``).
FREQUENCY_FIGURE_NAMES = ("frequency.png", "time_series.png")


def diagram_grid(fit, n: int = 100, n_refine: int = 25) -> np.ndarray:
    """μ grid for the diagram of ``fit``, refined about the Hopf and fold points.

    The amplitude has a square-root singularity at the Hopf point and at the
    fold, so a uniform grid leaves the branches visibly short of those points;
    ``n_refine`` extra points are spread over each point's 90% interval widened
    by two grid steps.

    Args:
        fit: A :class:`~bayeshopf.posterior.HybridPosterior`.
        n: Points of the uniform base grid (its ``default_mu_grid``).
        n_refine: Extra points about each of the Hopf and fold points.
    """
    base = fit.default_mu_grid(n)
    step = float(base[1] - base[0])
    extra = []
    for name in ("mu0", "mu_fold"):
        iv = fit.interval(name)
        if iv is not None and np.isfinite([iv.lo, iv.hi]).all():
            extra.append(np.linspace(iv.lo - 2 * step, iv.hi + 2 * step, n_refine))
    mu = np.unique(np.concatenate([base, *extra]))
    return mu[(mu >= base[0]) & (mu <= base[-1])]


def default_zoom(fit, mu: np.ndarray) -> tuple[float, float]:
    """μ window about the stable recording of largest μ (±5% of the grid's span).

    That is where the diagram is furthest from the Hopf point and its bands,
    measured interval and any truth can be compared at a glance in an inset.
    """
    f = fit.features
    stable = ~np.asarray(f.unstable, bool)
    mus = np.asarray(f.mu, float)[stable] if stable.any() else np.asarray(f.mu, float)
    centre = float(mus.max())
    half = 0.05 * float(mu.max() - mu.min())
    return max(centre - half, float(mu.min())), min(centre + half, float(mu.max()))


def _named(names, fmt: str) -> list[str]:
    return [str(Path(n).with_suffix(f".{fmt}")) for n in names]


@dataclass(frozen=True)
class FigureOptions:
    """How :func:`plot_all` and :func:`start_figures` draw (their keyword arguments).

    Attributes:
        zoom: Add an inset magnifying the diagram's bands where they are too
            thin to see at full scale, about the stable recording of largest μ
            (:func:`~bayeshopf.plotting.diagram.auto_zoom`), placed where it
            hides nothing.
        dpi: Resolution of raster files.
        fmt: File format: ``"png"``, ``"pdf"`` or ``"svg"`` (vector).
        ci: Level of the bands and intervals.
        length_unit: Unit of lengths (``"mm"``, …), ``None`` for the fit's
            own, or ``"auto"``: the one of m, mm, µm in which the largest
            measured amplitude reads 1–1000.
        angle_unit: Unit of angles (``"deg"``, …), ``None`` for the fit's own.
        offsets: ``"remove"`` or ``"keep"`` each recording's mean in the phase
            portraits and time series.
    """

    zoom: bool = True
    dpi: int = 150
    fmt: str = "png"
    ci: float = 0.9
    length_unit: str | None = "auto"
    angle_unit: str | None = None
    offsets: str = "remove"


def plot_all(fit, recordings: RecordingSet | None, out_dir: str | os.PathLike[str], truth=None,
             *, executor: Executor | None = None, **options) -> list[Path]:
    """Draw and save the standard figures of a fit.

    Writes ``bifurcation.png`` (:func:`plot_bifurcation` with the training
    amplitudes and their measured spread, and P(exists)), ``phase_portraits.png``
    (:func:`plot_phase_portraits`) and ``ppc.png`` (:func:`plot_ppc`) into
    ``out_dir``, each atomically; for a fit with a frequency model also
    ``frequency.png`` (:func:`plot_frequency`, curve and predictive bands with
    the measured frequencies) and ``time_series.png`` (:func:`plot_time_series`,
    z1 over four periods of each recording). Without ``recordings`` the phase
    portraits and time series, which need the raw records, are left out.

    Args:
        fit: A :class:`~bayeshopf.posterior.HybridPosterior` (fitted, or
            ``load_fit(DIR).posterior``).
        recordings: The recordings it was fitted to, in its order, or ``None``.
        out_dir: Destination folder (created if missing).
        truth: Optional planted system
            (:class:`~bayeshopf.data.synthetic.PlantedHopf`) whose amplitude
            curve and orbits are overlaid.
        executor: Optional :class:`concurrent.futures.Executor` (a process
            pool, :func:`figure_worker`) that draws and saves the predictive
            check, the phase portraits (their orbits computed here,
            :func:`~bayeshopf.plotting.phase.phase_panels`), the time series
            and the frequency while this process computes the bands and draws
            the diagram; Matplotlib's drawing holds the interpreter, so a second
            process is what runs it beside the first.
        **options: The fields of :class:`FigureOptions` (``zoom``, ``dpi``,
            ``fmt``, ``ci``, ``length_unit``, ``angle_unit``, ``offsets``).

    Returns:
        The paths written, in the order of :data:`FIGURE_NAMES` (then
        :data:`FREQUENCY_FIGURE_NAMES`), less those that need recordings when
        there are none.
    """
    return start_figures(fit, recordings, out_dir, truth, executor=executor, **options)()


def start_figures(fit, recordings: RecordingSet | None, out_dir: str | os.PathLike[str],
                  truth=None, *, executor: Executor | None = None, **options
                  ) -> Callable[[], list[Path]]:
    """:func:`plot_all`, returning before the figures an executor draws are written.

    The arguments are :func:`plot_all`'s. The figures drawn in this process are
    written when it returns; the returned function waits for the executor's and
    returns every path, as :func:`plot_all` does. The CLI writes
    ``posterior.nc`` in between, while the figure process finishes
    (``bayeshopf.fit_folder.save_hybrid``).

    Returns:
        A function without arguments that returns :func:`plot_all`'s paths once
        every figure is written (it raises what a figure's drawing raised).
    """
    opts = FigureOptions(**options)
    zoom, dpi, fmt, ci = opts.zoom, opts.dpi, opts.fmt, opts.ci
    length_unit, angle_unit, offsets = opts.length_unit, opts.angle_unit, opts.offsets
    if fmt not in ("png", "pdf", "svg"):
        raise ValueError(f"fmt must be 'png', 'pdf' or 'svg'; got {fmt!r}")
    out = Path(out_dir)
    z1 = fit.spec.frame.names[0]
    amp_label = f"peak-to-peak of {z1}"
    if length_unit == "auto":
        length_unit = readable_length(fit.amplitude_units,
                                      float(np.max(np.abs(fit.features.amplitude))))
    units = dict(length_unit=length_unit, angle_unit=angle_unit)
    ppc = fit.ppc(ci)
    mu = diagram_grid(fit)
    names = FIGURE_NAMES + (FREQUENCY_FIGURE_NAMES if fit.has_frequency else ())
    paths = dict(zip(names, (out / n for n in _named(names, fmt)), strict=True))
    jobs = {}             # name -> future, or the path already written

    def draw(name, builder, *args, **kwargs):      # data only: drawable in another process
        if executor is None:
            jobs[name] = save_figure(builder(*args, **kwargs), paths[name], dpi=dpi)
        else:
            jobs[name] = executor.submit(_draw_and_save, builder, args, kwargs, paths[name], dpi)

    orbit_truth = None if truth is None else (lambda mu, branch: truth.orbit(mu, branch))
    draw(FIGURE_NAMES[2], plot_ppc, ppc, amplitude_units=fit.amplitude_units,
         amplitude_label=amp_label, length_unit=length_unit,
         channels=tuple(fit.spec.frame.names[:2]))
    if recordings is not None:       # the orbits computed here, drawn by the executor
        draw(FIGURE_NAMES[1], draw_phase_panels,
             phase_panels(fit, recordings, truth=orbit_truth, offsets=offsets),
             recordings.planar, recordings.units[:2], mu_units=recordings.mu_units,
             offsets=offsets, **units)
    if fit.has_frequency:
        bands, pred = [], []
        branches = ("stable", "unstable") if fit.criticality == "subcritical" else ("stable",)
        for b in branches:
            bands.append(fit.frequency_band(mu, b, ci=ci))
            pred.append(fit.frequency_band(mu, b, predictive=True, ci=ci))
        f = fit.features
        measured = [(m, hz, "unstable" if u else "stable", se / (2 * np.pi))
                    for m, hz, u, se in zip(f.mu, f.frequency_hz, f.unstable, f.omega_se,
                                            strict=True)]
        if recordings is not None:
            draw(FREQUENCY_FIGURE_NAMES[1], plot_time_series,
                 fit.time_series_bands(recordings, ci=ci), mu_label=fit.mu_label,
                 mu_units=fit.mu_units, offsets=offsets, ci=ci, **units)
        draw(FREQUENCY_FIGURE_NAMES[0], plot_frequency, bands, measured, predictive=pred,
             mu_label=fit.mu_label, mu_units=fit.mu_units, ci=ci)
    # the diagram (its truth is a function of a simulator) is drawn here; the CLI
    # then writes posterior.nc while the executor finishes (fit_folder.save_hybrid)
    diagram = fit.diagram(mu, ci)
    amp_truth = None if truth is None else (lambda mu, branch: truth.amplitude(mu, branch))
    jobs[FIGURE_NAMES[0]] = save_figure(plot_bifurcation(
        diagram, ppc, mu_label=fit.mu_label, mu_units=fit.mu_units,
        amplitude_units=fit.amplitude_units, amplitude_label=amp_label, truth=amp_truth,
        zoom="auto" if zoom else None, length_unit=length_unit),
        paths[FIGURE_NAMES[0]], dpi=dpi)

    def written() -> list[Path]:
        return [j if isinstance(j, Path) else j.result() for n in names if (j := jobs.get(n))]

    return written


def _draw_and_save(builder, args, kwargs, path, dpi) -> Path:
    return save_figure(builder(*args, **kwargs), path, dpi=dpi)


__getattr__ = submodule_getattr(__name__)
