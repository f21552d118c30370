"""The front door: fit recordings, get a typed, immutable :class:`Fit`, save it, load it.

>>> import bayeshopf as bh
>>> recordings = bh.read_recordings("my_rig/")                  # doctest: +SKIP
>>> fit = bh.fit(recordings, seed=0)                            # doctest: +SKIP
>>> fit.interval("mu0"), fit.diagnostics.ok                     # doctest: +SKIP
>>> fit.predict([15.0, 16.0], branch="stable", ci=0.9)          # doctest: +SKIP
>>> fit.save("fit_out/"); bh.load_fit("fit_out/")               # doctest: +SKIP

:func:`fit` runs the whole pipeline (features, MAP, posterior draws, checks) as
:func:`bayeshopf.posterior.fit_hybrid` does, after giving JAX and the linear
algebra libraries their CPU settings (:func:`~bayeshopf.inference.cache.configure_xla_cpu`),
so user code does not have to. :class:`Fit` wraps the
:class:`~bayeshopf.posterior.HybridPosterior`, in the way diffrax's
``diffeqsolve`` returns a ``Solution``: every prediction goes through the
posterior's one predictive path (:mod:`bayeshopf.predictive`), whether the fit
was just computed or read back from its folder.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from bayeshopf.diagnostics.checks import Diagnostics
from bayeshopf.diagnostics.summaries import CI, Interval
from bayeshopf.errors import FitError
from bayeshopf.inference.cache import configure_xla_cpu
from bayeshopf.inference.collapsed import CollapsedSettings as Settings

__all__ = ["Fit", "Settings", "fit", "load_fit"]

#: Share of posterior draws in which a branch must exist for :meth:`Fit.predict` to report it.
MIN_P_EXISTS = 0.5
#: Criticalities :func:`fit` accepts (``"auto"``: both fitted, leave-one-out chooses).
CRITICALITIES = ("subcritical", "supercritical", "auto")


@dataclass(frozen=True)
class Fit:
    """A fitted Bayesian hybrid model (immutable).

    Every attribute of its :attr:`posterior` is also one of the fit's: the
    record (``criticality``, ``settings``, ``seed``, ``samples``, ``mu_label``,
    ``mu_units``, ``amplitude_units``, ``spec``, ``features``) and the building
    blocks of prediction (``amplitude``, ``orbits``, ``frequency``,
    ``time_series``, …), so the package's functions that take a
    :class:`~bayeshopf.posterior.HybridPosterior` take a :class:`Fit` too.

    Attributes:
        posterior: The fitted :class:`~bayeshopf.posterior.HybridPosterior`:
            draws, features, MAP point, settings and the building blocks of
            every prediction.
        evidence: With ``criticality="auto"``, the leave-one-out comparison of
            the two normal forms (:func:`~bayeshopf.posterior.fit_auto`);
            otherwise ``None``.
        folder: The folder it was saved to or read from, or ``None``.
    """

    posterior: object
    evidence: Mapping | None = None
    folder: Path | None = None

    def __getattr__(self, name: str):
        # the posterior's building blocks (spec, features, amplitude, orbits, …), so
        # that every function taking a HybridPosterior takes a Fit as well
        if name.startswith("_") or name == "posterior":
            raise AttributeError(name)
        try:
            return getattr(self.posterior, name)
        except AttributeError:
            raise AttributeError(f"'Fit' object has no attribute {name!r}") from None

    # ------------------------------------------------------------------ record
    @cached_property
    def diagnostics(self) -> Diagnostics:
        """Every check of the fit, each with a status (:class:`Diagnostics`)."""
        return Diagnostics.from_dict(self.posterior.diagnostics)

    def interval(self, name: str, ci: float = CI) -> Interval | None:
        """Median and ``ci`` interval of a scalar site (``"mu0"``, ``"mu_fold"``, ``"a2"``, …).

        ``None`` for a site the model does not have (the fold of a
        supercritical fit).
        """
        return self.posterior.interval(name, ci)

    # -------------------------------------------------------------- prediction
    def predict(self, mu, branch: str = "stable", *, ci: float = CI, predictive: bool = True,
                min_p_exists: float = MIN_P_EXISTS):
        """Amplitude (and frequency) of the LCO at each μ: median and ``ci`` interval.

        ``predictive=True`` (default) describes a new recording: the orbit's
        posterior plus the model discrepancy and the measurement error;
        ``False`` the model's curve alone. Where the branch exists in fewer
        than ``min_p_exists`` of the draws, the values are ``nan`` (the branch
        is not there; ``p_exists`` says how sure that is).

        Args:
            mu: One value or a sequence of values of μ.
            branch: ``"stable"`` or ``"unstable"``.
            ci: Mass of the equal-tailed interval.
            predictive: A new recording (``True``) or the model's curve.
            min_p_exists: Share of draws in which the branch must exist.

        Returns:
            An :class:`xarray.Dataset` over ``mu`` with ``amplitude``,
            ``amplitude_lo``, ``amplitude_hi`` and ``p_exists``, and with the
            frequency model also ``frequency``, ``frequency_lo``,
            ``frequency_hi`` (Hz); its ``attrs`` say the branch, ``ci``, units
            and whether it is predictive.

        Raises:
            FitError: For a branch other than ``"stable"``/``"unstable"``, a
                ``ci`` outside (0, 1) or a non-finite μ.
        """
        import xarray as xr

        if not 0.0 < ci < 1.0:
            raise FitError(f"ci must lie strictly between 0 and 1; got {ci!r}")
        mu = np.atleast_1d(np.asarray(mu, dtype=float))
        if mu.ndim != 1 or not np.all(np.isfinite(mu)):
            raise FitError(f"mu must be finite numbers; got {mu.tolist()!r}")
        post = self.posterior
        amp = post.amplitude(mu, branch, predictive=predictive)
        p = np.isfinite(amp).mean(axis=0)
        data = {"p_exists": ("mu", p)}
        data.update(_quantiles("amplitude", amp, p, ci, min_p_exists))
        if post.has_frequency:
            data.update(_quantiles("frequency", post.frequency(mu, branch, predictive), p, ci,
                                   min_p_exists))
        ds = xr.Dataset(data, coords={"mu": mu})
        ds["mu"].attrs.update(long_name=post.mu_label, units=post.mu_units)
        for v in ("amplitude", "amplitude_lo", "amplitude_hi"):
            ds[v].attrs["units"] = post.amplitude_units
        for v in ("frequency", "frequency_lo", "frequency_hi"):
            if v in ds:
                ds[v].attrs["units"] = "Hz"
        ds.attrs.update(branch=branch, ci=ci, predictive=int(predictive),
                        min_p_exists=min_p_exists,
                        amplitude="peak-to-peak of " + post.spec.frame.names[0])
        return ds

    def diagram(self, mu=None, ci: float = CI):
        """The bifurcation diagram with its bands (``HybridPosterior.diagram``)."""
        return self.posterior.diagram(mu, ci)

    def ppc(self, ci: float = CI):
        """The posterior predictive check of the recordings (``HybridPosterior.ppc``)."""
        return self.posterior.ppc(ci)

    def to_inference_data(self):
        """The draws, log-likelihood, predictive and data as ArviZ ``InferenceData``."""
        return self.posterior.to_inference_data()

    @cached_property
    def plot(self):
        """Figures of this fit drawn into a user's axes (``bayeshopf.plotting.fit.FitPlots``)."""
        from bayeshopf.plotting.fit import FitPlots

        return FitPlots(self.posterior)

    # ------------------------------------------------------------------ files
    def save(self, folder: str | os.PathLike[str], *, force: bool = False, ci: float = CI,
             figures: bool = True, recordings=None) -> Fit:
        """Write the fit folder (``summary.json``, ``model.json``, ``posterior.nc``, figures).

        Written atomically (:func:`~bayeshopf.fit_folder.save_hybrid`); the figures
        that need the raw records are drawn only with ``recordings``.

        Args:
            folder: The output folder (new, or empty unless ``force``).
            force: Replace bayeshopf's files in a non-empty folder.
            ci: Mass of the summary's intervals.
            figures: Draw the standard figures into ``folder/figures``.
            recordings: The recordings fitted, for the phase portraits and time series.

        Returns:
            The same fit, with ``folder`` set.
        """
        from bayeshopf.fit_folder import save_hybrid

        draw = None
        if figures:
            from bayeshopf.plotting import plot_all

            def draw(figures_folder: Path) -> list[Path]:
                return plot_all(self.posterior, recordings, figures_folder, ci=ci)

        out = save_hybrid(self.posterior, folder, force=force, figures=draw, ci=ci)
        return Fit(self.posterior, self.evidence, Path(out))


