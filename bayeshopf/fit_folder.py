"""Saving a fit to a folder and loading it back for predictions.

A fit folder holds

* ``summary.json``: μ0, a2 and μ_fold (median and 90% interval), the
  criticality, the amplitude unit, and every recording's measured and
  predicted amplitude, plus settings and stage timings;
* ``posterior.nc``: the fit as ArviZ InferenceData (netCDF,
  :meth:`~bayeshopf.posterior.HybridPosterior.to_inference_data`): the posterior
  draws, each recording's leave-one-out log-likelihood (``az.loo`` reads it),
  a replicated recording per draw (posterior predictive), the measured
  amplitudes and features, with coordinates;
* ``model.json``: the model structure (:class:`CollapsedSpec`) and the MAP
  point, enough to predict and to draw every figure again;
* ``figures/*.png`` (or ``.pdf``/``.svg``: :func:`redraw_figures`, ``bayeshopf plot``).

:func:`load_fit` reads a folder back: :class:`SavedHybrid` predicts, and its
:attr:`SavedHybrid.posterior` is the :class:`~bayeshopf.posterior.HybridPosterior`
again (diagram, predictive check, frequency; the phase portraits and time
series with the recordings), without refitting.

Every file is written to a staging folder first and moved into place with
``os.replace``, so an interrupted run never leaves a half-written file, and a
folder that already holds files is refused unless ``force`` is set.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from bayeshopf._atomic import move_into
from bayeshopf._x64 import ensure_x64
from bayeshopf.diagnostics import arviz_io
from bayeshopf.diagnostics.summaries import CI, Interval, interval
from bayeshopf.errors import DataError, OutputError
from bayeshopf.fit_summary import (  # noqa: F401 (re-exported)
    COLLAPSED_CORE,
    _finite_or_none,
    summary_hybrid,
)
from bayeshopf.model.collapsed import CollapsedSpec

SUMMARY = "summary.json"
POSTERIOR = "posterior.nc"
MODEL = "model.json"
FIGURES = "figures"


def check_output_folder(out: str | os.PathLike[str], force: bool) -> Path:
    """Refuse a non-empty output folder unless ``force``; refuse a file in its place.

    Raises:
        OutputError: With the folder and what was found.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: expected an output folder; found an existing file")
    if out.is_dir() and any(out.iterdir()) and not force:
        raise OutputError(
            f"{out}: output folder is not empty; expected a new or empty folder "
            "(force=True replaces bayeshopf's files in it; other files are kept)"
        )
    return out


def json_ready(obj):
    """``obj`` with every non-finite float as ``None`` (strict JSON has no inf or nan)."""
    if isinstance(obj, dict):
        return {k: json_ready(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_ready(v) for v in obj]
    if isinstance(obj, float):
        return _finite_or_none(obj)
    return obj


def _write_json(obj, path: Path) -> None:
    path.write_text(json.dumps(json_ready(obj), indent=2, allow_nan=False) + "\n")


def _draw_figures(figures, stage: Path, meanwhile) -> dict:
    """Run ``figures(folder)`` and ``meanwhile()``; the figures' wall time.

    ``figures`` may return a function that waits for figures still being drawn
    elsewhere (:func:`bayeshopf.plotting.start_figures`): ``meanwhile`` then runs
    before that wait, while they finish, and the figures' time, to the last one
    written, includes it. Otherwise ``meanwhile`` runs after the figures.
    """
    if figures is None:
        meanwhile()
        return {}
    (stage / FIGURES).mkdir()
    t0 = time.perf_counter()
    pending = figures(stage / FIGURES)
    if not callable(pending):
        spent = time.perf_counter() - t0
        meanwhile()
        return {"figures": spent}
    meanwhile()
    pending()
    return {"figures": time.perf_counter() - t0}


def _staged(out, force: bool, write) -> Path:
    """Run ``write(stage)`` in a staging folder, then move its files into ``out`` atomically."""
    out = check_output_folder(out, force)
    parent = out.parent if str(out.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=parent))
    except OSError as e:
        raise OutputError(f"{out}: cannot create the output folder ({e.strerror})") from None
    try:
        write(stage)
        move_into(stage, out)
    except OSError as e:
        raise OutputError(f"{out}: cannot write the fit ({e.strerror or e})") from None
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return out


