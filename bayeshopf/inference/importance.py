r"""Importance sampling from the MAP's Laplace approximation, Pareto-smoothed, NUTS where it fails.

The collapsed model leaves a dozen nonlinear parameters, whose posterior is
often close to Gaussian around the MAP (with the discrepancy and the network
at infinite width; not μ0's long tail in the default model,
``docs/inference.md``). Draws from a multivariate Student-t proposal
``q`` there, weighted by ``w ∝ p(x | y) / q(x)`` (the potential at each
draw, no gradient), estimate the posterior; Pareto smoothing of the largest
weights (PSIS, Vehtari, Simpson, Gelman, Yao & Gabry 2024, ArviZ's
``psislw``) stabilises the estimate and its shape :math:`\hat k` says whether
it can be trusted.

1. **Round 1**: :data:`PROPOSALS` draws from ``t_ν(x̂, Σ_L)``, the MAP ``x̂``
   and its Laplace covariance ``Σ_L``
   (:func:`~bayeshopf.inference.optimum.laplace_covariance`), ``ν =``
   :data:`DF`.
2. **Round 2**: ``2 ×`` :data:`PROPOSALS` draws from ``t_ν(m, c Σ)``, the
   smoothed-weight mean and covariance of round 1, ``c =``
   :data:`INFLATION`; their weights are the estimate.
3. **Check**: :math:`\hat k ≤` :data:`K_MAX` (above it the estimate's error
   falls too slowly with the draws, Vehtari et al. 2024, §3) and Kish's
   effective sample size ``1/Σw²`` at least
   :data:`~bayeshopf.inference.nuts.ESS_MIN`. Where either fails, or the
   Laplace covariance does not exist, the posterior is NUTS's
   (:func:`~bayeshopf.inference.nuts.run_nuts`) and the reason is kept.
4. **Draws**: ``num_chains · num_samples`` draws resampled from round 2 by
   their smoothed weights (multinomial), returned as one chain.

The potential is evaluated one draw after another on each device
(:func:`~bayeshopf.inference.devices.mapped_call`), the draws split over the
process's devices; every round calls one stored program.
"""

from __future__ import annotations

import sys

import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from bayeshopf import _preload
from bayeshopf.inference import devices, nuts, optimum, programs
from bayeshopf.inference.optimum import MapPoint
from bayeshopf.inference.settings import CollapsedSettings, ModelInputs

#: Draws per call of the potential's program (round 1 makes one call, round 2 two).
PROPOSALS = 4000
#: Degrees of freedom of the Student-t proposals (heavier tails than the posterior's).
DF = 4.0
#: Round 2's covariance: round 1's weighted covariance times this.
INFLATION = 1.1
#: Largest Pareto shape k̂ of the weights accepted (Vehtari et al. 2024: 0.7).
K_MAX = 0.7


def _psis(log_w: np.ndarray) -> tuple[np.ndarray, float]:
    """Normalised Pareto-smoothed weights and their shape k̂ (ArviZ's ``psislw``)."""
    lw = np.asarray(log_w, dtype=float)
    ok = np.isfinite(lw)
    if not ok.any():
        return np.full(lw.shape, 1.0 / lw.size), np.inf
    lw = np.where(ok, lw, lw[ok].min() - 800.0)      # a draw the model rejects: weight 0
    smoothed, k = nuts.arviz().psislw(lw - lw.max())
    w = np.exp(smoothed - smoothed.max())
    return w / w.sum(), float(k)


def _round(potential, x0, cov, n_calls: int, rng) -> tuple[np.ndarray, np.ndarray, float]:
    """``n_calls · PROPOSALS`` draws from ``t_ν(x0, cov)``: ``(draws, weights, k̂)``.

    SciPy's ``stats`` is imported here, not with the module: the sampler's
    background import (:mod:`bayeshopf._preload`, ArviZ) has usually loaded it
    by then, and a fit by NUTS never needs it.
    """
    from scipy.stats import multivariate_t

    q = multivariate_t(loc=x0, shape=cov, df=DF, allow_singular=False)
    x = q.rvs(size=n_calls * PROPOSALS, random_state=rng).reshape(-1, np.size(x0))
    u = np.concatenate([np.asarray(potential(jnp.asarray(c)), dtype=float)
                        for c in np.split(x, n_calls)])
    w, k = _psis(-u - q.logpdf(x))
    return x, w, k


