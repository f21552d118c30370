"""NumPyro's functions of the collapsed model and the compiled programs built on them.

:func:`model_functions` runs the model once per data set (NumPyro's
``initialize_model``) and keeps its potential on a flat unconstrained vector;
:func:`potential_program` and :func:`constrain_program` compile the potential's
value and gradient and the map to constrained sites, stored by
:mod:`bayeshopf.inference.cache` under :func:`model_key`. Every stage (the
start, the MAP, the Laplace covariance, NUTS) shares them.
"""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from numpyro.infer import init_to_value
from numpyro.infer.util import initialize_model

from bayeshopf.inference.cache import compile_ahead, compiled_function, on_release
from bayeshopf.inference.settings import ModelInputs
from bayeshopf.model import collapsed as cm
from bayeshopf.model import discrepancy as dm
from bayeshopf.model import horizontal as hz
from bayeshopf.model import network_kernel as nk


def model_key(inputs: ModelInputs) -> tuple:
    """What a traced function of the model closes over: the spec and the data arrays.

    The ``key`` of :func:`~bayeshopf.inference.cache.compiled_call` for the functions
    of :func:`model_functions` and the model's blocks.
    """
    return (json.dumps(inputs["spec"].to_dict(), sort_keys=True),
            {k: np.asarray(v) for k, v in inputs.items() if k != "spec"})


def _initial_values(spec: cm.CollapsedSpec) -> dict:
    """Where the model is first run: hyperparameters near their prior medians, gaps of 0.3 Δμ."""
    v = {"tau_mu": cm.TAU_MU_PRIOR[0], "tau_shape": cm.TAU_SHAPE_PRIOR[0],
         "sigma": np.full(2, 0.5 * cm.SIGMA_PRIOR * spec.orbit_scale),
         "sigma_rel": 0.5 * cm.SIGMA_REL_PRIOR,
         "gap_hopf": 0.3 * spec.mu_span}
    if spec.omega_centre is not None:
        v["sigma_omega"] = 0.5 * cm.SIGMA_OMEGA_PRIOR * spec.omega_centre
    if spec.has_discrepancy:
        v["sigma_rel_z"] = v.pop("sigma_rel") / cm.SIGMA_REL_PRIOR   # σ_rel = S|z|
        v["eta"] = 0.5 * dm.ETA_PRIOR
        v["ell"] = dm.LENGTH_PRIOR[0]
    if spec.samples_nu_mu:
        v["nu_mu"] = nk.NU_PRIOR[0]
    if spec.criticality == "subcritical":
        v["gap_fold"] = 0.3 * spec.mu_span
        if spec.unfolding == "curved":
            v["w_unfold"] = 0.0
        if spec.unfolding == "horizontal":
            v.update(eta_h=0.5 * hz.ETA_PRIOR, ell_h=hz.LENGTH_PRIOR[0],
                     z_h=np.zeros(hz.N_BASIS))
        if spec.unfolding == "window":
            v.update(depth_h=0.0, width_h=hz.WINDOW_WIDTH_PRIOR[0])
    else:
        v["kappa"] = 0.3 / spec.mu_span
    return {k: jnp.asarray(x, dtype=float) for k, x in v.items()}


#: The last data set's model functions (:func:`model_functions`).
_MODEL_INFO: dict = {}


def model_functions(inputs: ModelInputs):
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
    args = tuple(inputs.items())
    hit = _MODEL_INFO.get("last")
    if (hit is not None and len(hit[0]) == len(args)
            and all(k == k2 and v is v2 for (k, v), (k2, v2) in zip(hit[0], args, strict=True))):
        return hit[1]
    # validate_grad=False: no eager gradient of the model (run operation by operation,
    # it costs more than the model's run itself); the MAP and NUTS compute theirs compiled
    init = _initial_values(inputs["spec"])
    info = initialize_model(jax.random.PRNGKey(0), cm.collapsed_model, model_kwargs=dict(inputs),
                            init_strategy=init_to_value(values=init), validate_grad=False)
    unravel = ravel_pytree(info.param_info.z)[1]

    def potential(x):
        return info.potential_fn(unravel(x))

    _MODEL_INFO["last"] = (args, (info, unravel, potential))   # one data set at a time
    return _MODEL_INFO["last"][1]


@on_release
def clear_model_functions() -> None:
    """Forget the cached model functions (``inference.cache.release_compiled``)."""
    _MODEL_INFO.clear()


on_release(cm.clear_jits)


def potential_program(inputs: ModelInputs, n: int, ahead: bool = False):
    """The potential's value and gradient at a flat unconstrained vector, compiled.

    One program per data set and settings, stored
    (:func:`~bayeshopf.inference.cache.compiled_function`),
    shared by the start, the MAP's L-BFGS and the Laplace covariance of NUTS's start.
    With ``ahead``, compiled in the background instead
    (:func:`~bayeshopf.inference.cache.compile_ahead`) and ``None`` returned.
    """
    def make():
        return jax.value_and_grad(model_functions(inputs)[2])

    args, key = (jax.ShapeDtypeStruct((n,), jnp.float64),), model_key(inputs)
    if ahead:
        compile_ahead("value-and-grad", make, args, key=key)
        return None
    return compiled_function("value-and-grad", make, args, key=key)


def constrain_program(inputs: ModelInputs, n: int):
    """A flat unconstrained vector as dicts, compiled: ``{"params", "unconstrained"}``.

    ``params``: the constrained value of every site, the deterministic ones (μ0,
    a2, the fold) too; ``unconstrained``: the vector's sites in NumPyro's
    unconstrained space.
    """
    def make():
        info, unravel, _ = model_functions(inputs)
        return lambda x: {"params": info.postprocess_fn(unravel(x)), "unconstrained": unravel(x)}

    return compiled_function("constrain", make, (jnp.zeros(n),), key=model_key(inputs))