def save_hybrid(post, out: str | os.PathLike[str], *, force: bool = False, figures=None,
                ppc=None, extra_summary: dict | None = None, ci: float = CI) -> Path:
    """Write a fit folder atomically.

    ``posterior.nc`` is :meth:`~bayeshopf.posterior.HybridPosterior.to_inference_data`:
    the draws by chain of every site, the map's coefficients ``beta`` and the
    frequency's ``gamma`` (one exact draw per posterior draw), each recording's
    ``log p(y_i | y_{−i}, θ)`` as the ``log_likelihood`` group (for ``az.loo``),
    the posterior predictive and observed amplitudes and features, with
    coordinates; ``model.json`` the model structure, the MAP point and the
    predictive standard errors of a new recording.

    Args:
        post: The :class:`~bayeshopf.posterior.HybridPosterior`.
        out: The output folder.
        force: Replace bayeshopf's files in a non-empty folder (others are kept).
        figures: Optional callable ``figures(folder)`` that draws the figures
            into a folder and returns their paths, or a function that waits
            for them (:func:`~bayeshopf.plotting.start_figures`: ``model.json``
            and ``posterior.nc`` are then written before it is called, while a
            figure process finishes). Its time is recorded in the summary.
        ppc: The posterior predictive check, if already computed (at level ``ci``).
        extra_summary: More keys for ``summary.json``.
        ci: Mass of the summary's intervals (:func:`summary_hybrid`).

    Returns:
        The output folder.
    """
    def write(stage: Path) -> None:
        post.dispatch()     # posterior.nc's log-likelihood computes beside the figures
        # model.json and posterior.nc are written while a figure process finishes
        timed = replace(post, timings={**post.timings,
                                       **_draw_figures(figures, stage, lambda: files(stage))})
        _write_json(summary_hybrid(timed, ppc, extra_summary, ci), stage / SUMMARY)

    def files(stage: Path) -> None:
        mp = post.map_point
        model = {"core": COLLAPSED_CORE, "spec": post.spec.to_dict(),
                 "predictive_se": np.median(post.features.coeffs_se, axis=0).tolist(),
                 "predictive_omega_se": float(np.median(post.features.omega_se)),
                 "extrapolation": _extrapolation_data(post),
                 "seed": post.seed,
                 "map": {"params": {k: np.asarray(v, float).tolist()
                                    for k, v in mp.params.items()},
                         "grad_norm": float(mp.grad_norm), "converged": bool(mp.converged),
                         "steps": int(mp.n_steps), "log_joint": float(mp.log_joint),
                         "polish_evaluations": int(mp.polish_evaluations)},
                 "divergences": int(post.run.divergences)}
        _write_json(model, stage / MODEL)
        arviz_io.write_netcdf(post.to_inference_data(), stage / POSTERIOR)

    return _staged(out, force, write)


def _extrapolation_data(post) -> dict | None:
    """Training μ per branch for the model error away from the recordings, or None if off."""
    if not post.settings.extrapolation:
        return None
    f = post.features
    return {"mu_stable": f.mu[~f.unstable].tolist(), "mu_unstable": f.mu[f.unstable].tolist(),
            "scale": post.settings.extrapolation_scale}


