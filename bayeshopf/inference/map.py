"""MAP: minimise the negative log joint with optax Adam, then L-BFGS."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
import optax
from numpyro.handlers import Messenger
from numpyro.infer.initialization import init_to_value
from numpyro.infer.util import initialize_model

from bayeshopf.inference._progress import run_chunked
from bayeshopf.inference.results import MapResult


class likelihood_only(Messenger):
    """Handler that drops every log density but that of the observed sites.

    Under it NumPyro's potential energy is the negative log likelihood (the
    priors and the Jacobians of the constraining transforms are scaled by 0), so
    :func:`fit_map` returns the maximum-likelihood point: the paper's
    point-estimate fit, without priors.
    """

    def process_message(self, msg):
        """Scale the log density of every latent site (and Jacobian factor) by 0."""
        if msg["type"] == "sample" and not (msg["is_observed"] and not msg["name"].startswith("_")):
            msg["scale"] = 0.0 if msg["scale"] is None else 0.0 * msg["scale"]


def fit_map(
    model: Callable,
    model_kwargs: dict,
    init_values: dict,
    *,
    key: jax.Array,
    adam_steps: int = 1500,
    lbfgs_steps: int = 500,
    learning_rate: float = 1e-2,
    gtol: float = 1e-6,
    progress: bool = True,
    regularised: bool = True,
) -> MapResult:
    """Maximum a posteriori estimate of a NumPyro model.

    The negative log joint (NumPyro's potential energy, with the Jacobians of
    the constraining transforms) is minimised in unconstrained space: Adam first
    (robust far from the optimum), then L-BFGS with a zoom line search (fast near
    it).

    Args:
        model: NumPyro model.
        model_kwargs: Keyword arguments of the model (data included).
        init_values: Constrained starting values of some sites; the others start
            from a draw of ``init_to_value``'s fallback (uniform in ``[-2, 2]``
            in unconstrained space) with ``key``.
        key: PRNG key.
        adam_steps: Adam iterations.
        lbfgs_steps: L-BFGS iterations.
        learning_rate: Adam step size.
        gtol: Gradient-norm tolerance that counts as converged.
        progress: Show progress bars.
        regularised: ``False`` drops the priors (:class:`likelihood_only`):
            maximum likelihood instead of MAP.

    Returns:
        A :class:`MapResult`.
    """
    if not regularised:
        model = likelihood_only(model)
    info = initialize_model(
        key,
        model,
        model_kwargs=model_kwargs,
        init_strategy=init_to_value(values={k: jnp.asarray(v) for k, v in init_values.items()}),
    )
    potential = info.potential_fn
    z0 = info.param_info.z

    adam = optax.adam(learning_rate)

    def adam_step(carry):
        z, state = carry
        loss, g = jax.value_and_grad(potential)(z)
        updates, state = adam.update(g, state, z)
        return (optax.apply_updates(z, updates), state), loss

    (z, _), l1 = run_chunked(
        adam_step, (z0, adam.init(z0)), adam_steps, desc="MAP (Adam)", progress=progress
    )

    lbfgs = optax.lbfgs()
    value_and_grad = optax.value_and_grad_from_state(potential)

    def lbfgs_step(carry):
        z, state = carry
        loss, g = value_and_grad(z, state=state)
        updates, state = lbfgs.update(g, state, z, value=loss, grad=g, value_fn=potential)
        return (optax.apply_updates(z, updates), state), loss

    (z, _), l2 = run_chunked(
        lbfgs_step, (z, lbfgs.init(z)), lbfgs_steps,
        desc="MAP (L-BFGS)", progress=progress, chunk=50,
    )
    g = jax.grad(potential)(z)
    gnorm = float(optax.tree.norm(g)) if hasattr(optax, "tree") else float(
        jnp.sqrt(sum(jnp.sum(x**2) for x in jax.tree.leaves(g)))
    )
    params = {k: np.asarray(v) for k, v in info.postprocess_fn(z).items()}
    return MapResult(
        params=params,
        unconstrained={k: np.asarray(v) for k, v in z.items()},
        losses=np.concatenate([l1, l2]),
        n_adam=adam_steps,
        converged=bool(gnorm < gtol * max(1.0, abs(float(l2[-1]) if l2.size else 1.0))),
        grad_norm=gnorm,
    )
