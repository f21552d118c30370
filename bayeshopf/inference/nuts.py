"""A check of the variational posterior by NUTS chains started at the MAP.

SVI with a Gaussian autoguide (:mod:`bayeshopf.inference.svi`) describes one
mode of the posterior. Where the data leave the normal form's μ0 or fold weakly
identified, the map's network can trade off against them and the posterior has
several modes. Then the SVI band is too narrow, and nothing in the SVI output
says so. This check runs ``num_chains`` NUTS chains (NumPyro's
:class:`~numpyro.infer.NUTS`) from the fit's MAP point and compares them:

* ``R̂`` and the effective sample size of each site
  (:func:`numpyro.diagnostics.summary`);
* the median and 90% interval of μ0, a2 and the fold (or a4), chain by chain.

If the chains agree with each other and with SVI, the SVI band is trustworthy.
If they do not mix (``R̂`` above :data:`RHAT_MIXED`), the chains have found separate
modes, and their spread in μ0 and the fold is a lower bound on the spread the
data allow. The check reports this; it does not replace the SVI posterior.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import numpy as np
from numpyro import handlers
from numpyro.diagnostics import summary
from numpyro.infer import MCMC, NUTS, init_to_value

from bayeshopf.diagnostics.summaries import Interval, interval
from bayeshopf.model.probabilistic import hopf_model, model_arguments

#: ``R̂`` above which the chains are reported as not mixed.
RHAT_MIXED = 1.05

#: The quantities compared chain by chain.
CHECKED = ("mu0", "a2", "mu_fold", "a4")


@dataclass(frozen=True)
class NutsCheck:
    """NUTS chains from a fit's MAP point, compared with each other (immutable).

    Attributes:
        per_chain: ``{name: (Interval per chain)}`` for μ0, and a2 and the fold
            (subcritical) or a4 (supercritical).
        pooled: ``{name: Interval}`` over all chains.
        rhat: Largest split ``R̂`` of each sample site.
        ess: Smallest effective sample size of each sample site.
        divergences: Divergent transitions per chain.
        samples: Draws of every site, leading axes ``(num_chains, num_samples)``.
    """

    per_chain: dict
    pooled: dict
    rhat: dict
    ess: dict
    divergences: tuple
    samples: dict

    @property
    def max_rhat(self) -> float:
        """The largest ``R̂`` over every sample site."""
        return max(self.rhat.values())

    @property
    def mixed(self) -> bool:
        """Whether every site's ``R̂`` is below :data:`RHAT_MIXED`."""
        return self.max_rhat < RHAT_MIXED

    def to_json(self) -> dict:
        """JSON-serialisable summary (no draws), as written to ``summary.json``."""
        return {
            "max_rhat": self.max_rhat, "mixed": self.mixed,
            "divergences": list(self.divergences),
            "chains": {n: [iv.to_json() for iv in ivs] for n, ivs in self.per_chain.items()},
            "pooled": {n: iv.to_json() for n, iv in self.pooled.items()},
        }

    def spread(self, name: str) -> tuple[float, float]:
        """Smallest and largest per-chain median of ``name``."""
        medians = [iv.median for iv in self.per_chain[name]]
        return min(medians), max(medians)


def _latent_sites(kwargs: dict) -> list[str]:
    """Names of the model's unobserved sample sites."""
    tr = handlers.trace(handlers.seed(hopf_model, 0)).get_trace(**kwargs)
    return [k for k, v in tr.items() if v["type"] == "sample" and not v["is_observed"]]


def nuts_check(
    fit_,
    *,
    num_chains: int = 4,
    num_warmup: int = 300,
    num_samples: int = 300,
    max_tree_depth: int = 8,
    seed: int = 0,
    progress: bool = False,
) -> NutsCheck:
    """Run NUTS chains from the MAP point of ``fit_`` and compare them.

    Args:
        fit_: A :class:`~bayeshopf.pipeline.HopfFit` (its spec, features and MAP).
        num_chains: Chains, run one after the other from the same MAP point.
        num_warmup: Warm-up (step-size and mass-matrix adaptation) per chain.
        num_samples: Draws kept per chain.
        max_tree_depth: NUTS tree depth limit.
        seed: Seed of the chains.
        progress: Show NumPyro's progress bar.

    Returns:
        A :class:`NutsCheck`.
    """
    if num_chains < 2:
        raise ValueError(f"num_chains must be at least 2 to compare chains; got {num_chains}")
    kernel = NUTS(hopf_model, init_strategy=init_to_value(values=dict(fit_.map.params)),
                  max_tree_depth=max_tree_depth, target_accept_prob=0.9)
    mcmc = MCMC(kernel, num_warmup=num_warmup, num_samples=num_samples, num_chains=num_chains,
                chain_method="sequential", progress_bar=progress)
    kwargs = model_arguments(fit_.spec, fit_.features)
    mcmc.run(jax.random.PRNGKey(seed), extra_fields=("diverging",), **kwargs)
    by_chain = {k: np.asarray(v) for k, v in mcmc.get_samples(group_by_chain=True).items()}
    stats = summary({k: by_chain[k] for k in _latent_sites(kwargs)})
    rhat = {k: float(np.nanmax(v["r_hat"])) for k, v in stats.items()}
    ess = {k: float(np.nanmin(v["n_eff"])) for k, v in stats.items()}
    # a2 is fixed (−1) in the supercritical gauge, a4 in the subcritical one
    names = [n for n in CHECKED if n in by_chain and np.ptp(by_chain[n]) > 0]
    per_chain = {n: tuple(interval(c) for c in by_chain[n]) for n in names}
    pooled: dict[str, Interval] = {n: interval(by_chain[n].reshape(-1)) for n in names}
    div = np.asarray(mcmc.get_extra_fields(group_by_chain=True)["diverging"])
    return NutsCheck(per_chain=per_chain, pooled=pooled, rhat=rhat, ess=ess,
                     divergences=tuple(int(d.sum()) for d in div), samples=by_chain)
