"""The whole job in one call: recordings → features → MAP → SVI → posterior.

>>> import bayeshopf as bh
>>> rs, truth = bh.data.synthetic.demo_system(seed=0)       # doctest: +SKIP
>>> fit = bh.fit(rs, criticality="subcritical", seed=0)     # doctest: +SKIP
>>> fit.interval("mu0")                                     # doctest: +SKIP
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import jax
import numpy as np
from scipy.special import logsumexp

from bayeshopf.data.recording import RecordingSet
from bayeshopf.diagnostics.bifurcation import BifurcationDiagram, bifurcation_diagram
from bayeshopf.diagnostics.comparison import (
    compare_criticality,
    held_out_log_likelihood,
    pointwise_log_likelihood,
)
from bayeshopf.diagnostics.ppc import PosteriorPredictiveCheck, posterior_predictive_check
from bayeshopf.diagnostics.predictive import amplitude_draws, predictive_amplitude_draws
from bayeshopf.diagnostics.summaries import Interval, interval
from bayeshopf.errors import FitError
from bayeshopf.features.orbits import DEFAULT_N_HARMONICS, OrbitFeatures, extract_features
from bayeshopf.inference.cache import enable_compilation_cache, release_compiled
from bayeshopf.inference.init import build_spec, initial_values
from bayeshopf.inference.map import fit_map
from bayeshopf.inference.multistart import mix, stacking_weights
from bayeshopf.inference.results import MapResult, SviResult
from bayeshopf.inference.svi import fit_svi
from bayeshopf.model import normal_form
from bayeshopf.model.hybrid import ModelSpec, branch_signs
from bayeshopf.model.probabilistic import hopf_model, model_arguments


@dataclass(frozen=True)
class FitSettings:
    """Settings of :func:`fit` (the defaults are the documented ones).

    Attributes:
        n_h: Harmonics of the R(θ) features.
        adam_steps: MAP Adam iterations.
        lbfgs_steps: MAP L-BFGS iterations.
        svi_steps: SVI iterations from the MAP point.
        num_particles: ELBO particles per SVI step.
        n_draws: Posterior draws kept.
        guide: Autoguide, ``"lowrank"`` (low-rank plus diagonal) or ``"mvn"``
            (full-rank).
        n_starts: MAP starts (different initial MLP weights); SVI runs from
            each and the posteriors are combined by stacking
            (:mod:`bayeshopf.inference.multistart`).
        nn_width: Neurons per hidden layer of the map's MLP.
        nn_depth: Hidden layers of the map's MLP.
    """

    n_h: int = DEFAULT_N_HARMONICS
    adam_steps: int = 800
    lbfgs_steps: int = 300
    svi_steps: int = 1500
    num_particles: int = 2
    n_draws: int = 1000
    guide: str = "lowrank"
    n_starts: int = 4
    nn_width: int = 10
    nn_depth: int = 2

    @classmethod
    def fast(cls) -> FitSettings:
        """Short runs for CI and smoke tests (intervals less converged)."""
        return cls(adam_steps=500, lbfgs_steps=150, svi_steps=600, n_draws=400, n_starts=1)


@dataclass(frozen=True)
class StartSummary:
    """One start of a multi-start fit (immutable).

    Attributes:
        map_loss: Negative log joint at the start's MAP point.
        weight: Its stacking weight in the posterior.
        lpd: Its in-sample log pointwise predictive density,
            ``Σ_i log E_q p(Φ(R_i) | θ)``.
        map_values: MAP values of ``mu0``, ``a2`` and (subcritical) ``mu_fold``.
    """

    map_loss: float
    weight: float
    lpd: float
    map_values: dict


@dataclass(frozen=True)
class HopfFit:
    """A fitted Bayesian hybrid model (immutable).

    Attributes:
        spec: Model structure and prior constants.
        features: The training features.
        map: The MAP fit.
        svi: The SVI fit, with posterior draws in ``svi.samples``.
        settings: Settings used.
        seed: Seed used.
        mu_label: Name of μ (e.g. "airspeed").
        mu_units: Unit of μ.
        amplitude_units: Unit of the amplitude (that of z1).
        timings: Seconds per stage.
        starts: One :class:`StartSummary` per MAP start that converged.
    """

    spec: ModelSpec
    features: OrbitFeatures
    map: MapResult
    svi: SviResult
    settings: FitSettings
    seed: int
    mu_label: str
    mu_units: str
    amplitude_units: str
    timings: dict = field(default_factory=dict, compare=False)
    starts: tuple = ()

    @property
    def samples(self) -> dict:
        """Posterior draws of every site."""
        return self.svi.samples

    @property
    def criticality(self) -> str:
        """``"subcritical"`` or ``"supercritical"``."""
        return self.spec.criticality

    def interval(self, name: str) -> Interval | None:
        """Median and 90% interval of ``mu0``, ``a2``, ``a4`` or ``mu_fold`` (None if absent).

        ``a4`` is a free site only in the supercritical gauge (``a2 = −1``,
        :mod:`~bayeshopf.model.normal_form`); ``mu_fold`` only in the
        subcritical one.
        """
        if name == "mu_fold":
            if self.criticality != "subcritical":
                return None
            return interval(normal_form.fold_point(self.samples["mu0"], self.samples["a2"]))
        if name not in self.samples:
            return None
        return interval(self.samples[name])

    def amplitude(self, mu, branch: str = "stable", predictive: bool = False) -> np.ndarray:
        """Amplitude draws at μ on a branch, shape ``(n_draws, n_mu)``.

        ``predictive=False`` gives the model curve; ``True`` a new recording's
        amplitude (with the scatter σ).
        """
        return predict_amplitude(self.samples, self.spec, mu, branch, predictive, seed=self.seed)

    def diagram(self, mu=None) -> BifurcationDiagram:
        """The posterior bifurcation diagram."""
        return bifurcation_diagram(self.samples, self.spec, mu, seed=self.seed)

    def ppc(self) -> PosteriorPredictiveCheck:
        """Posterior predictive check of the training recordings."""
        return posterior_predictive_check(self.samples, self.spec, self.features)


@dataclass(frozen=True)
class PointFit:
    """A point-estimate fit: MAP, or maximum likelihood as in the paper (immutable).

    It has no posterior. Its ``samples`` are the optimum as a single draw, so
    the prediction functions apply; :meth:`plugin_samples` repeats it to give
    the plug-in band (fixed parameters, only the fitted scatter σ random).

    Attributes:
        spec: Model structure.
        features: The training features.
        map: The optimisation result.
        regularised: ``True`` for MAP (with the priors), ``False`` for maximum
            likelihood (the paper's approach).
        settings: Settings used.
        seed: Seed used.
        timings: Seconds per stage.
    """

    spec: ModelSpec
    features: OrbitFeatures
    map: MapResult
    regularised: bool
    settings: FitSettings
    seed: int
    timings: dict = field(default_factory=dict, compare=False)

    @property
    def samples(self) -> dict:
        """The optimum as one draw (every site with a leading axis of length 1)."""
        return {k: np.asarray(v)[None] for k, v in self.map.params.items()}

    def plugin_samples(self, n: int = 300) -> dict:
        """The optimum repeated ``n`` times (for plug-in predictive bands)."""
        return {k: np.repeat(v, n, axis=0) for k, v in self.samples.items()}

    def value(self, name: str) -> float:
        """Point value of ``mu0``, ``a2`` or ``mu_fold`` (nan when absent)."""
        if name == "mu_fold":
            if self.spec.criticality != "subcritical":
                return float("nan")
            return float(normal_form.fold_point(self.map.params["mu0"], self.map.params["a2"]))
        return float(self.map.params[name])

    def amplitude(self, mu, branch: str = "stable", predictive: bool = False) -> np.ndarray:
        """Amplitude at μ: the curve ``(1, n_mu)``, or plug-in predictive draws ``(300, n_mu)``."""
        samples = self.plugin_samples() if predictive else self.samples
        return predict_amplitude(samples, self.spec, mu, branch, predictive, seed=self.seed)


def _sign(branch: str) -> int:
    if branch not in ("stable", "unstable"):
        raise FitError(f"branch must be 'stable' or 'unstable'; got {branch!r}")
    return normal_form.STABLE if branch == "stable" else normal_form.UNSTABLE


def predict_amplitude(samples, spec, mu, branch="stable", predictive=False, *, seed=0):
    """Amplitude draws ``(n_draws, n_mu)`` at μ on ``branch`` (see :meth:`HopfFit.amplitude`)."""
    sign = _sign(branch)
    if branch == "unstable" and spec.criticality != "subcritical":
        raise FitError("a supercritical model has no unstable branch; got branch 'unstable'")
    if predictive:
        return predictive_amplitude_draws(samples, spec, mu, sign, jax.random.PRNGKey(seed))
    return amplitude_draws(samples, spec, mu, sign)


@dataclass(frozen=True)
class _Prepared:
    features: OrbitFeatures
    spec: ModelSpec
    model_kwargs: dict
    mu_label: str
    mu_units: str
    amplitude_units: str


def _prepare(recordings, criticality: str, settings: FitSettings,
             single_branch: bool = False) -> _Prepared:
    """Features, model structure and the model's data arguments."""
    if isinstance(recordings, RecordingSet):
        features = extract_features(recordings, n_h=settings.n_h)
        labels = recordings.mu_label, recordings.mu_units, recordings.units[0]
    else:
        features = recordings
        labels = "mu", "", features.frame.units[0]
    if single_branch:
        features = replace(features, unstable=np.zeros_like(features.unstable))
    spec = build_spec(
        features, criticality, nn_width=settings.nn_width, nn_depth=settings.nn_depth,
        mu_label=labels[0], mu_units=labels[1],
    )
    kwargs = model_arguments(spec, features)
    return _Prepared(features, spec, kwargs, *labels)


def fit(
    recordings: RecordingSet | OrbitFeatures,
    criticality: str = "subcritical",
    *,
    seed: int = 0,
    settings: FitSettings | None = None,
    progress: bool = True,
    compilation_cache: bool = True,
    single_branch: bool = False,
) -> HopfFit:
    """Fit the Bayesian hybrid normal-form model to LCO recordings.

    Stages: Fourier features of every recording; MAP by Adam then L-BFGS from
    data-driven starting values of the normal form and ``settings.n_starts``
    random initial MLP weights; from each MAP point, SVI with a low-rank
    multivariate-normal autoguide; the approximations combined by stacking
    (:mod:`bayeshopf.inference.multistart`) into ``settings.n_draws``
    posterior draws. ``map`` is the start with the lowest negative log joint.

    Args:
        recordings: The recordings, or features already extracted from them.
        criticality: ``"subcritical"`` or ``"supercritical"``.
        seed: Seed of every random choice (results are reproducible from it).
        settings: Step counts and model sizes (:class:`FitSettings`).
        progress: Show progress bars.
        compilation_cache: Use JAX's persistent compilation cache.
        single_branch: Ignore the branch labels: every recording is taken to
            lie on the one LCO branch of a supercritical model (used to test
            criticality from the orbits alone, see :func:`fit_auto`).

    Returns:
        A :class:`HopfFit`.
    """
    settings = settings or FitSettings()
    if compilation_cache:
        enable_compilation_cache()
    release_compiled()
    timings = {}
    t0 = time.perf_counter()
    prep = _prepare(recordings, criticality, settings, single_branch)
    spec, features, kwargs = prep.spec, prep.features, prep.model_kwargs
    timings["features"] = time.perf_counter() - t0

    k_map, k_svi = jax.random.split(jax.random.PRNGKey(seed))
    init = initial_values(features, spec)
    maps, svis = [], []
    timings["map"] = timings["svi"] = 0.0
    for j in range(settings.n_starts):
        t0 = time.perf_counter()
        # start 0 keeps the single-start keys, so n_starts=1 is the plain fit
        key_j = (k_map, k_svi) if j == 0 else (
            jax.random.fold_in(k_map, j), jax.random.fold_in(k_svi, j))
        m = fit_map(
            hopf_model, kwargs, init, key=key_j[0],
            adam_steps=settings.adam_steps, lbfgs_steps=settings.lbfgs_steps, progress=progress,
        )
        timings["map"] += time.perf_counter() - t0
        if not np.isfinite(m.losses[-1]):
            continue
        t0 = time.perf_counter()
        svis.append(fit_svi(
            hopf_model, kwargs, m, key=key_j[1], steps=settings.svi_steps,
            num_particles=settings.num_particles, guide=settings.guide,
            n_draws=settings.n_draws, progress=progress,
        ))
        maps.append(m)
        timings["svi"] += time.perf_counter() - t0
    if not maps:
        raise FitError(
            f"MAP did not converge: the loss is not finite from any of {settings.n_starts} starts"
        )
    t0 = time.perf_counter()
    log_liks = [pointwise_log_likelihood(r.samples, features) for r in svis]
    weights = stacking_weights(log_liks)
    svi_result = mix(svis, weights, jax.random.fold_in(k_svi, settings.n_starts))
    map_result = maps[int(np.argmin([m.losses[-1] for m in maps]))]
    starts = tuple(
        StartSummary(map_loss=float(m.losses[-1]), weight=float(w),
                     lpd=float(np.sum(logsumexp(ll, axis=0) - np.log(ll.shape[0]))),
                     map_values={k: float(m.params[k]) for k in ("mu0", "a2", "mu_fold")
                                 if k in m.params})
        for m, w, ll in zip(maps, weights, log_liks, strict=True)
    )
    timings["stacking"] = time.perf_counter() - t0
    return HopfFit(
        spec=spec, features=features, map=map_result, svi=svi_result, settings=settings,
        seed=seed, mu_label=prep.mu_label, mu_units=prep.mu_units,
        amplitude_units=prep.amplitude_units, timings=timings, starts=starts,
    )


def fit_point(
    recordings: RecordingSet | OrbitFeatures,
    criticality: str = "subcritical",
    *,
    regularised: bool = True,
    seed: int = 0,
    settings: FitSettings | None = None,
    progress: bool = True,
    compilation_cache: bool = True,
) -> PointFit:
    """Point-estimate fit: the MAP stage of :func:`fit` alone, with or without priors.

    ``regularised=False`` maximises the likelihood alone, which is the paper's
    fit (least squares of the Fourier coefficients, no priors, no uncertainty);
    it is the baseline against which the Bayesian fit's robustness is measured.

    Args:
        recordings: The recordings, or features already extracted from them.
        criticality: ``"subcritical"`` or ``"supercritical"``.
        regularised: Keep the priors (MAP) or drop them (maximum likelihood).
        seed: Seed.
        settings: Step counts and model sizes.
        progress: Show progress bars.
        compilation_cache: Use JAX's persistent compilation cache.

    Returns:
        A :class:`PointFit`.
    """
    settings = settings or FitSettings()
    if compilation_cache:
        enable_compilation_cache()
    release_compiled()
    t0 = time.perf_counter()
    prep = _prepare(recordings, criticality, settings)
    k_map, _ = jax.random.split(jax.random.PRNGKey(seed))
    map_result = fit_map(
        hopf_model, prep.model_kwargs, initial_values(prep.features, prep.spec), key=k_map,
        adam_steps=settings.adam_steps, lbfgs_steps=settings.lbfgs_steps, progress=progress,
        regularised=regularised,
    )
    if not np.isfinite(map_result.losses[-1]):
        raise FitError("the point fit did not converge: the loss is not finite")
    return PointFit(
        spec=prep.spec, features=prep.features, map=map_result, regularised=regularised,
        settings=settings, seed=seed, timings={"map": time.perf_counter() - t0},
    )


def with_timings(fit_: HopfFit, **extra: float) -> HopfFit:
    """A copy of ``fit_`` with more stage timings recorded."""
    return replace(fit_, timings={**fit_.timings, **extra})


def loo_refit(fits: dict, *, seed: int = 0, settings: FitSettings | None = None):
    """The refit callback of an exact leave-one-out comparison.

    Args:
        fits: Criticality → :class:`HopfFit` on the same recordings.
        seed: Seed of every refit.
        settings: Settings of every refit.

    Returns:
        ``(criticality, i) ↦ log p(Φ(R_i) | θ_s^(−i))``: the model refitted without
        recording i, in the full data's frame (so that the densities of all
        recordings and both models are in the same units), and its draws'
        log-likelihood of recording i (:func:`held_out_log_likelihood`). The
        supercritical model places every recording on its one branch.
    """

    def refit(criticality: str, i: int) -> np.ndarray:
        features = fits[criticality].features
        keep = [j for j in range(features.n_recordings) if j != i]
        single = criticality == "supercritical"
        f = fit(features.subset(keep), criticality, seed=seed, settings=settings,
                progress=False, single_branch=single)
        sign = 1.0 if single else float(branch_signs(features.unstable)[i])
        return held_out_log_likelihood(f.samples, f.spec, features, i, sign)

    return refit


def fit_auto(
    recordings: RecordingSet,
    *,
    seed: int = 0,
    settings: FitSettings | None = None,
    progress: bool = True,
    exact_loo: bool = False,
) -> tuple[HopfFit, dict]:
    """Fit with the criticality decided from the data by leave-one-out.

    Both normal forms are fitted to the same Fourier coefficients and compared
    by their expected log predictive density (ArviZ ``compare``). The
    supercritical model has one LCO per μ, so it ignores the branch labels and
    must explain every orbit, labelled stable or unstable, as that one LCO; the
    subcritical model places the unstable recordings on its inner branch. Two
    recordings of different size at the same μ, or amplitudes that do not grow
    from zero at a Hopf point below every recording, are what a supercritical
    model cannot fit, and the ELPD says by how much.

    The ELPD can fail to say it: the supercritical model may take two orbits at
    one μ for scatter, and its wider predictive then does as well on held-out
    recordings (on the wind-tunnel rig, exact leave-one-out puts the two models
    0.3 ± 7.7 apart; ``benchmarks/criticality.md``). So two recordings at one μ
    whose amplitudes differ by at least
    :data:`~bayeshopf.diagnostics.comparison.DISTINCT_ORBITS` times their spread
    over segments decide for the subcritical model, whatever the ELPD
    (:func:`~bayeshopf.diagnostics.comparison.compare_criticality`).

    Args:
        recordings: The recordings.
        seed: Seed of every fit.
        settings: Settings of every fit.
        progress: Show progress bars.
        exact_loo: Refit each model without every recording whose PSIS Pareto k
            exceeds 0.7 (ArviZ ``reloo``), in the full data's frame, and use the
            exact leave-one-out density there. With few recordings PSIS often
            fails (on the rig, k up to 2.1), and each refit costs a fit.

    Returns:
        ``(fit, evidence)``: the preferred fit, and ``evidence`` with each
        model's ELPD, its standard error, the ELPD difference with its standard
        error (``dse``), the stacking weights, the Pareto k diagnostics, the
        refitted recordings, the coexisting orbits, the ``preferred``
        criticality, the ELPD's own choice (``elpd_preferred``) and which rule
        decided (``decided_by``).
    """
    fits = {
        c: fit(recordings, c, seed=seed, settings=settings, progress=progress,
               single_branch=c == "supercritical")
        for c in ("subcritical", "supercritical")
    }
    refit = loo_refit(fits, seed=seed, settings=settings) if exact_loo else None
    evidence = compare_criticality(fits, refit)
    evidence["branch_labels"] = (
        "used by the subcritical model only" if recordings.is_unstable.any() else "all stable"
    )
    return fits[evidence["preferred"]], evidence