@dataclass(frozen=True)
class SavedHybrid:
    """A collapsed-core fit read back from its folder.

    It predicts (:meth:`predict`, :meth:`frequency`, :meth:`p_exists`) from the
    draws alone; :attr:`posterior` rebuilds the
    :class:`~bayeshopf.posterior.HybridPosterior` from the saved draws,
    features and MAP point, so every summary and figure of the fit is drawn
    again without refitting (:meth:`diagram`, :meth:`ppc`, :meth:`plot`).

    Attributes:
        folder: Where it was read from.
        spec: The model structure.
        samples: Posterior draws of every site (``beta``: the map's coefficients).
        summary: The content of ``summary.json``.
        predictive_se: Standard errors of a new recording's coefficients.
        predictive_omega_se: Standard error of a new recording's frequency (rad/s).
        extrapolation: Training μ of each branch (``mu_stable``, ``mu_unstable``)
            and the prior scale (``scale``; the default where a fit saved before
            it had none) of the model error away from the recordings; ``None``
            when the fit had it off.
        model: The content of ``model.json``.
    """

    folder: Path
    spec: object
    samples: dict
    summary: dict
    predictive_se: np.ndarray
    predictive_omega_se: float = 0.0
    extrapolation: dict | None = None
    model: dict | None = None

    def inference_data(self):
        """``posterior.nc`` as ArviZ InferenceData (see ``HybridPosterior.to_inference_data``)."""
        return arviz_io.read_inference_data(self.folder / POSTERIOR)

    @cached_property
    def posterior(self):
        """The fit as a :class:`~bayeshopf.posterior.HybridPosterior`, rebuilt without refitting.

        Its draws, features, MAP point, settings and diagnostics are the saved
        ones, its ``log_likelihood`` the saved one; ``diagram``, ``ppc``,
        ``frequency_band``, ``orbits`` and ``time_series_bands`` compute as on
        the fitted object (the same draws and seed give the same numbers).

        Raises:
            DataError: For a folder written by a bayeshopf without the saved
                features (before the ``amplitude`` group variables existed).
        """
        return _rebuild(self)

    def diagram(self, mu=None, ci: float = CI):
        """The bifurcation diagram (:meth:`~bayeshopf.posterior.HybridPosterior.diagram`)."""
        return self.posterior.diagram(mu, ci)

    def ppc(self, ci: float = CI):
        """The predictive check (:meth:`~bayeshopf.posterior.HybridPosterior.ppc`)."""
        return self.posterior.ppc(ci)

    def plot(self, out_dir=None, recordings=None, **kwargs) -> list[Path]:
        """Draw the fit's figures again; :func:`redraw_figures` (into ``figures/`` by default)."""
        return redraw_figures(self, recordings, out_dir, **kwargs)

    def frequency(self, mu: float, branch: str = "stable", predictive: bool = False,
                  ci: float = CI) -> Interval | None:
        """Frequency (Hz) median and ``ci`` interval (90% by default) at μ, or ``None``.

        ``None`` without a frequency model, or where no draw has the branch.
        """
        from bayeshopf import predictive as pr
        from bayeshopf.model.normal_form import branch_sign

        if "gamma" not in self.samples:
            return None
        try:                        # the rebuilt fit's prediction (one path for every command)
            f = self.posterior.frequency([mu], branch, predictive=predictive,
                                         omega_se=self.predictive_omega_se)[:, 0]
        except DataError:           # a folder of an older bayeshopf: from the draws alone
            idx = pr.draw_indices(len(self.samples["gamma"]))
            theta = {k: v[idx] for k, v in self.samples.items() if k not in ("beta", "gamma")}
            f = pr.frequency_draws(self.spec, theta, self.samples["gamma"][idx], [mu],
                                   branch_sign(branch), predictive=predictive,
                                   omega_se=self.predictive_omega_se,
                                   seed=int(self.summary.get("seed", 0)))[:, 0]
        f = f[np.isfinite(f)]
        return interval(f, ci) if f.size else None

    def _draws(self, mu: float, branch: str, predictive: bool) -> np.ndarray:
        """Amplitude draws at μ: the rebuilt fit's own prediction (one path for every command).

        A folder without the saved features (an older bayeshopf) predicts from
        the draws alone, without the model error away from the recordings.
        """
        from bayeshopf import predictive as pr
        from bayeshopf.model.normal_form import branch_sign

        if (self.spec.has_discrepancy or self.spec.nn_training is not None
                or self.extrapolation is not None):
            try:
                return self.posterior.amplitude([mu], branch, predictive=predictive)[:, 0]
            except DataError:
                pass
        idx = pr.draw_indices(len(self.samples["beta"]))
        s = {k: v[idx] for k, v in self.samples.items()}
        theta = {k: v for k, v in s.items() if k not in ("beta", "gamma")}
        c = pr.orbit_coefficients(self.spec, theta, s["beta"], [mu], branch_sign(branch))
        if predictive:
            rng = np.random.default_rng(int(self.summary.get("seed", 0)))
            sd = pr.noise_sd(c, s["sigma"], s["sigma_rel"], self.predictive_se)
            c = c + sd * rng.standard_normal(c.shape)
        return pr.amplitude_of(self.spec, c)[:, 0]

    def predict(self, mu: float, branch: str = "stable", predictive: bool = False,
                ci: float = CI) -> Interval:
        """Amplitude median and ``ci`` interval (90% by default) at μ on ``branch``.

        Raises:
            DataError: When the branch does not exist at μ in any posterior draw.
        """
        draws = self._draws(mu, branch, predictive)
        if not np.isfinite(draws).any():
            raise DataError(
                f"mu = {mu:g}: the {branch} branch does not exist there in any posterior "
                f"draw (Hopf point μ0 ≈ "
                f"{np.median(self.samples.get('mu0_rig', self.samples['mu0'])):.4g}"
                + (f", fold ≈ {self.summary['mu_fold']['median']:.4g}"
                   if self.summary.get("mu_fold") else "") + ")")
        return interval(draws, ci)

    def p_exists(self, mu: float, branch: str = "stable") -> float:
        """Posterior probability that ``branch`` exists at μ."""
        return float(np.isfinite(self._draws(mu, branch, False)).mean())


