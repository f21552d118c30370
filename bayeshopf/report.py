"""Saving a fit to a folder and loading it back for predictions.

A fit folder holds

* ``summary.json``: μ0, a2 and μ_fold (median and 90% interval), the
  criticality, the amplitude unit, and every recording's measured and
  predicted amplitude, plus settings and stage timings;
* ``posterior.nc``: the posterior draws as ArviZ InferenceData (netCDF), with
  each recording's leave-one-out log-likelihood as its ``log_likelihood`` group;
* ``model.json``: the model structure (:class:`CollapsedSpec`), enough to predict;
* ``figures/*.png``.

Every file is written to a staging folder first and moved into place with
``os.replace``, so an interrupted run never leaves a half-written file, and a
folder that already holds files is refused unless ``force`` is set.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

import bayeshopf
from bayeshopf.diagnostics import arviz_io
from bayeshopf.diagnostics.summaries import Interval, interval
from bayeshopf.errors import DataError, OutputError
from bayeshopf.model.collapsed import CollapsedSpec

SUMMARY = "summary.json"
POSTERIOR = "posterior.nc"
MODEL = "model.json"
FIGURES = "figures"



def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


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
            "(use --force to replace bayeshopf's files in it; other files are kept)"
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


def _draw_figures(figures, stage: Path) -> dict:
    if figures is None:
        return {}
    (stage / FIGURES).mkdir()
    t0 = time.perf_counter()
    figures(stage / FIGURES)
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
        if not out.exists():
            os.replace(stage, out)
        else:
            for src in sorted(stage.rglob("*")):
                dst = out / src.relative_to(stage)
                if src.is_dir():
                    dst.mkdir(exist_ok=True)
                else:
                    os.replace(src, dst)
    except OSError as e:
        raise OutputError(f"{out}: cannot write the fit ({e.strerror or e})") from None
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return out


#: ``model.json``'s ``core`` for fits of :func:`bayeshopf.posterior.fit_hybrid`.
COLLAPSED_CORE = "collapsed"


def summary_hybrid(post, ppc=None, extra: dict | None = None) -> dict:
    """The ``summary.json`` content of a :class:`~bayeshopf.posterior.HybridPosterior`."""
    ppc = post.ppc() if ppc is None else ppc
    diag = post.diagnostics
    errors = {e["name"]: e for e in diag["fit"]["orbit_error"]}
    f = post.features
    freq = diag["fit"].get("frequency")
    recs = []
    for i, name in enumerate(f.names):
        recs.append({
            "file": name, "mu": float(f.mu[i]),
            "branch": "unstable" if f.unstable[i] else "stable",
            "amplitude": float(f.amplitude[i]), "amplitude_sd": float(f.amplitude_sd[i]),
            "n_segments": int(f.n_segments[i]),
            "predicted": ppc.predictive[i].to_json(), "curve": ppc.curve[i].to_json(),
            "inside_ci90": bool(ppc.covered[i]),
            "frequency_hz": float(f.frequency_hz[i]),
            "frequency_predicted": freq[i]["predicted"] if freq else None,
            "frequency_inside_ci90": freq[i]["inside_ci90"] if freq else None,
            "orbit_error": {k: errors[name][k] for k in ("relative", "spread", "ok")},
        })

    def iv(name):
        v = post.interval(name)
        return None if v is None else v.to_json()

    out = {
        "core": COLLAPSED_CORE,
        "mu0": iv("mu0"), "a2": iv("a2"), "a4": iv("a4"), "mu_fold": iv("mu_fold"),
        "w_unfold": iv("w_unfold"),
        "criticality": post.criticality, "unfolding": post.spec.unfolding,
        "mu_label": post.mu_label, "mu_units": post.mu_units,
        "amplitude_units": post.amplitude_units,
        "amplitude_definition": "peak-to-peak of z1 over the orbit, from its K-harmonic "
        "reconstruction",
        "planar_channels": list(post.spec.frame.names),
        "recordings": recs,
        "orbit_error": [errors[n] for n in f.names],
        "ppc": {"amplitudes_inside_ci90": int(ppc.covered.sum()),
                "frequencies_inside_ci90": (sum(e["inside_ci90"] for e in freq)
                                            if freq else None),
                "n_recordings": int(ppc.covered.size),
                "coefficients_inside_ci90": ppc.coeff_coverage},
        "map": {k: _finite_or_none(float(np.asarray(post.map_point.params[k])))
                for k in ("mu0", "a2", "a4", "mu_fold", "w_unfold")
                if k in post.map_point.params},
        "diagnostics": diag,
        "seed": post.seed,
        "settings": dict(post.settings.__dict__),
        "n_draws": int(np.shape(post.samples["mu0"])[0]),
        "timings_s": {k: round(v, 3) for k, v in post.timings.items()},
        "bayeshopf_version": bayeshopf.__version__,
    }
    if extra:
        out.update(extra)
    return out


def save_hybrid(post, out: str | os.PathLike[str], *, force: bool = False, figures=None,
                ppc=None, extra_summary: dict | None = None) -> Path:
    """Write a fit folder atomically.

    ``posterior.nc`` holds the draws by chain of every site, the map's
    coefficients ``beta`` and the frequency's ``gamma`` (one exact draw per
    posterior draw), and, as its ``log_likelihood`` group, each recording's
    ``log p(y_i | y_{−i}, θ)`` (for ``az.loo``); ``model.json`` the model
    structure and the predictive standard errors of a new recording.

    Args:
        post: The :class:`~bayeshopf.posterior.HybridPosterior`.
        out: The output folder.
        force: Replace bayeshopf's files in a non-empty folder (others are kept).
        figures: Optional callable ``figures(folder) -> list[Path]`` that draws
            the figures into a folder (its time is recorded in the summary).
        ppc: The posterior predictive check, if already computed.
        extra_summary: More keys for ``summary.json``.

    Returns:
        The output folder.
    """
    def write(stage: Path) -> None:
        nonlocal post
        post = replace(post, timings={**post.timings, **_draw_figures(figures, stage)})
        _write_json(summary_hybrid(post, ppc, extra_summary), stage / SUMMARY)
        model = {"core": COLLAPSED_CORE, "spec": post.spec.to_dict(),
                 "predictive_se": np.median(post.features.coeffs_se, axis=0).tolist(),
                 "predictive_omega_se": float(np.median(post.features.omega_se)),
                 "extrapolation": _extrapolation_data(post),
                 "seed": post.seed}
        _write_json(model, stage / MODEL)
        chains = {k: v for k, v in post.run.chains.items() if not k.startswith("marginal")}
        n_chain, n_draw = next(iter(chains.values())).shape[:2]
        chains["beta"] = post.run.betas.reshape((n_chain, n_draw) + post.run.betas.shape[1:])
        if post.run.gammas is not None:
            chains["gamma"] = post.run.gammas.reshape((n_chain, n_draw) + post.run.gammas.shape[1:])
        idata = arviz_io.chains_to_inference_data(
            chains,
            log_likelihood={"y": post.log_likelihood},
            dims={"y": ["recording"], "coeffs": ["recording", "frame_axis", "coefficient"],
                  "coeffs_se": ["recording", "frame_axis", "coefficient"],
                  "mu": ["recording"], "unstable": ["recording"]},
            coords={"recording": list(post.features.names), "frame_axis": ["w1", "w2"]},
            observed={"coeffs": post.features.coeffs},
            constant={"mu": post.features.mu, "unstable": post.features.unstable.astype(int),
                      "coeffs_se": post.features.coeffs_se},
            attrs={"criticality": post.criticality, "seed": post.seed,
                   "bayeshopf_version": bayeshopf.__version__},
        )
        arviz_io.write_netcdf(idata, stage / POSTERIOR)

    return _staged(out, force, write)


def _extrapolation_data(post) -> dict | None:
    """Training μ per branch for the model error away from the recordings, or None if off."""
    if not post.settings.extrapolation:
        return None
    f = post.features
    return {"mu_stable": f.mu[~f.unstable].tolist(), "mu_unstable": f.mu[f.unstable].tolist()}


@dataclass(frozen=True)
class SavedHybrid:
    """A collapsed-core fit read back from its folder.

    Attributes:
        folder: Where it was read from.
        spec: The model structure.
        samples: Posterior draws of every site (``beta``: the map's coefficients).
        summary: The content of ``summary.json``.
        predictive_se: Standard errors of a new recording's coefficients.
        predictive_omega_se: Standard error of a new recording's frequency (rad/s).
        extrapolation: Training μ of each branch (``mu_stable``, ``mu_unstable``)
            for the model error away from the recordings; ``None`` when the fit
            had it off.
    """

    folder: Path
    spec: object
    samples: dict
    summary: dict
    predictive_se: np.ndarray
    predictive_omega_se: float = 0.0
    extrapolation: dict | None = None

    def frequency(self, mu: float, branch: str = "stable", predictive: bool = False
                  ) -> Interval | None:
        """Frequency (Hz) median and 90% interval at μ, or ``None``.

        ``None`` without a frequency model, or where no draw has the branch.
        """
        from bayeshopf import posterior as bp

        if "gamma" not in self.samples:
            return None
        idx = bp.draw_indices(len(self.samples["gamma"]))
        theta = {k: v[idx] for k, v in self.samples.items() if k not in ("beta", "gamma")}
        f = bp.frequency_draws(self.spec, theta, self.samples["gamma"][idx], [mu],
                               bp.branch_sign(branch), predictive=predictive,
                               omega_se=self.predictive_omega_se,
                               seed=int(self.summary.get("seed", 0)))[:, 0]
        f = f[np.isfinite(f)]
        return interval(f) if f.size else None

    def _draws(self, mu: float, branch: str, predictive: bool) -> np.ndarray:
        from bayeshopf import posterior as bp

        idx = bp.draw_indices(len(self.samples["beta"]))   # the draws the summary used
        s = {k: v[idx] for k, v in self.samples.items()}
        theta = {k: v for k, v in s.items() if k not in ("beta", "gamma")}
        c = bp.orbit_coefficients(self.spec, theta, s["beta"], [mu], bp.branch_sign(branch))
        if predictive:
            if self.extrapolation is not None:
                c = bp.scale_orbits(c, bp.extrapolation_factor(
                    [mu], self.extrapolation[f"mu_{branch}"], self.spec.mu_span, c.shape[0],
                    int(self.summary.get("seed", 0))))
            rng = np.random.default_rng(int(self.summary.get("seed", 0)))
            sd = bp.noise_sd(c, s["sigma"], s["sigma_rel"], self.predictive_se)
            c = c + sd * rng.standard_normal(c.shape)
        return bp.amplitude_of(self.spec, c)[:, 0]

    def predict(self, mu: float, branch: str = "stable", predictive: bool = False) -> Interval:
        """Amplitude median and 90% interval at μ on ``branch``.

        Raises:
            DataError: When the branch does not exist at μ in any posterior draw.
        """
        draws = self._draws(mu, branch, predictive)
        if not np.isfinite(draws).any():
            raise DataError(
                f"--mu {mu:g}: the {branch} branch does not exist there in any posterior "
                f"draw (Hopf point μ0 ≈ {np.median(self.samples['mu0']):.4g}"
                + (f", fold ≈ {self.summary['mu_fold']['median']:.4g}"
                   if self.summary.get("mu_fold") else "") + ")")
        return interval(draws)

    def p_exists(self, mu: float, branch: str = "stable") -> float:
        """Posterior probability that ``branch`` exists at μ."""
        return float(np.isfinite(self._draws(mu, branch, False)).mean())


def load_fit(folder: str | os.PathLike[str]) -> SavedHybrid:
    """Read a fit folder written by :func:`save_hybrid`.

    Raises:
        DataError: When a file is missing or unreadable.
    """
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
                       float(model.get("predictive_omega_se", 0.0)), model.get("extrapolation"))
