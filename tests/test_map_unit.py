"""The MAP stage on models with closed-form optima (independent of the Hopf model)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

from bayeshopf.inference.map import fit_map


def _model(y=None):
    m = numpyro.sample("m", dist.Normal(0.0, 1.0))
    s = numpyro.sample("s", dist.LogNormal(0.0, 1.0))
    numpyro.sample("y", dist.Normal(m, s).expand([8]), obs=y)


Y = jnp.array([3.1, 2.4, 3.9, 2.8, 3.3, 2.0, 3.6, 2.9])


def _fit(regularised):
    return fit_map(_model, {"y": Y}, {"m": 0.5, "s": 1.0}, key=jax.random.PRNGKey(0),
                   adam_steps=400, lbfgs_steps=200, progress=False, regularised=regularised)


def test_maximum_likelihood_is_the_sample_mean_and_sd():
    """Without priors the optimum is the Gaussian MLE: mean and the 1/n standard deviation."""
    p = _fit(False).params
    assert abs(float(p["m"]) - float(Y.mean())) < 1e-6
    assert abs(float(p["s"]) - float(Y.std())) < 1e-6


def test_map_is_shrunk_towards_the_prior():
    """With the N(0, 1) prior the mean is pulled below the sample mean."""
    ml, mp = _fit(False).params, _fit(True).params
    assert float(mp["m"]) < float(ml["m"]) - 0.05
    # and it is the stationary point of the log joint: check by finite differences
    def log_joint(m, s):
        return (dist.Normal(0, 1).log_prob(m) + dist.LogNormal(0, 1).log_prob(s)
                + dist.Normal(m, s).log_prob(Y).sum() + jnp.log(s))  # + Jacobian of log s
    g = jax.grad(log_joint, argnums=(0, 1))(jnp.asarray(mp["m"]), jnp.asarray(mp["s"]))
    assert np.allclose([float(g[0]), float(g[1]) * float(mp["s"])], 0.0, atol=1e-5)
