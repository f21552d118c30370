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
   line search stops at the value's rounding); the final norm is reported.
3. **Posterior.** ``"nuts"`` (default): NumPyro's NUTS kernel, ``num_chains``
   chains started at the MAP point with the mass matrix started at the MAP's
   Laplace covariance, advanced in compiled chunks and extended while R̂ or
   bulk ESS (ArviZ) of a checked site fails, up to ``max_samples``.
   ``"svi"``: a full-rank Gaussian autoguide started at the MAP point, with an
   ELBO-plateau test.
4. **Map draws.** For every posterior draw, one exact draw of the map's linear
   coefficients from their Gaussian conditional.
"""

from __future__ import annotations

import itertools
import json
import math
import sys
import time
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
import optax
import scipy.differentiate
import scipy.optimize
from jax.flatten_util import ravel_pytree
from jax.sharding import Mesh, NamedSharding, PartitionSpec
from numpyro.infer import NUTS, SVI, Predictive, Trace_ELBO, init_to_value
from numpyro.infer.autoguide import AutoMultivariateNormal
from numpyro.infer.util import initialize_model

from bayeshopf import _preload
from bayeshopf._x64 import ensure_x64
from bayeshopf.diagnostics.arviz_io import rhat_ess
from bayeshopf.errors import FitError
from bayeshopf.features.harmonics import HarmonicFeatures
from bayeshopf.inference.cache import (
    compile_ahead,
    compiled_call,
    compiled_function,
    stored_shapes,
)
from bayeshopf.model import collapsed as cm
from bayeshopf.model import discrepancy as dm

#: Gradient norm (unconstrained space) below which the MAP counts as converged.
MAP_GTOL = 1e-4
#: R̂ above which a site counts as not converged.
RHAT_MAX = 1.01
#: Bulk ESS below which a site counts as not converged.
ESS_MIN = 400
#: Sites whose convergence is checked and reported.
CHECKED = ("mu0", "a2", "mu_fold", "a4", "w_unfold")
#: Grid of the deterministic start, as fractions of Δμ for both gaps.
START_GRID = (0.03, 0.1, 0.3, 1.0)
#: What L-BFGS-B is told where the potential is not finite (it then shortens the step).
_NOT_FINITE = 1e100
#: First step of the finite differences of the Laplace covariance (unconstrained units).
_HESSIAN_STEP = 0.05


@dataclass(frozen=True)
class CollapsedSettings:
    """Settings of :func:`fit_collapsed` (the defaults are the documented ones).

    Attributes:
        n_harmonics: Harmonics per channel of the features.
        segment_periods: Segment length in periods.
        nn_width: Hidden units of the map's network.
        nn_seed: Seed of the network's fixed hidden layer (a draw from its
            prior, :func:`~bayeshopf.model.collapsed.hidden_layer`; refit with
            others to see what the draw decides).
        unfolding: ``"curved"`` (default) or ``"linear"`` (the paper's ``μ − μ0``).
        inference: ``"nuts"`` (default) or ``"svi"``.
        num_chains: NUTS chains.
        num_warmup: NUTS warm-up steps per chain.
        num_samples: NUTS draws per chain before the first convergence check.
        extend_samples: Draws per chain added while a checked site fails R̂ or
            ESS (:data:`RHAT_MAX`, :data:`ESS_MIN`).
        max_samples: Most draws per chain; the chains stop here whatever the
            diagnostics say, and the CLI warns about the sites that fail.
        dense_mass: Adapt a dense mass matrix (the gaps, ``w`` and ``τ_μ`` are
            correlated: on the rig it halves the tree size and doubles the ESS
            per draw against a diagonal one; ``benchmarks/nuts_mass.json``).
        target_accept: NUTS's target acceptance probability during warm-up.
        max_tree_depth: NUTS's largest tree depth (``2**depth − 1`` leapfrog steps).
        svi_steps: SVI steps (``inference="svi"``).
        n_svi_draws: Draws of the SVI posterior.
        lbfgs_steps: Most L-BFGS steps of the MAP.
        frequency: Whether the model includes the frequency ``Ω(r, μ)``.
        extrapolation: Whether a new measurement's band includes the model error
            away from the recordings (:func:`~bayeshopf.model.collapsed.extrapolation_sd`;
            zero at the training recordings, so the fit and its checks do not change).
        extrapolation_scale: Half-normal scale ``S`` of the model error away
            from the recordings, ``s_e ~ HalfNormal(S)`` in log orbit size; it
            changes the bands of new measurements only. ``None`` (the default):
            with the discrepancy none; without it each posterior draw chooses
            by its relative model error σ_rel,
            :data:`~bayeshopf.model.collapsed.EXTRAPOLATION_SCALE_MISFIT` (0.7)
            where σ_rel is above :data:`~bayeshopf.model.collapsed.SIGMA_REL_LIMIT`
            (2%), :data:`~bayeshopf.model.collapsed.EXTRAPOLATION_SCALE` (0.1)
            otherwise (:func:`~bayeshopf.posterior.default_extrapolation_scale`).
        control: Whether the model includes the response to the control's
            residual fundamental, where the recordings name a control channel
            (:mod:`bayeshopf.model.collapsed`, "Control").
        discrepancy: Whether the model includes the model discrepancy, a
            Gaussian process over the diagram on the orbits' fundamental whose
            scale and length are sampled with the normal form
            (:mod:`bayeshopf.model.discrepancy`). Off (the default until it is
            shown to calibrate the bands better than the rule above;
            ``docs/model_discrepancy.md``), the model has a relative model error
            ``σ_rel y`` instead.
        discrepancy_floor: ``κ``, the floor of the discrepancy's scale near the
            Hopf point relative to its training mean
            (:func:`~bayeshopf.model.discrepancy.scales`; 0: purely relative).
    """

    n_harmonics: int = 4
    segment_periods: float = 5.0
    nn_width: int = 16
    nn_seed: int = 0
    unfolding: str = "curved"
    inference: str = "nuts"
    num_chains: int = 4
    num_warmup: int = 500
    num_samples: int = 500
    extend_samples: int = 250
    max_samples: int = 2000
    dense_mass: bool = True
    target_accept: float = 0.8
    max_tree_depth: int = 10
    svi_steps: int = 3000
    n_svi_draws: int = 2000
    lbfgs_steps: int = 300
    frequency: bool = True
    extrapolation: bool = True
    control: bool = True
    extrapolation_scale: float | None = None
    discrepancy: bool = False
    discrepancy_floor: float = dm.FLOOR

    def __post_init__(self):
        s = self.extrapolation_scale
        if s is not None and (isinstance(s, bool) or not isinstance(s, (int, float))
                              or not math.isfinite(s) or s <= 0):
            raise FitError("extrapolation_scale: a positive number or None expected (the "
                           "half-normal scale of the model error away from the recordings, "
                           f"in log orbit size; None: {cm.EXTRAPOLATION_SCALE} or "
                           f"{cm.EXTRAPOLATION_SCALE_MISFIT} by the fit's relative model "
                           f"error, or none with the discrepancy); got {s!r}")

    @classmethod
    def fast(cls) -> CollapsedSettings:
        """Shorter chains for smoke tests, never extended (R̂ and ESS usually fail then)."""
        return cls(num_chains=2, num_warmup=200, num_samples=200, max_samples=200,
                   svi_steps=1000, n_svi_draws=400)


def build_spec(features: HarmonicFeatures, criticality: str, *, nn_width: int = 16,
               unfolding: str = "curved", mu_label: str = "mu",
               mu_units: str = "", frequency: bool = True,
               control: bool = True, discrepancy: bool = False,
               discrepancy_floor: float = dm.FLOOR, nn_seed: int = 0) -> cm.CollapsedSpec:
    """Structure and data constants of the collapsed model.

    The control term is on when ``control`` is true and the features hold a
    control channel whose fundamental is not zero throughout; its prior sd is
    ``CONTROL_SCALE · ρ / ū`` (``ū`` the RMS of ``|U_i|``). With ``discrepancy``
    the model includes the discrepancy Gaussian process, its coefficient
    scales ``q`` read off the features (:mod:`bayeshopf.model.discrepancy`).

    Raises:
        FitError: For fewer than two distinct μ, an unknown criticality or
            unfolding, or unstable recordings under a supercritical model.
    """
    if criticality not in ("subcritical", "supercritical"):
        raise FitError(f"criticality must be 'subcritical' or 'supercritical'; got {criticality!r}")
    if unfolding not in ("curved", "linear"):
        raise FitError(f"unfolding must be 'curved' or 'linear'; got {unfolding!r}")
    mu = features.mu
    if np.unique(mu).size < 2:
        raise FitError(f"the fit needs recordings at two or more distinct values of μ; found "
                       f"{features.n_recordings} recording(s) at μ = {sorted(set(mu.tolist()))}")
    if criticality == "supercritical" and features.unstable.any():
        raise FitError("criticality 'supercritical' has no unstable LCO branch, but the data hold "
                       f"{int(features.unstable.sum())} unstable recording(s)")
    orbits = features.orbit()
    rms = np.sqrt(np.mean(np.sum((orbits - orbits.mean(axis=1, keepdims=True)) ** 2, -1), -1))
    unstable_mu = mu[features.unstable]
    scale = float(np.median(rms))
    control_scale = None
    if control and features.control is not None:
        u_rms = float(np.sqrt(np.mean(np.sum(np.asarray(features.control) ** 2, axis=-1))))
        if u_rms > 0:
            control_scale = cm.CONTROL_SCALE * scale / u_rms
    return cm.CollapsedSpec(
        criticality=criticality, frame=features.frame, n_harmonics=features.n_harmonics,
        mu_centre=float(0.5 * (mu.max() + mu.min())), mu_span=float(mu.max() - mu.min()),
        mu_min=float(mu.min()),
        mu_unstable_max=float(unstable_mu.max()) if unstable_mu.size else None,
        orbit_scale=scale, nn_hidden=cm.hidden_layer(nn_width, nn_seed),
        mu_label=mu_label, mu_units=mu_units,
        unfolding=unfolding if criticality == "subcritical" else "linear",
        omega_centre=float(np.mean(features.omega)) if frequency else None,
        control_scale=control_scale,
        discrepancy_scale=(tuple(map(tuple, dm.coefficient_scale(features.coeffs).tolist()))
                           if discrepancy else None),
        discrepancy_floor=float(discrepancy_floor),
    )


def model_key(kwargs: dict) -> tuple:
    """What a traced function of the model closes over: the spec and the data arrays.

    The ``key`` of :func:`~bayeshopf.inference.cache.compiled_call` for the functions
    of :func:`model_functions` and the model's blocks.
    """
    return (json.dumps(kwargs["spec"].to_dict(), sort_keys=True),
            {k: np.asarray(v) for k, v in kwargs.items() if k != "spec"})


def model_arguments(spec: cm.CollapsedSpec, features: HarmonicFeatures) -> dict:
    """Keyword arguments of :func:`~bayeshopf.model.collapsed.collapsed_model`.

    ``control`` is there only when the spec has the control term.
    """
    kw = dict(spec=spec, mu=jnp.asarray(features.mu),
              sign=jnp.asarray(np.where(features.unstable, -1.0, 1.0)),
              coeffs=jnp.asarray(features.coeffs), coeffs_se=jnp.asarray(features.coeffs_se),
              omega=jnp.asarray(features.omega), omega_se=jnp.asarray(features.omega_se))
    if spec.control_scale is not None:
        if features.control is None:
            raise FitError("the model has the control term but the features hold no control "
                           "channel; extract them from recordings that name one")
        kw["control"] = jnp.asarray(features.control)
    return kw


def _initial_values(spec: cm.CollapsedSpec) -> dict:
    v = {"tau_mu": cm.TAU_MU_PRIOR[0], "tau_shape": cm.TAU_SHAPE_PRIOR[0],
         "sigma": np.full(2, 0.5 * cm.SIGMA_PRIOR * spec.orbit_scale),
         "sigma_rel": 0.5 * cm.SIGMA_REL_PRIOR,
         "gap_hopf": 0.3 * spec.mu_span}
    if spec.omega_centre is not None:
        v["sigma_omega"] = 0.5 * cm.SIGMA_OMEGA_PRIOR * spec.omega_centre
    if spec.has_discrepancy:
        v["eta"] = 0.5 * dm.ETA_PRIOR
        v["ell"] = dm.LENGTH_PRIOR[0]
    if spec.criticality == "subcritical":
        v["gap_fold"] = 0.3 * spec.mu_span
        if spec.unfolding == "curved":
            v["w_unfold"] = 0.0
    else:
        v["kappa"] = 0.3 / spec.mu_span
    return {k: jnp.asarray(x, dtype=float) for k, x in v.items()}


@dataclass(frozen=True)
class MapPoint:
    """The MAP stage's result (immutable).

    Attributes:
        params: Constrained values of every site at the optimum.
        unconstrained: The optimum in NumPyro's unconstrained space.
        log_joint: Log joint density there.
        grad_norm: Gradient norm there (unconstrained space).
        converged: ``grad_norm < MAP_GTOL``.
        n_steps: L-BFGS steps taken.
        start: Constrained values of the deterministic start.
        polish_evaluations: Gradient evaluations of the root find that finished
            the MAP where L-BFGS stopped short of :data:`MAP_GTOL` (0: none).
    """

    params: dict
    unconstrained: dict
    log_joint: float
    grad_norm: float
    converged: bool
    n_steps: int
    start: dict
    polish_evaluations: int = 0


def potential_program(kwargs: dict, n: int, ahead: bool = False):
    """The potential's value and gradient at a flat unconstrained vector, compiled.

    One program per data set and settings, stored
    (:func:`~bayeshopf.inference.cache.compiled_function`),
    shared by the start, the MAP's L-BFGS and the Laplace covariance of NUTS's start.
    With ``ahead``, compiled in the background instead
    (:func:`~bayeshopf.inference.cache.compile_ahead`) and ``None`` returned.
    """
    def make():
        return jax.value_and_grad(model_functions(kwargs)[2])

    args, key = (jax.ShapeDtypeStruct((n,), jnp.float64),), model_key(kwargs)
    if ahead:
        compile_ahead("value-and-grad", make, args, key=key)
        return None
    return compiled_function("value-and-grad", make, args, key=key)


def compile_programs(kwargs: dict, settings: CollapsedSettings) -> None:
    """Start compiling the MAP's and NUTS's programs in the background, before the MAP.

    With an empty compilation cache most of a rig fit was XLA compiling, one
    program after another on one core, each when first called: the potential
    (2.4 s), NUTS's start (2.5 s) and advance (5.5 s), the map draws (1.7 s)
    and the log-likelihood (1.8 s; ``jax.monitoring`` durations). All but NUTS's
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
    nuts = settings.inference == "nuts"
    draws = settings.num_chains * settings.num_samples    # those of the first convergence check
    n_dev = spread_devices(settings.num_chains)

    def shapes():
        info, unravel, _ = model_functions(kwargs)
        x = ravel_pytree(info.param_info.z)[0]
        theta = jax.eval_shape(lambda x: info.postprocess_fn(unravel(x)), x)
        return {"x": jax.ShapeDtypeStruct(x.shape, x.dtype),
                "theta": {k: jax.ShapeDtypeStruct((draws,) + a.shape, a.dtype)
                          for k, a in theta.items() if not k.startswith("marginal")},
                "states": _nuts_states(kwargs, settings, x.shape[0]) if nuts else []}

    # traced once per data set and settings, then read from the cache folder
    got = stored_shapes("shapes", (_nuts_key(kwargs, settings), nuts, draws,
                                   settings.num_chains), shapes)
    n = got["x"].shape[0]
    potential_program(kwargs, n, ahead=True)
    if not nuts:
        return
    where = _placement(n_dev)
    states = [jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=where) for a in got["states"]]
    _nuts_advance(kwargs, settings, n, n_dev, states, ahead=True)
    keys = jax.ShapeDtypeStruct((draws, 2), jnp.uint32)
    mapped_call("maps", _map_draw(kwargs), (got["theta"], keys), key=model_key(kwargs), ahead=True)
    mapped_call("loglik", _pointwise(kwargs), got["theta"], key=model_key(kwargs), ahead=True)


