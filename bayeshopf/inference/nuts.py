"""NUTS on the collapsed model, in compiled chunks, extended until R̂ and ESS pass.

NumPyro's NUTS kernel, ``num_chains`` chains started at the MAP point with
the mass matrix started at the MAP's Laplace covariance
(:func:`~bayeshopf.inference.optimum.laplace_covariance`), advanced in
compiled chunks (:func:`nuts_chunk`) and extended while R̂ or bulk ESS
(ArviZ) of a :data:`CHECKED` site fails, up to ``max_samples``.
"""

from __future__ import annotations

import math
import sys
import warnings

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from numpyro.infer import NUTS

from bayeshopf import _preload
from bayeshopf.errors import FitError
from bayeshopf.inference import devices, optimum, programs
from bayeshopf.inference.cache import compile_ahead, compiled_call, compiled_function
from bayeshopf.inference.optimum import MapPoint
from bayeshopf.inference.settings import CollapsedSettings, ModelInputs

#: R̂ above which a site counts as not converged.
RHAT_MAX = 1.01
#: Bulk ESS below which a site counts as not converged.
ESS_MIN = 400
#: Sites whose convergence is checked and reported.
CHECKED = ("mu0", "a2", "mu_fold", "a4", "w_unfold")


def arviz():
    """The ``arviz`` module, imported at the first call.

    The sampler's background import (:mod:`bayeshopf._preload`) has usually
    loaded it by then. (:func:`bayeshopf.diagnostics.arviz_io.arviz` is the same
    for the layers above inference.)
    """
    with warnings.catch_warnings():  # the 0.2x series announces its 1.x refactor on import
        warnings.simplefilter("ignore", FutureWarning)
        import arviz as az
    return az


def rhat_ess(chains: dict) -> dict:
    """R̂ and bulk ESS per site (ArviZ) of draws by chain ``(n_chains, n_draws)`` (scalar sites)."""
    az = arviz()
    ds = az.convert_to_dataset({k: np.asarray(v) for k, v in chains.items()})
    rhat, ess = az.rhat(ds), az.ess(ds, method="bulk")
    return {k: (float(rhat[k]), float(ess[k])) for k in chains}


def convergence(chains: dict) -> dict:
    """R̂ and bulk ESS (ArviZ) of the :data:`CHECKED` sites present, with pass flags."""
    present = {k: v for k, v in chains.items() if k in CHECKED}
    out = {}
    if next(iter(present.values())).shape[0] < 2:
        return out
    for k, (r, e) in rhat_ess(present).items():
        out[k] = {"r_hat": r, "ess_bulk": e, "ok": bool(r <= RHAT_MAX and e >= ESS_MIN)}
    return out


def nuts_chunk(settings: CollapsedSettings) -> int:
    """Iterations per compiled call of NUTS.

    The largest number that divides the warm-up, the first draws and each
    extension: ``gcd(num_warmup, num_samples, extend_samples)``.
    """
    return math.gcd(settings.num_warmup, settings.num_samples, settings.extend_samples)


def _nuts_kernel(inputs: ModelInputs, settings: CollapsedSettings, cov=None) -> NUTS:
    """NumPyro's NUTS on the collapsed potential (``cov``: the starting inverse mass matrix)."""
    return NUTS(potential_fn=programs.model_functions(inputs)[2],
                dense_mass=settings.dense_mass, inverse_mass_matrix=cov,
                target_accept_prob=settings.target_accept,
                max_tree_depth=settings.max_tree_depth)


def nuts_key(inputs: ModelInputs, settings: CollapsedSettings) -> tuple:
    """Everything NUTS's programs close over besides the MAP point (``inference.cache``)."""
    return (programs.model_key(inputs), settings.num_warmup, settings.dense_mass,
            settings.target_accept, settings.max_tree_depth)


def _nuts_start(inputs: ModelInputs, settings: CollapsedSettings, x0, keys, cov) -> list:
    """Every chain's initial state at ``x0`` (NumPyro's ``init``), as flat leaves, compiled.

    The program holds ``x0`` (one per data set, settings and MAP point); the
    draws of a fit are those of the program that holds it.
    """
    def make_start():
        def start(keys, cov):
            nuts = _nuts_kernel(inputs, settings, cov if settings.dense_mass else None)
            states = jax.lax.map(lambda k: nuts.init(k, settings.num_warmup, init_params=x0,
                                                     model_args=(), model_kwargs={}), keys)
            return jax.tree.leaves(states)

        return start

    return compiled_call("nuts-start", make_start, (keys, jnp.asarray(cov)),
                         key=(nuts_key(inputs, settings), x0))