def _quantiles(name: str, draws: np.ndarray, p_exists: np.ndarray, ci: float,
               min_p_exists: float) -> dict:
    """Median and ``ci`` interval per μ over the draws where the branch exists."""
    q = np.full((3, draws.shape[1]), np.nan)
    for j in np.flatnonzero(p_exists >= max(min_p_exists, 1e-12)):
        col = draws[:, j][np.isfinite(draws[:, j])]
        q[:, j] = np.quantile(col, [0.5, 0.5 - ci / 2, 0.5 + ci / 2])
    return {name: ("mu", q[0]), f"{name}_lo": ("mu", q[1]), f"{name}_hi": ("mu", q[2])}


def fit(recordings, settings: Settings | None = None, *, criticality: str = "subcritical",
        seed: int = 0, progress: bool = True, keep_unconverged: bool = False) -> Fit:
    """Fit the Bayesian hybrid normal-form model to LCO recordings.

    Stages: phase-aligned harmonic features, a deterministic start and the MAP,
    importance sampling (NUTS where its check fails; or NUTS, or SVI) on the normal
    form's parameters with the map and the model discrepancy integrated out,
    one exact map draw per posterior draw, and the checks
    (:func:`~bayeshopf.posterior.fit_hybrid`). JAX's CPU settings are made here
    (:func:`~bayeshopf.inference.cache.configure_xla_cpu`); they take effect
    when this is the process's first JAX computation.

    Args:
        recordings: A :class:`~bayeshopf.data.recording.RecordingSet`
            (:func:`bayeshopf.read_recordings`), or features already extracted.
        settings: :class:`Settings` (defaults when ``None``).
        criticality: ``"subcritical"`` (two branches meeting at a fold),
            ``"supercritical"``, or ``"auto"``: both fitted and compared by
            leave-one-out (:func:`~bayeshopf.posterior.fit_auto`).
        seed: Seed of every random choice.
        progress: Say on stderr which stage is running.
        keep_unconverged: Keep the controlled recordings on which the CBC
            controller did not converge (:func:`bayeshopf.data.unconverged`;
            rigs whose description names the convergence fields). By default
            they are left out with a warning each: such a recording is not an
            orbit of the uncontrolled system.

    Returns:
        The :class:`Fit`.

    Raises:
        FitError: For an unknown ``criticality`` or settings of the wrong type.
    """
    if criticality not in CRITICALITIES:
        raise FitError(f"criticality must be one of {', '.join(CRITICALITIES)}; "
                       f"got {criticality!r}")
    if settings is not None and not isinstance(settings, Settings):
        raise FitError(f"settings must be bayeshopf.Settings; got {type(settings).__name__}")
    configure_xla_cpu()
    from bayeshopf.data.recording import RecordingSet
    from bayeshopf.data.screening import converged_only, convergence_report
    from bayeshopf.posterior import fit_auto, fit_hybrid

    if isinstance(recordings, RecordingSet) and not keep_unconverged:
        for line in convergence_report(recordings):
            warnings.warn(f"{line}; left out (keep_unconverged=True keeps it)", stacklevel=2)
        recordings = converged_only(recordings)

    if criticality == "auto":
        post, evidence = fit_auto(recordings, seed=seed, settings=settings, progress=progress)
        return Fit(post, evidence)
    return Fit(fit_hybrid(recordings, criticality, seed=seed, settings=settings,
                          progress=progress))


def load_fit(folder: str | os.PathLike[str]) -> Fit:
    """Read a fit folder written by :meth:`Fit.save` or ``bayeshopf fit``, without refitting.

    Raises:
        DataError: When a file is missing or unreadable, or the folder was
            written by a bayeshopf too old to rebuild its fit.
    """
    from bayeshopf.fit_folder import load_fit as read_folder

    saved = read_folder(folder)
    return Fit(saved.posterior, None, saved.folder)