def potential_draws(inputs: ModelInputs, x, ahead: bool = False):
    """The potential at each flat unconstrained draw ``x`` ``(m, n)``, compiled and stored.

    :func:`~bayeshopf.inference.devices.mapped_call`, the draws split over the
    devices; with ``ahead`` (``x`` a shape) only compiled in the background.
    """
    potential = programs.model_functions(inputs)[2]
    return devices.mapped_call("potential-draws", potential, x, key=programs.model_key(inputs),
                               ahead=ahead)


def sites_at(inputs: ModelInputs, x, ahead: bool = False):
    """Every site (the deterministic ones too) at the flat unconstrained draws ``x`` ``(m, n)``.

    As :func:`potential_draws`, compiled and stored, or with ``ahead`` only compiled.
    """
    info, unravel, _ = programs.model_functions(inputs)
    return devices.mapped_call("constrain-draws", lambda xi: info.postprocess_fn(unravel(xi)),
                               x, key=programs.model_key(inputs), ahead=ahead)


def importance_draws(potential, x0, cov, n_out: int, rng) -> tuple[np.ndarray | None, dict]:
    """Rounds 1 and 2 and the check (module docstring) on any potential.

    Args:
        potential: Flat points ``(PROPOSALS, n)`` ↦ their potentials ``(PROPOSALS,)``
            (the negative log posterior up to a constant; ``inf`` or NaN where
            the model has none).
        x0: The mode, ``(n,)``.
        cov: The Laplace covariance there, ``(n, n)``.
        n_out: Draws to resample.
        rng: NumPy's random generator.

    Returns:
        ``(draws, check)``: ``draws`` ``(n_out, n)`` resampled by the smoothed
        weights, or ``None`` where the check fails; ``check`` holds
        ``pareto_k_first`` (round 1's k̂), ``pareto_k``, ``ess``, ``proposals``,
        ``df``, ``k_max``, and after a failure ``fallback``, the reason.
    """
    check = {"proposals": 3 * PROPOSALS, "df": DF, "k_max": K_MAX}
    x, w, k1 = _round(potential, x0, cov, 1, rng)
    mean = w @ x
    c = np.atleast_2d(np.cov(x.T, aweights=w)) * INFLATION
    try:
        np.linalg.cholesky(c)
    except np.linalg.LinAlgError:        # round 1's weights on too few draws: its own start
        mean, c = x0, cov
    x, w, k = _round(potential, mean, c, 2, rng)
    ess = float(1.0 / np.sum(w**2))
    check.update(pareto_k_first=k1, pareto_k=k, ess=ess)
    if k > K_MAX:
        return None, {**check, "fallback": f"Pareto k̂ {k:.2f} (at most {K_MAX} accepted)"}
    if ess < nuts.ESS_MIN:
        return None, {**check, "fallback": f"effective draws {ess:.0f} (at least "
                                           f"{nuts.ESS_MIN} needed)"}
    return x[rng.choice(x.shape[0], size=n_out, p=w)], check


def run_importance(inputs: ModelInputs, map_point: MapPoint, settings: CollapsedSettings,
                   key, progress: bool):
    """The posterior by importance sampling (:func:`importance_draws`), or NUTS's where it fails.

    Returns:
        ``(method, chains, divergences, sampler)``: ``method`` is
        ``"importance"`` (``chains`` one chain of ``num_chains · num_samples``
        resampled draws, ``sampler`` the check) or ``"nuts"``
        (:func:`~bayeshopf.inference.nuts.run_nuts`'s, with the failed check
        under ``sampler["importance"]``).
    """
    x0 = np.asarray(ravel_pytree({k: jnp.asarray(v)
                                  for k, v in map_point.unconstrained.items()})[0])
    cov, laplace = optimum.laplace_covariance(programs.potential_program(inputs, x0.size), x0)
    _preload.start()   # ArviZ (PSIS, R̂ and ESS, posterior.nc) imports beside the first round
    rng = np.random.default_rng(np.asarray(key, dtype=np.uint32).ravel().tolist())
    if laplace:
        x, check = importance_draws(lambda x: potential_draws(inputs, x), x0, cov,
                                    settings.num_chains * settings.num_samples, rng)
        if x is not None:
            out = sites_at(inputs, jnp.asarray(x))
            chains = {k: np.asarray(v)[None] for k, v in out.items()
                      if not k.startswith("marginal")}
            return "importance", chains, 0, check
    else:
        check = {"fallback": "the MAP's Hessian is not positive definite"}
    if progress:
        print(f"posterior: importance sampling not used ({check['fallback']}); NUTS instead",
              file=sys.stderr)
    chains, div, sampler = nuts.run_nuts(inputs, map_point, settings, key, progress,
                                         laplace=(cov, laplace))
    return "nuts", chains, div, {**sampler, "importance": check}