def _nuts_init(nuts: NUTS, settings: CollapsedSettings, n: int):
    """A state of ``nuts`` at zero, for the kernel's configuration and the state's shapes.

    ``init`` sets the warm-up schedule; the state's values are not used.
    """
    return nuts.init(jax.random.PRNGKey(0), settings.num_warmup, init_params=jnp.zeros(n),
                     model_args=(), model_kwargs={})


def nuts_states(inputs: ModelInputs, settings: CollapsedSettings, n: int) -> list:
    """Shapes of every chain's state as :func:`_nuts_start` returns it (traced, not run)."""
    nuts = _nuts_kernel(inputs, settings, jnp.eye(n) if settings.dense_mass else None)
    one = jax.eval_shape(lambda: jax.tree.leaves(_nuts_init(nuts, settings, n)))
    return [jax.ShapeDtypeStruct((settings.num_chains,) + a.shape, a.dtype) for a in one]


def nuts_advance(inputs: ModelInputs, settings: CollapsedSettings, n: int, n_dev: int,
                 leaves,
                  ahead: bool = False):
    """The program that advances every chain by :func:`nuts_chunk` iterations, compiled.

    It takes the chains' states as flat leaves (as :func:`_nuts_start` gives
    them, split over ``n_dev`` devices by :func:`~bayeshopf.inference.devices.place`) and returns
    ``(leaves, draws, diverging, steps)``. It does not depend on the MAP point,
    so it can be traced and compiled before the MAP is found: with ``ahead``
    it is (:func:`~bayeshopf.inference.cache.compile_ahead`), and ``None`` is
    returned. ``leaves``: the states it will be called with (arrays, or their
    shapes and placement, :func:`nuts_states`).
    """
    chunk = nuts_chunk(settings)

    def make_advance():
        info, unravel, _ = programs.model_functions(inputs)

        def advance(leaves):
            nuts = _nuts_kernel(inputs, settings)
            # the states passed in carry the point and the adapted mass matrix
            tree = jax.tree.structure(_nuts_init(nuts, settings, n))

            def chain(state_leaves):
                def step(s, _):   # adapts while s.i < num_warmup (windowed adaptation)
                    s = nuts.sample(s, (), {})
                    return s, (s.z, s.diverging, s.num_steps)

                state, out = jax.lax.scan(step, jax.tree.unflatten(tree, state_leaves), None,
                                          length=chunk)
                return jax.tree.leaves(state), out

            leaves, (x, diverging, steps) = jax.lax.map(chain, leaves)
            # every site, the deterministic ones (μ0, a2, the fold) too; lax.map, not
            # vmap: XLA's batched Cholesky is slow on CPU
            draws = jax.lax.map(lambda xi: info.postprocess_fn(unravel(xi)),
                                x.reshape(-1, x.shape[-1]))
            return leaves, draws, diverging, steps

        return devices.spread(advance, n_dev)     # draws: chain by chain, as on one device

    key = (nuts_key(inputs, settings), chunk, n_dev)
    if ahead:
        compile_ahead("nuts-advance", make_advance, (leaves,), key=key)
        return None
    return compiled_function("nuts-advance", make_advance, (leaves,), key=key)