def constrain_program(kwargs: dict, n: int):
    """A flat unconstrained vector as dicts, compiled: ``{"params", "unconstrained"}``.

    ``params``: the constrained value of every site, the deterministic ones (μ0,
    a2, the fold) too; ``unconstrained``: the vector's sites in NumPyro's
    unconstrained space.
    """
    def make():
        info, unravel, _ = model_functions(kwargs)
        return lambda x: {"params": info.postprocess_fn(unravel(x)), "unconstrained": unravel(x)}

    return compiled_function("constrain", make, (jnp.zeros(n),), key=model_key(kwargs))


def fit_map(kwargs: dict, *, max_steps: int = 300) -> MapPoint:
    """Deterministic start (grid over the gaps), then L-BFGS to the MAP (module docstring).

    Three small compiled programs, each stored for the next process: the grid of
    starts (flat unconstrained vectors), the potential's value and gradient
    (:func:`potential_program`) and the constrained sites (:func:`constrain_program`).
    The optimiser is SciPy's L-BFGS-B, driven from Python: the single compiled
    program of optax's L-BFGS with its zoom line search held the potential and
    its gradient several times over and compiled in 10.5 s on the 3-DOF demo,
    against 2–2.5 s for one value and gradient. Where L-BFGS-B stops short of
    :data:`MAP_GTOL` (its line search needs the value to fall, and on precise
    data the value's rounding stops it), SciPy's root find on the gradient
    (MINPACK's hybrd) finishes, and is kept only where it lowers the gradient
    norm without raising the value.
    """
    ensure_x64()
    spec = kwargs["spec"]
    names = ("gap_fold", "gap_hopf") if spec.criticality == "subcritical" else ("gap_hopf",
                                                                                  "kappa")
    scale = [1 / spec.mu_span if n == "kappa" else spec.mu_span for n in names]
    gaps = jnp.log(jnp.array([[g1 * scale[0], g2 * scale[1]]
                              for g1, g2 in itertools.product(START_GRID, repeat=2)]))

    def make_grid():
        info, _, _ = model_functions(kwargs)

        def start(g):      # the deterministic start with the two gaps set (unconstrained)
            z = dict(info.param_info.z)
            z[names[0]], z[names[1]] = g[0], g[1]
            return ravel_pytree(z)[0]

        return jax.vmap(start)

    grid = np.asarray(compiled_call("map-grid", make_grid, (gaps,), key=model_key(kwargs)))
    value_and_grad = potential_program(kwargs, grid.shape[1])

    def fun(x):                # what L-BFGS-B sees: a large finite value where it is not finite
        v, g = value_and_grad(jnp.asarray(x))
        v, g = float(v), np.asarray(g, dtype=float)
        return (v, g) if np.isfinite(v) and np.all(np.isfinite(g)) else (_NOT_FINITE, 0.0 * x)

    values = np.array([float(value_and_grad(jnp.asarray(x))[0]) for x in grid])
    if not np.any(np.isfinite(values)):
        raise FitError("no start on the grid of gaps gives a finite log density: are the "
                       "branch labels right (unstable orbits need a fold below them)?")
    best = int(np.argmin(np.where(np.isfinite(values), values, np.inf)))
    # stop on the gradient's L2 norm: below MAP_GTOL when its largest element is below
    # MAP_GTOL/√n (ftol=0: no stop on a slow decrease of the value)
    res = scipy.optimize.minimize(
        fun, grid[best], jac=True, method="L-BFGS-B",
        options={"maxiter": max_steps, "gtol": MAP_GTOL / np.sqrt(grid.shape[1]), "ftol": 0.0})
    x, v, g, polish = np.asarray(res.x, dtype=float), float(res.fun), np.asarray(res.jac), 0
    if v == _NOT_FINITE:          # fun's stand-in for a value that is not finite
        raise FitError("MAP: the log density is not finite at the optimum")
    if np.linalg.norm(g) >= MAP_GTOL:
        # on precise data (the 3-DOF demo) the value carries rounding noise of about 1e-8
        # (the marginal's factorisation of an ill-conditioned matrix), so L-BFGS-B's line
        # search, which needs the value to fall, stops once a step gains less: at a
        # gradient norm of 4e-4–1e-2. The gradient is precise there (noise 6e-9), so a
        # root find on it (MINPACK's hybrd) finishes
        root = scipy.optimize.root(lambda z: fun(z)[1], x, method="hybr")
        v_root, g_root = fun(np.asarray(root.x, dtype=float))
        if (np.linalg.norm(g_root) < np.linalg.norm(g)
                and v_root <= v + 1e-9 * max(1.0, abs(v))):  # not a saddle above the optimum
            x, v, g, polish = np.asarray(root.x, dtype=float), v_root, g_root, int(root.nfev)
    gnorm = float(np.linalg.norm(g))
    constrain = constrain_program(kwargs, grid.shape[1])
    at_map, at_start = constrain(jnp.asarray(x)), constrain(jnp.asarray(grid[best]))
    return MapPoint(
        params={k: np.asarray(val) for k, val in at_map["params"].items()},
        unconstrained={k: np.asarray(val) for k, val in at_map["unconstrained"].items()},
        log_joint=-v, grad_norm=gnorm, converged=gnorm < MAP_GTOL, n_steps=int(res.nit),
        start={k: np.asarray(val) for k, val in at_start["params"].items()},
        polish_evaluations=polish,
    )


