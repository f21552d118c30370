r"""Several MAP starts, SVI from each, and their posteriors combined by stacking.

The hybrid model's posterior has more than one mode. The MLP of the map and the
normal form trade against each other, and optimisation from different starting
weights ends in different optima. On one simulated 3-DOF data set (seed 8 of
``benchmarks/calibration.md``), four starts reached negative log joints from
−154 to −232 and MAP values of μ0 from 18.256 to 18.292 m/s, while the 90%
interval of any one mode is 0.03–0.07 m/s wide. A Gaussian guide describes one
mode, so a single start gives an interval that misses the truth whenever that
start lands in a mode away from it.

Each start ``j`` gives a posterior approximation :math:`q_j`. They are combined
as the mixture :math:`\sum_j w_j q_j` with **stacking** weights (Yao, Vehtari &
Gelman 2022, *Stacking for non-mixing Bayesian computations*): the weights that
maximise the leave-one-recording-out predictive density of the mixture,

.. math::

    w = \arg\max_{w \in \Delta} \sum_i \log \sum_j w_j\, p(\Phi(R_i) \mid
        \Phi(R_{-i}), q_j),

with each :math:`p(\Phi(R_i) \mid \Phi(R_{-i}), q_j)` estimated by PSIS-LOO
(ArviZ ``compare``, through :mod:`bayeshopf.diagnostics.arviz_io`) from the
pointwise log-likelihoods of
:func:`bayeshopf.diagnostics.comparison.pointwise_log_likelihood`. A start
stuck in a poor optimum gets weight near zero; modes that predict equally well
share the weight, and the spread between them enters the intervals.
"""

from __future__ import annotations

import jax
import numpy as np

from bayeshopf.diagnostics import arviz_io
from bayeshopf.inference.results import SviResult


def stacking_weights(log_liks: list[np.ndarray]) -> np.ndarray:
    """Stacking weights of posterior approximations from their pointwise log-likelihoods.

    Args:
        log_liks: One ``(n_draws, n_obs)`` array per approximation, the same
            observations in each.

    Returns:
        Weights ``(n_approx,)``, non-negative, summing to 1.
    """
    if len(log_liks) == 1:
        return np.ones(1)
    table = arviz_io.compare({f"start{j}": ll for j, ll in enumerate(log_liks)})
    w = np.array([table[f"start{j}"]["weight"] for j in range(len(log_liks))], dtype=float)
    w = np.where(np.isfinite(w) & (w > 0), w, 0.0)
    return w / w.sum() if w.sum() > 0 else np.full(len(log_liks), 1.0 / len(log_liks))


def draw_counts(weights: np.ndarray, n_draws: int) -> np.ndarray:
    """Integer draws per component, proportional to ``weights`` and summing to ``n_draws``.

    Largest-remainder rounding, so the mixture is sampled without Monte Carlo
    noise in its proportions.
    """
    w = np.asarray(weights, dtype=float)
    exact = w / w.sum() * n_draws
    counts = np.floor(exact).astype(int)
    order = np.argsort(-(exact - counts), kind="stable")
    counts[order[: n_draws - counts.sum()]] += 1
    return counts


def mix(results: list[SviResult], weights: np.ndarray, key: jax.Array) -> SviResult:
    """The mixture ``Σ_j w_j q_j`` as one set of draws.

    Each component contributes ``draw_counts(weights, n)`` of its draws (chosen
    at random without replacement with ``key``), where ``n`` is the number of
    draws of one component; the pooled draws are shuffled. The guide
    parameters and losses returned are those of the component with the
    largest weight.
    """
    n = min(np.shape(r.samples["mu0"])[0] for r in results)
    counts = draw_counts(weights, n)
    keys = jax.random.split(key, len(results) + 1)
    parts = []
    for r, c, k in zip(results, counts, keys[1:], strict=True):
        if c:
            idx = np.asarray(jax.random.choice(k, np.shape(r.samples["mu0"])[0], (int(c),),
                                               replace=False))
            parts.append({name: np.asarray(v)[idx] for name, v in r.samples.items()})
    # shuffled, so that any leading subset of the draws is a sample of the mixture
    order = np.asarray(jax.random.permutation(keys[0], n))
    samples = {name: np.concatenate([p[name] for p in parts])[order] for name in parts[0]}
    best = results[int(np.argmax(weights))]
    return SviResult(samples=samples, guide_params=best.guide_params, losses=best.losses,
                     guide=best.guide)