def run_nuts(inputs: ModelInputs, map_point: MapPoint, settings: CollapsedSettings, key,
             progress: bool, laplace: tuple | None = None):
    """NumPyro's NUTS kernel from the MAP point, chains extended until they pass.

    The mass matrix starts at the MAP's Laplace covariance (the inverse Hessian
    of the potential there) and is adapted from it. From the identity, the
    windowed adaptation spends its first windows on deep trees, with several
    times the leapfrog steps per warm-up iteration.

    Two compiled programs besides the gradient the Laplace covariance
    differences (:func:`~bayeshopf.inference.optimum.laplace_covariance`): one
    starts every chain (NumPyro's ``init`` with that covariance); the other
    advances every chain by :func:`nuts_chunk` iterations, warm-up or draws
    alike (the state carries the iteration count and the adaptation), and is
    called again and again. After ``num_warmup``
    warm-up iterations and ``num_samples`` draws per chain, R̂ and bulk ESS of
    the :data:`CHECKED` sites (:func:`convergence`) decide: while one fails and
    fewer than ``max_samples`` draws per chain exist, every chain gets
    ``extend_samples`` more. The draws are those of one longer run; only its
    length depends on the diagnostics.

    ``laplace``: the MAP's Laplace covariance and whether it exists,
    ``(cov, ok)`` (:func:`~bayeshopf.inference.optimum.laplace_covariance`),
    where the caller has computed it already (importance sampling that fell
    back to NUTS).

    On one device the chains run one after another inside each call
    (``lax.map`` over them), not vectorized: XLA's batched Cholesky and
    triangular solves are slow on CPU. Where the process has several CPU devices
    (:func:`~bayeshopf.inference.devices.spread_devices`), the chains are split
    between them (``shard_map``), each device running its share one after
    another; the draws are the same as on one device, as each chain's key and
    start are. One device per chain on fewer cores is slower than one device
    running the chains one after another; as many devices as cores, each with
    its share of the chains, is faster.
    """
    if not 1 <= settings.num_samples <= settings.max_samples or settings.extend_samples < 1:
        raise FitError("NUTS settings: expected 1 ≤ num_samples ≤ max_samples and "
                       f"extend_samples ≥ 1; got num_samples={settings.num_samples}, "
                       f"max_samples={settings.max_samples}, "
                       f"extend_samples={settings.extend_samples}")
    x0 = ravel_pytree({k: jnp.asarray(v) for k, v in map_point.unconstrained.items()})[0]
    n_dev = devices.spread_devices(settings.num_chains)
    keys = jax.random.split(key, settings.num_chains)
    # compiled once per data set, settings and MAP point (any seed), then loaded
    # (inference.cache); compile_programs may have started compiling them already
    if not settings.dense_mass:
        laplace = (np.eye(x0.shape[0]), False)
    elif laplace is None:
        laplace = optimum.laplace_covariance(programs.potential_program(inputs, x0.shape[0]),
                                             x0)
    cov, laplace = laplace
    leaves = devices.place(_nuts_start(inputs, settings, x0, keys, cov), n_dev)
    advance = nuts_advance(inputs, settings, x0.shape[0], n_dev, leaves)
    n_warm, chunk = settings.num_warmup, nuts_chunk(settings)
    draws, diverging, steps = [], [], []
    done, wanted = 0, n_warm + settings.num_samples
    while True:
        leaves, d, div, st = advance(leaves)   # dispatched: runs while Python goes on
        if done == 0:
            # ArviZ (R̂ and ESS, posterior.nc) and the figures' modules import now,
            # beside the compiled chunks, not beside the Python loops before them
            _preload.start()
        done += chunk
        steps.append(np.asarray(st))
        if done > n_warm:
            draws.append({k: np.asarray(v).reshape((settings.num_chains, chunk) + v.shape[1:])
                          for k, v in d.items()})
            diverging.append(np.asarray(div))
        if done < wanted:
            continue
        chains = {k: np.concatenate([c[k] for c in draws], axis=1) for k in draws[0]}
        failed = [k for k, v in convergence(chains).items() if not v["ok"]]
        if not failed or done - n_warm + settings.extend_samples > settings.max_samples:
            break
        wanted += settings.extend_samples
        if progress:
            print(f"posterior: R̂ or ESS short for {', '.join(failed)} after {done - n_warm} "
                  f"draws per chain; {settings.extend_samples} more", file=sys.stderr)
    steps = np.concatenate(steps, axis=1)
    sampler = {"mass_matrix_start": "laplace" if bool(laplace) else "identity",
               "leapfrog_steps_warmup": float(steps[:, :n_warm].mean()) if n_warm else 0.0,
               "leapfrog_steps_draws": float(steps[:, n_warm:].mean()),
               "draws_per_chain": int(done - n_warm)}
    return chains, int(np.sum(np.concatenate(diverging, axis=1))), sampler