#: The last data set's model functions (:func:`model_functions`).
_MODEL_INFO: dict = {}


def model_functions(kwargs: dict):
    """NumPyro's model functions of the collapsed model, on a flat unconstrained vector.

    One eager run of the model (``initialize_model``, at the deterministic
    start's hyperparameters) for each data set, shared by the MAP and NUTS
    stages: the last one is kept, and reused when every argument is the same
    object.

    Returns:
        ``(info, unravel, potential)``: NumPyro's ``ModelInfo``, the function that
        turns a flat unconstrained vector into the dict of sites, and the
        potential energy of a flat vector.
    """
    args = tuple(kwargs.items())
    hit = _MODEL_INFO.get("last")
    if (hit is not None and len(hit[0]) == len(args)
            and all(k == k2 and v is v2 for (k, v), (k2, v2) in zip(hit[0], args, strict=True))):
        return hit[1]
    # validate_grad=False: no eager gradient of the model (1.2 s on the rig, warm); the
    # MAP and NUTS compute theirs compiled
    init = _initial_values(kwargs["spec"])
    info = initialize_model(jax.random.PRNGKey(0), cm.collapsed_model, model_kwargs=kwargs,
                            init_strategy=init_to_value(values=init), validate_grad=False)
    unravel = ravel_pytree(info.param_info.z)[1]

    def potential(x):
        return info.potential_fn(unravel(x))

    _MODEL_INFO["last"] = (args, (info, unravel, potential))   # one data set at a time
    return _MODEL_INFO["last"][1]