def _rebuild(saved: SavedHybrid):
    """The :class:`~bayeshopf.posterior.HybridPosterior` of a fit folder (see ``posterior``)."""
    from dataclasses import fields

    from bayeshopf.features.harmonics import HarmonicFeatures
    from bayeshopf.inference.collapsed import CollapsedSettings, MapPoint, PosteriorRun
    from bayeshopf.posterior import HybridPosterior

    path = saved.folder / POSTERIOR
    idata = saved.inference_data()
    groups = set(idata.groups())
    need = {"observed_data": ("amplitude", "coeffs"),
            "constant_data": ("mu", "unstable", "coeffs_se", "amplitude_sd", "n_segments",
                              "segment_rms", "frequency_se")}
    for g, names in need.items():
        ds = getattr(idata, g) if g in groups else None
        missing = [n for n in names if ds is None or n not in ds]
        if missing:
            raise DataError(f"{path}: expected {g} variables {', '.join(missing)} (written by "
                            "bayeshopf since its figures can be redrawn); found none: fit "
                            "the recordings again to redraw figures (predict still works)")
    obs, const = idata.observed_data, idata.constant_data
    spec = saved.spec
    freq = (np.asarray(obs["frequency"].values, float) if "frequency" in obs
            else np.full(obs.sizes["recording"], np.nan))
    features = HarmonicFeatures(
        mu=np.asarray(const["mu"].values, float),
        unstable=np.asarray(const["unstable"].values).astype(bool),
        coeffs=np.asarray(obs["coeffs"].values, float),
        coeffs_se=np.asarray(const["coeffs_se"].values, float),
        segment_rms=np.asarray(const["segment_rms"].values, float),
        n_segments=np.asarray(const["n_segments"].values).astype(int),
        omega=2 * np.pi * freq,
        omega_se=2 * np.pi * np.asarray(const["frequency_se"].values, float),
        amplitude=np.asarray(obs["amplitude"].values, float),
        amplitude_sd=np.asarray(const["amplitude_sd"].values, float),
        frame=spec.frame, n_harmonics=spec.n_harmonics,
        names=tuple(str(n) for n in obs["recording"].values),
        control=np.asarray(const["control"].values, float) if "control" in const else None)
    post_ds = idata.posterior
    chains = {k: np.asarray(v.values) for k, v in post_ds.data_vars.items()
              if k not in ("beta", "gamma")}
    n = post_ds.sizes["chain"] * post_ds.sizes["draw"]
    betas = np.asarray(post_ds["beta"].values).reshape((n,) + post_ds["beta"].shape[2:])
    gammas = (np.asarray(post_ds["gamma"].values).reshape((n,) + post_ds["gamma"].shape[2:])
              if "gamma" in post_ds else None)
    model, summary = saved.model or {}, saved.summary
    m = model.get("map", {})
    params = {k: np.asarray(v, float) for k, v in m.get("params", {}).items()}
    if not params:     # an older folder: the summary's few MAP values
        params = {k: np.asarray(v, float) for k, v in summary.get("map", {}).items()
                  if v is not None}
    map_point = MapPoint(params=params, unconstrained={}, log_joint=m.get("log_joint", np.nan),
                         grad_norm=m.get("grad_norm", np.nan), converged=m.get("converged", True),
                         n_steps=m.get("steps", 0), start={},
                         polish_evaluations=m.get("polish_evaluations", 0))
    method = summary.get("diagnostics", {}).get("posterior", {}).get("method", "nuts")
    run = PosteriorRun(method, chains, betas, gammas, int(model.get("divergences", 0)))
    known = {f.name for f in fields(CollapsedSettings)}
    saved_settings = {"mu_discrepancy_floor": 0.0,   # a folder from before the floor
                      **summary.get("settings", {})}
    settings = CollapsedSettings(**{k: v for k, v in saved_settings.items() if k in known})
    post = HybridPosterior(spec, features, map_point, run, settings,
                           int(summary.get("seed", 0)), summary.get("mu_label", "mu"),
                           summary.get("mu_units", ""), summary.get("amplitude_units", ""),
                           timings=dict(summary.get("timings_s", {})),
                           diagnostics=dict(summary.get("diagnostics", {})))
    if "log_likelihood" in groups and "y" in idata.log_likelihood:
        # the saved leave-one-out log-likelihood, instead of computing it again
        post.__dict__["log_likelihood"] = np.asarray(idata.log_likelihood["y"].values)
    return post


