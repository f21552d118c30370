"""SVI on the collapsed model, its convergence test, and its agreement with NUTS.

A full-rank Gaussian autoguide started at the MAP point, with an ELBO-plateau
test (:func:`elbo_plateau`); :func:`interval_agreement` compares its intervals
with those of NUTS on the same model.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optax
from numpyro.infer import SVI, Predictive, Trace_ELBO, init_to_value
from numpyro.infer.autoguide import AutoMultivariateNormal

from bayeshopf.inference.optimum import MapPoint
from bayeshopf.inference.settings import CollapsedSettings, ModelInputs
from bayeshopf.model import collapsed as cm

#: Particles of the ELBO's estimate per SVI step.
SVI_PARTICLES = 4


def run_svi(inputs: ModelInputs, map_point: MapPoint, settings: CollapsedSettings, key,
            progress: bool):
    """A full-rank Gaussian guide from the MAP point: ``(chains, losses)``, one chain."""
    latent = {k: jnp.asarray(map_point.params[k]) for k in map_point.unconstrained}
    guide = AutoMultivariateNormal(cm.collapsed_model, init_loc_fn=init_to_value(values=latent),
                                   init_scale=0.01)
    # the particles one after another (lax.map), not vmapped: a batch of triangular solves
    # (the guide's and the collapsed likelihood's) runs on XLA's intra-op thread pool, and two
    # such batches at once can hang, each waiting for the pool (docs/changelog.md)
    svi = SVI(cm.collapsed_model, guide, optax.adam(5e-3),
              Trace_ELBO(num_particles=SVI_PARTICLES, vectorize_particles=False))
    k_run, k_draw = jax.random.split(key)
    res = svi.run(k_run, settings.svi_steps, progress_bar=progress, stable_update=True, **inputs)
    draws = guide.sample_posterior(k_draw, res.params, sample_shape=(settings.n_svi_draws,))
    det = Predictive(cm.collapsed_model, posterior_samples=draws)(k_draw, **inputs)
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