def clear_model_functions() -> None:
    """Forget the cached model functions (``inference.cache.release_compiled``)."""
    _MODEL_INFO.clear()


def laplace_covariance(value_and_grad, x):
    """The inverse Hessian of the potential at ``x`` (the Laplace approximation's covariance).

    The Hessian is SciPy's finite-difference Jacobian of the compiled gradient
    (:func:`scipy.differentiate.jacobian`: central differences of order 8 with
    Richardson extrapolation), made symmetric. ``jax.hessian`` of the collapsed
    marginal (forward mode over its custom JVP rule) compiled in 4–6 s on the
    3-DOF demo, as long as the rest of NUTS's start; the differences need no
    program besides the gradient, which the MAP compiled already.

    Args:
        value_and_grad: ``x ↦ (potential, gradient)`` (:func:`potential_program`).
        x: The point (flat, unconstrained).

    Returns:
        ``(cov, ok)``: ``ok`` is whether the Hessian is finite and positive
        definite there; where it is not (a MAP on a ridge or at a boundary),
        ``cov`` is the identity, NUTS's own start.
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[0]

    def grad(points):        # SciPy evaluates several points at once: points[:, k...]
        flat = points.reshape(n, -1)
        cols = [np.asarray(value_and_grad(jnp.asarray(flat[:, k]))[1])
                for k in range(flat.shape[1])]
        return np.stack(cols, axis=-1).reshape(points.shape)

    H = scipy.differentiate.jacobian(grad, x, initial_step=_HESSIAN_STEP).df
    H = 0.5 * (H + H.T)
    ok = bool(np.all(np.isfinite(H)) and np.linalg.eigvalsh(H)[0] > 0)
    return (np.linalg.inv(H) if ok else np.eye(n)), ok


def nuts_chunk(settings: CollapsedSettings) -> int:
    """Iterations per compiled call of NUTS.

    The largest number that divides the warm-up, the first draws and each
    extension: ``gcd(num_warmup, num_samples, extend_samples)``.
    """
    return math.gcd(settings.num_warmup, settings.num_samples, settings.extend_samples)


def spread_devices(n: int) -> int:
    """How many of this process's devices ``n`` independent items (chains, draws) are spread over.

    The most devices that divide ``n``; 1 in a process with one CPU device,
    JAX's default. The CLI asks for one host device per core
    (:func:`~bayeshopf.inference.cache.configure_xla_cpu`'s ``host_devices``),
    so that its four chains run two by two on two cores.
    """
    n_dev = jax.local_device_count()
    return max(d for d in range(1, min(n_dev, n) + 1) if n % d == 0)


def _spread(fn, n_dev: int):
    """``fn`` over a leading axis split into ``n_dev`` blocks, one per device (``shard_map``).

    ``fn`` must map a block of items to the outputs for those items, each with
    the items on its leading axis; the blocks' outputs are put back in order.
    With ``n_dev == 1`` this is ``fn``.
    """
    if n_dev == 1:
        return fn
    part = PartitionSpec("items")
    return jax.shard_map(fn, mesh=_mesh(n_dev), in_specs=part, out_specs=part, check_vma=False)


def _mesh(n_dev: int) -> Mesh:
    return Mesh(np.array(jax.local_devices()[:n_dev]), ("items",))


def _place(tree, n_dev: int):
    """``tree`` split over ``n_dev`` devices along its leading axes, as ``_spread`` takes it."""
    if n_dev == 1:
        return tree
    # from host memory: splitting arrays already on one device compiles a slicing
    # program per shape (1–1.4 s with an empty cache, beside the NUTS compilations)
    return jax.device_put(jax.tree.map(np.asarray, tree), _placement(n_dev))


def _placement(n_dev: int) -> NamedSharding | None:
    """The sharding :func:`_place` gives (``None``: one device, left where it is)."""
    return None if n_dev == 1 else NamedSharding(_mesh(n_dev), PartitionSpec("items"))


def _nuts_kernel(kwargs, settings: CollapsedSettings, cov=None) -> NUTS:
    """NumPyro's NUTS on the collapsed potential (``cov``: the starting inverse mass matrix)."""
    return NUTS(potential_fn=model_functions(kwargs)[2], dense_mass=settings.dense_mass,
                inverse_mass_matrix=cov, target_accept_prob=settings.target_accept,
                max_tree_depth=settings.max_tree_depth)


def _nuts_key(kwargs, settings: CollapsedSettings) -> tuple:
    """Everything NUTS's programs close over besides the MAP point (``inference.cache``)."""
    return (model_key(kwargs), settings.num_warmup, settings.dense_mass, settings.target_accept,
            settings.max_tree_depth)


def _nuts_start(kwargs, settings: CollapsedSettings, x0, keys, cov) -> list:
    """Every chain's initial state at ``x0`` (NumPyro's ``init``), as flat leaves, compiled.

    The program holds ``x0`` (one per data set, settings and MAP point); the
    draws of a fit are those of the program that holds it.
    """
    def make_start():
        def start(keys, cov):
            nuts = _nuts_kernel(kwargs, settings, cov if settings.dense_mass else None)
            states = jax.lax.map(lambda k: nuts.init(k, settings.num_warmup, init_params=x0,
                                                     model_args=(), model_kwargs={}), keys)
            return jax.tree.leaves(states)

        return start

    return compiled_call("nuts-start", make_start, (keys, jnp.asarray(cov)),
                         key=(_nuts_key(kwargs, settings), x0))


def _nuts_init(nuts: NUTS, settings: CollapsedSettings, n: int):
    """A state of ``nuts`` at zero, for the kernel's configuration and the state's shapes.

    ``init`` sets the warm-up schedule; the state's values are not used.
    """
    return nuts.init(jax.random.PRNGKey(0), settings.num_warmup, init_params=jnp.zeros(n),
                     model_args=(), model_kwargs={})


def _nuts_states(kwargs, settings: CollapsedSettings, n: int) -> list:
    """Shapes of every chain's state as :func:`_nuts_start` returns it (traced, not run)."""
    nuts = _nuts_kernel(kwargs, settings, jnp.eye(n) if settings.dense_mass else None)
    one = jax.eval_shape(lambda: jax.tree.leaves(_nuts_init(nuts, settings, n)))
    return [jax.ShapeDtypeStruct((settings.num_chains,) + a.shape, a.dtype) for a in one]


def _nuts_advance(kwargs, settings: CollapsedSettings, n: int, n_dev: int, leaves,
                  ahead: bool = False):
    """The program that advances every chain by :func:`nuts_chunk` iterations, compiled.

    It takes the chains' states as flat leaves (as :func:`_nuts_start` gives
    them, split over ``n_dev`` devices by :func:`_place`) and returns
    ``(leaves, draws, diverging, steps)``. It does not depend on the MAP point,
    so it can be traced and compiled before the MAP is found: with ``ahead``
    it is (:func:`~bayeshopf.inference.cache.compile_ahead`), and ``None`` is
    returned. ``leaves``: the states it will be called with (arrays, or their
    shapes and placement, :func:`_nuts_states`).
    """
    chunk = nuts_chunk(settings)

    def make_advance():
        info, unravel, _ = model_functions(kwargs)

        def advance(leaves):
            nuts = _nuts_kernel(kwargs, settings)
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

        return _spread(advance, n_dev)     # draws: chain by chain, as on one device

    key = (_nuts_key(kwargs, settings), chunk, n_dev)
    if ahead:
        compile_ahead("nuts-advance", make_advance, (leaves,), key=key)
        return None
    return compiled_function("nuts-advance", make_advance, (leaves,), key=key)


def _nuts(kwargs, map_point: MapPoint, settings: CollapsedSettings, key, progress: bool):
    """NumPyro's NUTS kernel from the MAP point, chains extended until they pass.

    The mass matrix starts at the MAP's Laplace covariance (the inverse Hessian
    of the potential there) and is adapted from it. From the identity, the
    windowed adaptation spends its first windows on deep trees: on the 3-DOF demo
    35.8 leapfrog steps per warm-up iteration against 14.6 from the Laplace
    covariance (seed 0, 4 × (500 + 500); ``benchmarks/nuts_start.json``).

    Two compiled programs besides the gradient the Laplace covariance
    differences (:func:`laplace_covariance`): one starts every chain (NumPyro's
    ``init`` with that covariance); the other advances every chain by :func:`nuts_chunk`
    iterations, warm-up or draws alike (the state carries the iteration count
    and the adaptation), and is called again and again. After ``num_warmup``
    warm-up iterations and ``num_samples`` draws per chain, R̂ and bulk ESS of
    the :data:`CHECKED` sites (:func:`convergence`) decide: while one fails and
    fewer than ``max_samples`` draws per chain exist, every chain gets
    ``extend_samples`` more. The draws are those of one longer run; only its
    length depends on the diagnostics.

    On one device the chains run one after another inside each call
    (``lax.map`` over them), not vectorized: XLA's batched Cholesky and
    triangular solves are slow on CPU (NUTS stage of the 3-DOF demo: 76 s
    vectorized, 43 s sequential). Where the process has several CPU devices
    (:func:`spread_devices`), the chains are split between them
    (``shard_map``), each device running its share one after another; the
    draws are the same as on one device, as each chain's key and start are.
    One device per chain on 2 cores (4 devices, pmap) took 31 s on the rig
    against 13 s sequential; two devices of two chains each, 1.0–1.2 s per
    250 iterations against 1.4–2.0 s (a probe, ``docs/inference_core.md``).
    """
    if not 1 <= settings.num_samples <= settings.max_samples or settings.extend_samples < 1:
        raise FitError("NUTS settings: expected 1 ≤ num_samples ≤ max_samples and "
                       f"extend_samples ≥ 1; got num_samples={settings.num_samples}, "
                       f"max_samples={settings.max_samples}, "
                       f"extend_samples={settings.extend_samples}")
    x0 = ravel_pytree({k: jnp.asarray(v) for k, v in map_point.unconstrained.items()})[0]
    n_dev = spread_devices(settings.num_chains)
    keys = jax.random.split(key, settings.num_chains)
    # compiled once per data set, settings and MAP point (any seed), then loaded
    # (inference.cache); compile_programs may have started compiling them already
    cov, laplace = (laplace_covariance(potential_program(kwargs, x0.shape[0]), x0)
                    if settings.dense_mass else (np.eye(x0.shape[0]), False))
    leaves = _place(_nuts_start(kwargs, settings, x0, keys, cov), n_dev)
    advance = _nuts_advance(kwargs, settings, x0.shape[0], n_dev, leaves)
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


#: Particles of the ELBO's estimate per SVI step.
SVI_PARTICLES = 4


def _svi(kwargs, map_point: MapPoint, settings: CollapsedSettings, key, progress: bool):
    latent = {k: jnp.asarray(map_point.params[k]) for k in map_point.unconstrained}
    guide = AutoMultivariateNormal(cm.collapsed_model, init_loc_fn=init_to_value(values=latent),
                                   init_scale=0.01)
    # the particles one after another (lax.map), not vmapped: a batch of triangular solves
    # (the guide's and the collapsed likelihood's) runs on XLA's intra-op thread pool, and two
    # such batches at once can hang, each waiting for the pool (docs/changelog.md)
    svi = SVI(cm.collapsed_model, guide, optax.adam(5e-3),
              Trace_ELBO(num_particles=SVI_PARTICLES, vectorize_particles=False))
    k_run, k_draw = jax.random.split(key)
    res = svi.run(k_run, settings.svi_steps, progress_bar=progress, stable_update=True, **kwargs)
    draws = guide.sample_posterior(k_draw, res.params, sample_shape=(settings.n_svi_draws,))
    det = Predictive(cm.collapsed_model, posterior_samples=draws)(k_draw, **kwargs)
    det = {k: v for k, v in det.items()    # the deterministic sites (μ0, a2, the fold)
           if k not in draws and not k.startswith("marginal") and np.ndim(v) >= 1}
    chains = {k: np.asarray(v)[None] for k, v in {**draws, **det}.items()}
    return chains, np.asarray(res.losses)


def elbo_plateau(losses: np.ndarray, frac: float = 0.1) -> dict:
    """Whether the −ELBO has stopped falling: the last ``frac`` of the steps against the one before.

    Plateau when the mean of the last window is not below the previous window's
    by more than twice the standard error of their difference.
    """
    n = max(int(frac * losses.size), 10)
    a, b = losses[-2 * n : -n], losses[-n:]
    diff = float(a.mean() - b.mean())
    se = float(np.sqrt(a.var(ddof=1) / a.size + b.var(ddof=1) / b.size))
    return {"drop": diff, "se": se, "plateau": bool(diff < 2 * se)}


def _sample_maps(spec, kwargs, theta: dict, key) -> tuple[np.ndarray, np.ndarray | None]:
    """One exact draw of the map's (and the frequency's) coefficients per posterior draw.

    Returns:
        ``β`` ``(n, J, 2)`` and ``γ`` ``(n, 4)`` (``None`` without the frequency model).
    """
    n = len(next(iter(theta.values())))
    keys = jax.random.split(key, n)
    th = {k: jnp.asarray(v) for k, v in theta.items()}
    betas, gammas = mapped_call("maps", _map_draw(kwargs), (th, keys), key=model_key(kwargs))
    return np.asarray(betas), np.asarray(gammas) if spec.omega_centre is not None else None


def _map_draw(kwargs):
    """``(θ, key) ↦ (β, γ)``: one exact draw of the map's and the frequency's coefficients."""
    spec = kwargs["spec"]

    def one(a):
        t, k = a
        k_map, k_freq = jax.random.split(k)
        beta = cm.draw_map(spec, t, kwargs["mu"], kwargs["sign"], kwargs["coeffs"],
                           kwargs["coeffs_se"], k_map, kwargs.get("control"))
        if spec.omega_centre is None:
            return beta, jnp.zeros(0)
        return beta, cm.draw_frequency(spec, t, kwargs["mu"], kwargs["sign"], kwargs["omega"],
                                       kwargs["omega_se"], k_freq)

    return one


def pointwise_log_likelihood_draws(kwargs, theta: dict):
    """``log p(y_i | y_{−i}, θ)`` of each recording at each draw, ``(n, n_rec)``, dispatched.

    :func:`~bayeshopf.model.collapsed.pointwise_log_likelihood` over the draws
    (:func:`mapped_call`); a JAX array, computed while the caller goes on.
    """
    th = {k: jnp.asarray(v) for k, v in theta.items()}
    return mapped_call("loglik", _pointwise(kwargs), th, key=model_key(kwargs))


def _pointwise(kwargs):
    """``θ ↦ log p(y_i | y_{−i}, θ)`` of every recording (the model's blocks)."""
    def one(t):
        return cm.pointwise_log_likelihood(kwargs["spec"], t, kwargs["mu"], kwargs["sign"],
                                           kwargs["coeffs"], kwargs["coeffs_se"],
                                           kwargs["omega"], kwargs["omega_se"],
                                           kwargs.get("control"))

    return one


def mapped_call(name: str, one, items, key, ahead: bool = False):
    """``lax.map(one, items)``, compiled and stored, the items split over this process's devices.

    ``lax.map``, not ``vmap``: XLA's batched Cholesky and triangular solves are
    slow on CPU (and hung in some versions). With several CPU devices (the
    CLI's, :func:`spread_devices`) each device maps its share of the items; the
    results come back in order, the same as on one device.

    Args:
        name: The stored program's name (:func:`~bayeshopf.inference.cache.compiled_call`).
        one: Maps one item (a slice of ``items``' leaves) to its outputs.
        items: A pytree of arrays with the items on their leading axes
            (``jax.ShapeDtypeStruct`` with ``ahead``).
        key: Everything ``one`` closes over besides its input's shapes.
        ahead: Only start compiling the program for such items in the
            background (:func:`~bayeshopf.inference.cache.compile_ahead`); returns ``None``.
    """
    n_dev = spread_devices(jax.tree.leaves(items)[0].shape[0])

    def make():
        return _spread(lambda it: jax.lax.map(one, it), n_dev)

    if ahead:
        where = _placement(n_dev)
        compile_ahead(name, make, (jax.tree.map(
            lambda a: jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=where), items),),
            key=(key, n_dev))
        return None
    return compiled_call(name, make, (_place(items, n_dev),), key=(key, n_dev))