def _bare(name: str) -> str:
    """A recording's name without a data file's suffix (``run01.csv`` and ``run01`` match)."""
    for suffix in (".csv", ".mat"):
        if name.lower().endswith(suffix):
            return name[: -len(suffix)]
    return name


def recordings_in_fit_order(saved: SavedHybrid, recordings):
    """``recordings`` (a RecordingSet or a folder) as the fit's recordings, in its order.

    Recordings are matched by name (a file's ``.csv`` or ``.mat`` suffix aside),
    else as the only recording at a fitted μ on its branch.

    Raises:
        DataError: When a recording of the fit is missing or its μ or branch differ.
    """
    from bayeshopf.data import load_recordings
    from bayeshopf.data.recording import RecordingSet

    planar = tuple(saved.spec.frame.names)
    rs = (recordings if isinstance(recordings, RecordingSet)
          else load_recordings(recordings, planar=planar))
    f = saved.posterior.features
    by_name = {_bare(r.name): r for r in rs}
    unnamed = [r for r in rs if _bare(r.name) not in {_bare(n) for n in f.names}]
    picked = {}
    for name, mu, unstable in zip(f.names, f.mu, f.unstable, strict=True):
        if _bare(name) in by_name:
            picked[name] = by_name[_bare(name)]
            continue
        # a renamed file: the one recording at the fit's μ on its branch
        same = [r for r in unnamed if np.isclose(r.mu, mu)
                and (r.branch == "unstable") == bool(unstable)]
        if len(same) == 1:
            picked[name] = same[0]
    missing = [n for n in f.names if n not in picked]
    if missing:
        raise DataError(f"recordings: expected the fit's recordings {', '.join(f.names)} (by "
                        f"name, or by μ and branch); missing {', '.join(missing)}")
    recs = []
    for name, mu, unstable in zip(f.names, f.mu, f.unstable, strict=True):
        r = picked[name]
        if not np.isclose(r.mu, mu) or (r.branch == "unstable") != bool(unstable):
            raise DataError(f"recordings: {name}: expected μ = {mu:g}, "
                            f"{'unstable' if unstable else 'stable'} as fitted; found μ = "
                            f"{r.mu:g}, {r.branch}")
        recs.append(r)
    return RecordingSet(tuple(recs), planar=rs.planar, mu_label=rs.mu_label,
                        mu_units=rs.mu_units, extra=rs.extra, control=rs.control)


