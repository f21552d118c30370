"""SVI from the MAP point with a NumPyro autoguide."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
import optax
from numpyro.infer import SVI, Predictive, Trace_ELBO
from numpyro.infer.autoguide import AutoLowRankMultivariateNormal, AutoMultivariateNormal
from numpyro.infer.initialization import init_to_value

from bayeshopf.inference.results import MapResult, SviResult

#: Autoguides. ``"lowrank"`` is the default: NumPyro parameterises its
#: covariance as ``diag(s) (W Wᵀ + I) diag(s)``, so the correlations ``W`` are
#: relative to the scales ``s``. The full-rank guide's Cholesky factor has
#: absolute off-diagonal entries; Adam's first step moves each of them by the
#: learning rate (5e-3), fifty times the initial scale below, and on two of 20
#: simulated 3-DOF data sets (seeds 10 and 17 of ``benchmarks/calibration.md``)
#: the ELBO loss jumped to 1e12 and the guide never recovered: intervals of
#: zero width, missing the truth. The low-rank guide from the same MAP points
#: gave finite, covering intervals on both.
GUIDES = {"lowrank": AutoLowRankMultivariateNormal, "mvn": AutoMultivariateNormal}
#: Initial standard deviation of the guide in unconstrained space. It must be
#: below the posterior's smallest conditional scale. With long, low-noise
#: records (20 s at 500 Hz, 1 % noise: simulated 3-DOF flutter) that scale is
#: ~1e-3, and a guide started at 1e-2 overestimates it in the stiff directions
#: for most of the run; the expected log density it maximises then rewards
#: regions where the stiff directions are flatter, and its location drifts away
#: from the MAP point by several posterior widths (μ0 0.06–0.3 m/s too high, the
#: 90% intervals missing the truth in 4 of 5 seeds). Started at 1e-4 it stays
#: at the MAP point and grows where the posterior is wide (see
#: benchmarks/calibration.md).
INIT_SCALE = 1e-4


def fit_svi(
    model: Callable,
    model_kwargs: dict,
    map_result: MapResult,
    *,
    key: jax.Array,
    steps: int = 3000,
    learning_rate: float = 5e-3,
    num_particles: int = 4,
    guide: str = "lowrank",
    init_scale: float = INIT_SCALE,
    n_draws: int = 1000,
    progress: bool = True,
    obs_name: str = "coeffs",
) -> SviResult:
    """Variational posterior started at the MAP point.

    The autoguide's location starts at the MAP values (``init_to_value``), its
    scale at ``init_scale`` in unconstrained space, and the ELBO is maximised
    with Adam.

    Args:
        model: NumPyro model.
        model_kwargs: Keyword arguments of the model (data included).
        map_result: The MAP fit to start from.
        key: PRNG key.
        steps: SVI iterations.
        learning_rate: Adam step size.
        num_particles: Monte Carlo samples per ELBO estimate.
        guide: ``"lowrank"`` (low-rank plus diagonal) or ``"mvn"`` (full-rank
            multivariate normal); see :data:`GUIDES`.
        init_scale: Initial standard deviation of the guide.
        n_draws: Posterior draws to return.
        progress: Show a progress bar.
        obs_name: Keyword argument of the model holding the observations; it is
            set to ``None`` for the posterior predictive draws, which are
            returned as ``<obs_name>_rep``.

    Returns:
        A :class:`SviResult` with ``n_draws`` posterior draws of every site.
    """
    if guide not in GUIDES:
        raise ValueError(f"guide must be one of {sorted(GUIDES)}; got {guide!r}")
    latent = {k: jnp.asarray(v) for k, v in map_result.params.items()}
    g = GUIDES[guide](model, init_loc_fn=init_to_value(values=latent), init_scale=init_scale)
    svi = SVI(model, g, optax.adam(learning_rate), Trace_ELBO(num_particles=num_particles))
    k_run, k_draw = jax.random.split(key)
    res = svi.run(k_run, steps, progress_bar=progress, stable_update=True, **model_kwargs)

    latent_draws = g.sample_posterior(k_draw, res.params, sample_shape=(n_draws,))
    # deterministic sites (mu0, a2, mu_fold, coeffs_hat) for every draw
    predictive = Predictive(model, posterior_samples=latent_draws, return_sites=None)
    det = jax.jit(lambda k: predictive(k, **{**model_kwargs, obs_name: None}))(k_draw)
    samples = {k: np.asarray(v) for k, v in {**latent_draws, **det}.items()}
    if obs_name in samples:  # posterior predictive draws of the data (Φ(R) by default)
        samples[f"{obs_name}_rep"] = samples.pop(obs_name)
    return SviResult(
        samples=samples,
        guide_params={k: np.asarray(v) for k, v in res.params.items()},
        losses=np.asarray(res.losses),
        guide=guide,
    )