def convergence(chains: dict) -> dict:
    """R̂ and bulk ESS (ArviZ) of the :data:`CHECKED` sites present, with pass flags."""
    present = {k: v for k, v in chains.items() if k in CHECKED}
    out = {}
    if next(iter(present.values())).shape[0] < 2:
        return out
    for k, (r, e) in rhat_ess(present).items():
        out[k] = {"r_hat": r, "ess_bulk": e, "ok": bool(r <= RHAT_MAX and e >= ESS_MIN)}
    return out


@dataclass(frozen=True)
class PosteriorRun:
    """The posterior stage's raw result (immutable).

    Attributes:
        method: ``"nuts"`` or ``"svi"``.
        chains: Draws of every site, ``(n_chains, n_draws, ...)`` (SVI: one chain).
        betas: Map coefficients, one exact draw per posterior draw, ``(n, J, 2)``.
        gammas: Frequency coefficients, one exact draw per posterior draw, ``(n, 4)``,
            or ``None`` without the frequency model.
        divergences: NUTS divergent transitions (0 for SVI).
        losses: SVI −ELBO per step (empty for NUTS).
        seconds: Wall time of the stage.
        sampler: NUTS: how the mass matrix started (``"laplace"`` or ``"identity"``)
            and the mean leapfrog steps per iteration in warm-up and in the draws
            (the stage's cost, whatever the machine's load); empty for SVI.
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


def sample_posterior(kwargs: dict, map_point: MapPoint, settings: CollapsedSettings, *,
                     seed: int = 0, progress: bool = True, method: str | None = None
                     ) -> PosteriorRun:
    """NUTS or SVI from the MAP point, then one exact map draw per posterior draw."""
    ensure_x64()
    method = method or settings.inference
    if method not in ("nuts", "svi"):
        raise FitError(f"inference must be 'nuts' or 'svi'; got {method!r}")
    k_post, k_map = jax.random.split(jax.random.PRNGKey(seed))
    t0 = time.perf_counter()
    if progress:
        what = (f"{settings.num_chains} chains × {settings.num_warmup} + {settings.num_samples} "
                f"steps, up to {settings.max_samples} draws while R̂ or ESS fails"
                if method == "nuts" else f"{settings.svi_steps} steps")
        print(f"posterior: {method.upper()} on the collapsed model ({what})", file=sys.stderr)
    sampler = {}
    if method == "nuts":   # _nuts starts the imports once its first chunk is dispatched
        chains, div, sampler = _nuts(kwargs, map_point, settings, k_post, progress)
        losses = np.zeros(0)
    else:
        _preload.start()   # ArviZ (R̂ and ESS, posterior.nc) imports while SVI runs
        chains, losses = _svi(kwargs, map_point, settings, k_post, progress)
        div = 0
    pooled = {k: v.reshape((-1,) + v.shape[2:]) for k, v in chains.items()}
    theta = {k: v for k, v in pooled.items() if not k.startswith("marginal")}
    betas, gammas = _sample_maps(kwargs["spec"], kwargs, theta, k_map)
    return PosteriorRun(method, chains, betas, gammas, div, losses, time.perf_counter() - t0,
                        sampler)


#: SVI's interval ends may differ from NUTS's by this fraction of NUTS's width.
AGREEMENT_FRACTION = 0.25


def interval_agreement(reference: dict, other: dict, names=("mu0", "a2", "mu_fold"),
                       mass: float = 0.9) -> dict:
    """Compare the central ``mass`` intervals of two sets of draws, end by end.

    For each site: both intervals, the larger end difference as a fraction of
    the reference's width, and whether it is within :data:`AGREEMENT_FRACTION`.
    """
    q = [0.5 - mass / 2, 0.5 + mass / 2]
    out = {}
    for k in names:
        if k not in reference or k not in other:
            continue
        a, b = np.quantile(reference[k], q), np.quantile(other[k], q)
        gap = float(np.max(np.abs(a - b)) / (a[1] - a[0]))
        out[k] = {"reference": a.tolist(), "other": b.tolist(), "end_gap_fraction": gap,
                  "agree": bool(gap <= AGREEMENT_FRACTION)}
    return out


def compare_with_nuts(post, *, seed: int = 0, progress: bool = True) -> dict:
    """NUTS on the same collapsed model as a reference for an SVI posterior.

    Returns:
        ``{"convergence": R̂ and ESS of the NUTS chains, "sites": the interval
        agreement of SVI with NUTS per site, "agree": all sites agree}``.
    """
    ensure_x64()
    kwargs = model_arguments(post.spec, post.features)
    ref = sample_posterior(kwargs, post.map_point, post.settings, seed=seed + 1,
                           progress=progress, method="nuts")
    sites = interval_agreement(ref.samples, post.samples)
    return {"convergence": convergence(ref.chains), "divergences": ref.divergences,
            "sites": sites, "agree": all(v["agree"] for v in sites.values())}
