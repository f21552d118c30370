"""The whole job on the collapsed core: recordings → harmonics → MAP → draws → posterior.

>>> import bayeshopf.posterior as bp
>>> post = bp.fit_hybrid(recordings, "subcritical", seed=0)    # doctest: +SKIP
>>> post.interval("mu0"), post.diagnostics["warnings"]           # doctest: +SKIP

:func:`fit_hybrid` returns a :class:`~bayeshopf.hybrid_posterior.HybridPosterior`:
the posterior draws of the normal form and the hyperparameters, one exact draw
of the map per draw, the convergence diagnostics, and methods for orbits,
amplitudes, the bifurcation diagram, the posterior predictive check and each
recording's orbit error. :func:`fit_auto` fits both normal forms and lets
leave-one-out choose. The record (:mod:`bayeshopf.hybrid_posterior`), its checks
(:mod:`bayeshopf.diagnostics.fit_checks`) and the prediction path
(:mod:`bayeshopf.predictive`) are re-exported here under their earlier names.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace

import numpy as np

from bayeshopf._x64 import ensure_x64
from bayeshopf.data.recording import RecordingSet
from bayeshopf.diagnostics.fit_checks import (  # noqa: F401 (re-exported)
    ORBIT_ERROR_MAX,
    ORBIT_SPREAD_FACTOR,
    SIGMA_ORBIT_FRACTION,
    SIGMA_RATIO_MAX,
    SIGMA_REL_MAX,
    diagnose,
    harmonic_name,
    orbit_error_parts,
)
from bayeshopf.features.harmonics import HarmonicFeatures, extract_harmonics
from bayeshopf.hybrid_posterior import (  # noqa: F401 (re-exported)
    N_PHI,
    RIG,
    HybridPosterior,
    log_likelihood_program,
)
from bayeshopf.inference import collapsed as ci
from bayeshopf.inference.cache import (
    enable_compilation_cache,
    release_compiled,
)
from bayeshopf.model import collapsed as cm
from bayeshopf.model.normal_form import branch_sign  # noqa: F401 (re-exported)

#: :func:`log_likelihood_program` under its earlier name.
_log_likelihood_program = log_likelihood_program


def log_likelihood_draws(spec: cm.CollapsedSpec, theta: dict,
                         features: HarmonicFeatures) -> np.ndarray:
    """``log p(y_i | y_{−i}, θ_s)`` for draws θ_s of a model ``spec`` and features, ``(n, n_rec)``.

    ``spec`` may be that of a fit without some of the recordings (an exact
    leave-one-out refit): the map is then conditioned on the others only.
    ``nan`` where a draw has no LCO on a recording's branch.
    """
    return np.asarray(log_likelihood_program(spec, theta, features))


def _features(recordings: RecordingSet | HarmonicFeatures, settings: ci.CollapsedSettings
              ) -> tuple[HarmonicFeatures, tuple[str, str, str]]:
    """The features of the recordings and the labels ``(μ name, μ unit, amplitude unit)``."""
    if isinstance(recordings, RecordingSet):
        features = extract_harmonics(recordings, n_harmonics=settings.n_harmonics,
                                     segment_periods=settings.segment_periods)
        return features, (recordings.mu_label, recordings.mu_units, recordings.units[0])
    return recordings, ("mu", "", recordings.frame.units[0])


def _fit_features(features: HarmonicFeatures, labels: tuple, criticality: str, seed: int,
                  settings: ci.CollapsedSettings, progress: bool, timings: dict
                  ) -> HybridPosterior:
    t0 = time.perf_counter()
    spec = ci.build_spec(features, criticality, nn_width=settings.nn_width,
                         unfolding=settings.unfolding, mu_label=labels[0], mu_units=labels[1],
                         frequency=settings.frequency, control=settings.control,
                         discrepancy=settings.discrepancy,
                         discrepancy_floor=settings.discrepancy_floor,
                         nn_seed=settings.nn_seed,
                         nn_mu_scale=settings.nn_mu_scale)
    inputs = ci.model_arguments(spec, features)
    timings["features"] = timings.get("features", 0.0) + time.perf_counter() - t0
    t0 = time.perf_counter()
    if progress:
        print(f"MAP ({criticality}): deterministic start and L-BFGS", file=sys.stderr)
    ci.compile_programs(inputs, settings)     # compiled beside the MAP (an empty cache)
    map_point = ci.fit_map(inputs, max_steps=settings.lbfgs_steps)
    timings["map"] = time.perf_counter() - t0
    run = ci.sample_posterior(inputs, map_point, settings, seed=seed, progress=progress)
    run = with_rig_bifurcations(run, spec, features, settings.mu_discrepancy, seed,
                                settings.mu_discrepancy_floor)
    timings["posterior"] = run.seconds
    post = HybridPosterior(spec, features, map_point, run, settings, seed, *labels,
                           timings=timings)
    t0 = time.perf_counter()
    # filled in place while the record is being built, so that the predicted
    # coefficients cached for the checks serve the caller's ppc() too
    post.diagnostics.update(diagnose(post))
    timings["diagnostics"] = time.perf_counter() - t0
    return post


def with_rig_bifurcations(run: ci.PosteriorRun, spec: cm.CollapsedSpec,
                          features: HarmonicFeatures, kappa: float, seed: int,
                          floor: float = 0.0) -> ci.PosteriorRun:
    """``run`` with the rig's Hopf point and fold, ``mu0_rig`` and ``mu_fold_rig`` (per draw).

    The normal form's points moved by the discrepancy in μ
    (:func:`~bayeshopf.model.bifurcation_shift.shift_draws`, ``κ = kappa``,
    ``φ = floor``, its normal pairs drawn from ``seed``); ``run`` itself without
    the model discrepancy or with ``kappa`` 0.
    """
    if not spec.has_discrepancy or kappa == 0:
        return run
    import jax

    from bayeshopf.model.bifurcation_shift import shift_draws

    samples = run.samples
    theta = {k: v for k, v in samples.items() if not k.startswith("marginal")}
    moved = shift_draws(spec, theta, features.mu, np.where(features.unstable, -1.0, 1.0),
                        kappa, jax.random.PRNGKey(seed), floor=floor)
    shape = np.shape(run.chains["mu0"])
    chains = {**run.chains, **{f"{k}{RIG}": v.reshape(shape) for k, v in moved.items()}}
    return replace(run, chains=chains)


def fit_hybrid(
    recordings: RecordingSet | HarmonicFeatures,
    criticality: str = "subcritical",
    *,
    seed: int = 0,
    settings: ci.CollapsedSettings | None = None,
    progress: bool = True,
    compilation_cache: bool = True,
) -> HybridPosterior:
    """Fit the Bayesian hybrid normal-form model on the collapsed core.

    Stages: phase-aligned harmonic features; a deterministic start and the MAP
    (:func:`~bayeshopf.inference.collapsed.fit_map`); importance sampling, NUTS
    or SVI on the nonlinear parameters with the map integrated out; one exact map draw per
    posterior draw; diagnostics.

    Args:
        recordings: The recordings, or features already extracted.
        criticality: ``"subcritical"`` or ``"supercritical"``.
        seed: Seed of every random choice.
        settings: :class:`~bayeshopf.inference.collapsed.CollapsedSettings`.
        progress: Show progress.
        compilation_cache: Use JAX's persistent compilation cache.

    Returns:
        A :class:`~bayeshopf.hybrid_posterior.HybridPosterior` with its ``diagnostics``.
    """
    ensure_x64()
    settings = settings or ci.CollapsedSettings()
    if compilation_cache:
        enable_compilation_cache()
    release_compiled()      # a process fitting many data sets would exhaust vm.max_map_count
    t0 = time.perf_counter()
    features, labels = _features(recordings, settings)
    timings = {"features": time.perf_counter() - t0}
    return _fit_features(features, labels, criticality, seed, settings, progress, timings)


def fit_auto(
    recordings: RecordingSet | HarmonicFeatures,
    *,
    seed: int = 0,
    settings: ci.CollapsedSettings | None = None,
    progress: bool = True,
    exact_loo: bool = False,
) -> tuple[HybridPosterior, dict]:
    """Fit both normal forms and let leave-one-out choose the criticality.

    Both models are fitted to the same features. The supercritical model has
    one LCO per μ, so it ignores the branch labels and must explain every
    orbit, labelled stable or unstable, as that one LCO. They are compared by
    the expected log predictive density of each recording given the others
    (:func:`~bayeshopf.diagnostics.comparison.compare_criticality`): PSIS-LOO
    over the posterior of θ with the exact conditional ``p(y_i | y_{−i}, θ)``
    (the map refitted in closed form without recording ``i``,
    :attr:`~bayeshopf.hybrid_posterior.HybridPosterior.log_likelihood`). Two
    recordings at one μ whose amplitudes differ by many times their spread over
    segments decide for the subcritical model whatever the ELPD: one LCO per μ
    cannot give them.

    Args:
        recordings: The recordings, or their features.
        seed: Seed of every fit.
        settings: Settings of every fit.
        progress: Show progress.
        exact_loo: Refit a model without every recording whose PSIS Pareto k
            exceeds 0.7 (ArviZ ``reloo``) and use the exact leave-one-out
            density ``log mean_s p(y_i | y_{−i}, θ_s^{(−i)})`` there (one fit each).

    Returns:
        ``(fit, evidence)``: the preferred fit, and the evidence of
        :func:`~bayeshopf.diagnostics.comparison.compare_criticality` with
        ``branch_labels`` added.
    """
    ensure_x64()
    from dataclasses import replace

    from bayeshopf.diagnostics.comparison import compare_criticality

    settings = settings or ci.CollapsedSettings()
    enable_compilation_cache()
    features, labels = _features(recordings, settings)
    by_model = {"subcritical": features,
                "supercritical": replace(features, unstable=np.zeros_like(features.unstable))}
    fits = {}
    for name, f in by_model.items():
        release_compiled()
        fits[name] = _fit_features(f, labels, name, seed, settings, progress, {})
        fits[name].log_likelihood      # noqa: B018 (computed while its jits are alive)

    def refit(name: str, i: int) -> np.ndarray:
        release_compiled()
        keep = [j for j in range(features.n_recordings) if j != i]
        if progress:
            print(f"exact leave-one-out: {name} without {features.names[i]}", file=sys.stderr)
        p = _fit_features(by_model[name].subset(keep), labels, name, seed, settings, False, {})
        theta = {k: v for k, v in p.samples.items() if k in p.map_point.params}
        ll = log_likelihood_draws(p.spec, theta, by_model[name])[:, i]
        return np.where(np.isfinite(ll), ll, -np.inf)

    evidence = compare_criticality(fits, refit if exact_loo else None)
    evidence["branch_labels"] = ("used by the subcritical model only"
                                 if np.any(features.unstable) else "all stable")
    return fits[evidence["preferred"]], evidence