def redraw_figures(saved: SavedHybrid, recordings=None, out_dir=None, *,
                   fmt: str = "png", truth=None, **kwargs) -> list[Path]:
    """Draw a saved fit's figures again, without refitting, and move them into place atomically.

    The figures are drawn into a staging folder beside ``out_dir`` and each is
    moved into ``out_dir`` with ``os.replace`` once all are drawn, so a failed
    run leaves the old figures as they were. Without ``recordings`` the
    figures that need the raw records (phase portraits, time series) are
    left out.

    Args:
        saved: The fit (:func:`load_fit`).
        recordings: The recordings it was fitted to (a
            :class:`~bayeshopf.data.recording.RecordingSet` or a folder that
            :func:`~bayeshopf.data.load_recordings` reads), or ``None``.
        out_dir: Destination (default ``saved.folder / "figures"``).
        fmt: ``"png"``, ``"pdf"`` or ``"svg"``.
        truth: A planted or simulated truth to overlay (e.g. the demo's).
        **kwargs: Passed to :func:`~bayeshopf.plotting.plot_all` (``ci``,
            ``length_unit``, ``offsets``, ``dpi``, ``zoom``).

    Returns:
        The paths written.

    Raises:
        DataError: For recordings that are not the fit's.
        OutputError: When the folder cannot be written.
    """
    from bayeshopf.plotting import plot_all

    out = Path(out_dir) if out_dir is not None else saved.folder / FIGURES
    rs = None if recordings is None else recordings_in_fit_order(saved, recordings)
    post = saved.posterior
    try:
        out.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    except OSError as e:
        raise OutputError(f"{out}: cannot create the figures folder ({e.strerror})") from None
    try:
        drawn = plot_all(post, rs, stage, truth=truth, fmt=fmt, **kwargs)
        paths = move_into(stage, out, drawn)
    except OSError as e:
        raise OutputError(f"{out}: cannot write the figures ({e.strerror or e})") from None
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return paths


def load_fit(folder: str | os.PathLike[str]) -> SavedHybrid:
    """Read a fit folder written by :func:`save_hybrid`.

    Raises:
        DataError: When a file is missing or unreadable.
    """
    ensure_x64()
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(f"{folder}: expected a fit folder (from 'bayeshopf fit'); not found")
    for name in (SUMMARY, MODEL, POSTERIOR):
        if not (folder / name).is_file():
            raise DataError(f"{folder}: expected {name} in a fit folder; not found")
    try:
        summary = json.loads((folder / SUMMARY).read_text())
        model = json.loads((folder / MODEL).read_text())
        if model.get("core") != COLLAPSED_CORE:
            raise DataError(f"{folder / MODEL}: expected \"core\": \"{COLLAPSED_CORE}\"; found "
                            f"{model.get('core')!r}, a fit of the removed legacy inference "
                            "core: fit the recordings again")
        spec = CollapsedSpec.from_dict(model["spec"])
    except (ValueError, KeyError, TypeError) as e:
        raise DataError(f"{folder}: summary.json or model.json is not readable ({e})") from None
    try:
        samples, _ = arviz_io.read_posterior(folder / POSTERIOR)
    except Exception as e:  # netCDF/HDF5 raise many types
        raise DataError(f"{folder / POSTERIOR}: not a readable posterior file ({e})") from None
    return SavedHybrid(folder, spec, samples, summary, np.asarray(model["predictive_se"]),
                       float(model.get("predictive_omega_se", 0.0)), model.get("extrapolation"),
                       model)
