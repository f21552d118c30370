"""Inference on the collapsed model: deterministic start, MAP, then NUTS or SVI.

With the map integrated out (:mod:`bayeshopf.model.collapsed`) the posterior is
over a handful of parameters: the normal form's gaps (and the unfolding's ``w``),
``τ_μ``, ``τ_s`` and one model error per channel. The stages:

1. **Start.** A grid over the two gaps (fractions of Δμ), the hyperparameters
   at their prior medians; the grid point with the highest log joint is kept.
   Nothing is random, so the answer does not depend on which start won.
2. **MAP** by SciPy's L-BFGS-B from that point, in NumPyro's unconstrained
   space, on the compiled potential and gradient, until the gradient norm falls
   below :data:`MAP_GTOL` (finished by a root find on the gradient where the
   line search stops at the value's rounding); the final norm is reported
   (:mod:`bayeshopf.inference.optimum`).
3. **Posterior.** ``"importance"`` (default): draws from a Student-t at the
   MAP point with its Laplace covariance, adapted once and weighted by the
   posterior, Pareto-smoothed, NUTS where their check fails
   (:mod:`bayeshopf.inference.importance`). ``"nuts"``: NumPyro's NUTS kernel,
   ``num_chains`` chains started at the MAP point with the mass matrix started
   at the MAP's Laplace covariance, advanced in compiled chunks and extended
   while R̂ or bulk ESS (ArviZ) of a checked site fails, up to ``max_samples``
   (:mod:`bayeshopf.inference.nuts`). ``"svi"``: a full-rank Gaussian
   autoguide started at the MAP point, with an ELBO-plateau test
   (:mod:`bayeshopf.inference.svi`).
4. **Map draws.** For every posterior draw, one exact draw of the map's linear
   coefficients from their Gaussian conditional.

This module runs the stages (:func:`sample_posterior`, :func:`compile_programs`)
and re-exports the names of the modules that hold them: the settings
(:mod:`bayeshopf.inference.settings`), the model's compiled programs
(:mod:`bayeshopf.inference.programs`), the devices
(:mod:`bayeshopf.inference.devices`), the MAP, NUTS and SVI.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from bayeshopf import _preload
from bayeshopf._x64 import ensure_x64
from bayeshopf.errors import FitError
from bayeshopf.inference import devices, importance, nuts, programs
from bayeshopf.inference.cache import (  # noqa: F401 (re-exported)
    compile_ahead,
    compiled_call,
    compiled_function,
    stored_shapes,
)
from bayeshopf.inference.devices import mapped_call, spread_devices  # noqa: F401
from bayeshopf.inference.nuts import (  # noqa: F401 (re-exported)
    CHECKED,
    ESS_MIN,
    RHAT_MAX,
    convergence,
    nuts_chunk,
    run_nuts,
)
from bayeshopf.inference.optimum import (  # noqa: F401 (re-exported)
    MAP_GTOL,
    START_GRID,
    MapPoint,
    fit_map,
    laplace_covariance,
)
from bayeshopf.inference.programs import (  # noqa: F401 (re-exported)
    _initial_values,
    clear_model_functions,
    constrain_program,
    model_functions,
    model_key,
    potential_program,
)
from bayeshopf.inference.settings import (  # noqa: F401 (re-exported)
    CollapsedSettings,
    ModelInputs,
    build_spec,
    model_arguments,
)
from bayeshopf.inference.svi import (  # noqa: F401 (re-exported)
    AGREEMENT_FRACTION,
    SVI_PARTICLES,
    elbo_plateau,
    interval_agreement,
    run_svi,
)
from bayeshopf.model import collapsed as cm

#: The posterior's methods (``CollapsedSettings.inference``).
METHODS = ("nuts", "importance", "svi")

#: NUTS's and SVI's runs under their earlier names.
_nuts, _svi = run_nuts, run_svi


def compile_programs(inputs: ModelInputs, settings: CollapsedSettings) -> None:
    """Start compiling the MAP's and the posterior's programs in the background, before the MAP.

    With an empty compilation cache most of a fit is XLA compiling, one program
    after another on one core, each when first called: the potential, NUTS's
    start and advance (or importance sampling's potential and sites at many
    draws), the map draws and the log-likelihood. All but NUTS's
    start (which holds the MAP point) are exported (or loaded) here and
    compiled in a background thread, on the other core, while this thread
    finds the MAP (:func:`~bayeshopf.inference.cache.compile_ahead`). Their
    arguments' shapes are traced once per data set and settings and then read
    from the cache folder (:func:`~bayeshopf.inference.cache.stored_shapes`),
    so that a warm fit traces nothing here. The map draws and the
    log-likelihood are compiled for the draws of the first convergence check;
    chains extended past it compile theirs when called. Does nothing on one
    core or without the persistent cache.
    """
    if _preload.available_cores() < 2:       # no core to compile on beside this thread
        return
    is_nuts = settings.inference == "nuts"
    draws = settings.num_chains * settings.num_samples    # those of the first convergence check
    n_dev = devices.spread_devices(settings.num_chains)

    def shapes():
        info, unravel, _ = programs.model_functions(inputs)
        x = ravel_pytree(info.param_info.z)[0]
        theta = jax.eval_shape(lambda x: info.postprocess_fn(unravel(x)), x)
        return {"x": jax.ShapeDtypeStruct(x.shape, x.dtype),
                "theta": {k: jax.ShapeDtypeStruct((draws,) + a.shape, a.dtype)
                          for k, a in theta.items() if not k.startswith("marginal")},
                "states": nuts.nuts_states(inputs, settings, x.shape[0]) if is_nuts else []}

    # traced once per data set and settings, then read from the cache folder
    got = stored_shapes("shapes", (nuts.nuts_key(inputs, settings), is_nuts, draws,
                                   settings.num_chains), shapes)
    n = got["x"].shape[0]
    programs.potential_program(inputs, n, ahead=True)
    if settings.inference == "svi":
        return
    if is_nuts:
        where = devices.placement(n_dev)
        states = [jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=where)
                  for a in got["states"]]
        nuts.nuts_advance(inputs, settings, n, n_dev, states, ahead=True)
    else:       # importance sampling
        importance.potential_draws(
            inputs, jax.ShapeDtypeStruct((importance.PROPOSALS, n), jnp.float64), ahead=True)
        importance.sites_at(inputs, jax.ShapeDtypeStruct((draws, n), jnp.float64), ahead=True)
    key = programs.model_key(inputs)
    keys = jax.ShapeDtypeStruct((draws, 2), jnp.uint32)
    devices.mapped_call("maps", _map_draw(inputs), (got["theta"], keys), key=key, ahead=True)
    devices.mapped_call("loglik", _pointwise(inputs), got["theta"], key=key, ahead=True)


def _sample_maps(spec, inputs, theta: dict, key) -> tuple[np.ndarray, np.ndarray | None]:
    """One exact draw of the map's (and the frequency's) coefficients per posterior draw.

    Returns:
        ``β`` ``(n, J, 2)`` and ``γ`` ``(n, 4)`` (``None`` without the frequency model).
    """
    n = len(next(iter(theta.values())))
    keys = jax.random.split(key, n)
    th = {k: jnp.asarray(v) for k, v in theta.items()}
    betas, gammas = devices.mapped_call("maps", _map_draw(inputs), (th, keys),
                                        key=programs.model_key(inputs))
    return np.asarray(betas), np.asarray(gammas) if spec.omega_centre is not None else None


def _map_draw(inputs):
    """``(θ, key) ↦ (β, γ)``: one exact draw of the map's and the frequency's coefficients."""
    spec = inputs["spec"]

    def one(a):
        t, k = a
        k_map, k_freq = jax.random.split(k)
        beta = cm.draw_map(spec, t, inputs["mu"], inputs["sign"], inputs["coeffs"],
                           inputs["coeffs_se"], k_map, inputs.get("control"))
        if spec.omega_centre is None:
            return beta, jnp.zeros(0)
        return beta, cm.draw_frequency(spec, t, inputs["mu"], inputs["sign"], inputs["omega"],
                                       inputs["omega_se"], k_freq)

    return one


def pointwise_log_likelihood_draws(inputs: ModelInputs, theta: dict):
    """``log p(y_i | y_{−i}, θ)`` of each recording at each draw, ``(n, n_rec)``, dispatched.

    :func:`~bayeshopf.model.collapsed.pointwise_log_likelihood` over the draws
    (:func:`~bayeshopf.inference.devices.mapped_call`); a JAX array, computed
    while the caller goes on.
    """
    th = {k: jnp.asarray(v) for k, v in theta.items()}
    return devices.mapped_call("loglik", _pointwise(inputs), th, key=programs.model_key(inputs))


def _pointwise(inputs):
    """``θ ↦ log p(y_i | y_{−i}, θ)`` of every recording (the model's blocks)."""
    def one(t):
        return cm.pointwise_log_likelihood(inputs["spec"], t, inputs["mu"], inputs["sign"],
                                           inputs["coeffs"], inputs["coeffs_se"],
                                           inputs["omega"], inputs["omega_se"],
                                           inputs.get("control"))

    return one


@dataclass(frozen=True)
class PosteriorRun:
    """The posterior stage's raw result (immutable).

    Attributes:
        method: ``"nuts"``, ``"importance"`` or ``"svi"`` (``"nuts"`` where
            importance sampling fell back to it).
        chains: Draws of every site, ``(n_chains, n_draws, ...)`` (SVI: one chain).
        betas: Map coefficients, one exact draw per posterior draw, ``(n, J, 2)``.
        gammas: Frequency coefficients, one exact draw per posterior draw, ``(n, 4)``,
            or ``None`` without the frequency model.
        divergences: NUTS divergent transitions (0 for SVI).
        losses: SVI −ELBO per step (empty for NUTS).
        seconds: Wall time of the stage.
        sampler: NUTS: how the mass matrix started (``"laplace"`` or ``"identity"``)
            and the mean leapfrog steps per iteration in warm-up and in the draws
            (the stage's cost, whatever the machine's load); importance
            sampling: its check (:func:`~bayeshopf.inference.importance.run_importance`),
            under ``"importance"`` after a fallback to NUTS; empty for SVI.
    """

    method: str
    chains: dict
    betas: np.ndarray
    gammas: np.ndarray | None = None
    divergences: int = 0
    losses: np.ndarray = field(default_factory=lambda: np.zeros(0))
    seconds: float = 0.0
    sampler: dict = field(default_factory=dict)

    @property
    def samples(self) -> dict:
        """Draws with the chains pooled, leading axis ``n``."""
        return {k: v.reshape((-1,) + v.shape[2:]) for k, v in self.chains.items()}


def sample_posterior(inputs: ModelInputs, map_point: MapPoint,
                     settings: CollapsedSettings, *,
                     seed: int = 0, progress: bool = True, method: str | None = None
                     ) -> PosteriorRun:
    """NUTS, importance sampling or SVI from the MAP point, then one exact map draw per draw."""
    ensure_x64()
    method = method or settings.inference
    if method not in METHODS:
        raise FitError(f"inference must be one of {', '.join(map(repr, METHODS))}; "
                       f"got {method!r}")
    k_post, k_map = jax.random.split(jax.random.PRNGKey(seed))
    t0 = time.perf_counter()
    if progress:
        what = (f"{settings.num_chains} chains × {settings.num_warmup} + {settings.num_samples} "
                f"steps, up to {settings.max_samples} draws while R̂ or ESS fails"
                if method == "nuts" else f"{settings.svi_steps} steps" if method == "svi" else
                f"{3 * importance.PROPOSALS} draws from the MAP's Laplace approximation, "
                "NUTS if their check fails")
        name = "importance sampling" if method == "importance" else method.upper()
        print(f"posterior: {name} on the collapsed model ({what})", file=sys.stderr)
    sampler = {}
    if method == "nuts":   # run_nuts starts the imports once its first chunk is dispatched
        chains, div, sampler = nuts.run_nuts(inputs, map_point, settings, k_post, progress)
        losses = np.zeros(0)
    elif method == "importance":
        method, chains, div, sampler = importance.run_importance(inputs, map_point, settings,
                                                                 k_post, progress)
        losses = np.zeros(0)
    else:
        _preload.start()   # ArviZ (R̂ and ESS, posterior.nc) imports while SVI runs
        chains, losses = run_svi(inputs, map_point, settings, k_post, progress)
        div = 0
    pooled = {k: v.reshape((-1,) + v.shape[2:]) for k, v in chains.items()}
    theta = {k: v for k, v in pooled.items() if not k.startswith("marginal")}
    betas, gammas = _sample_maps(inputs["spec"], inputs, theta, k_map)
    return PosteriorRun(method, chains, betas, gammas, div, losses, time.perf_counter() - t0,
                        sampler)


def compare_with_nuts(post, *, seed: int = 0, progress: bool = True) -> dict:
    """NUTS on the same collapsed model as a reference for an SVI posterior.

    Returns:
        ``{"convergence": R̂ and ESS of the NUTS chains, "sites": the interval
        agreement of SVI with NUTS per site, "agree": all sites agree}``.
    """
    ensure_x64()
    inputs = model_arguments(post.spec, post.features)
    ref = sample_posterior(inputs, post.map_point, post.settings, seed=seed + 1,
                           progress=progress, method="nuts")
    sites = interval_agreement(ref.samples, post.samples)
    return {"convergence": convergence(ref.chains), "divergences": ref.divergences,
            "sites": sites, "agree": all(v["agree"] for v in sites.values())}
