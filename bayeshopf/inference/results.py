"""Immutable result records of the inference stages (in the style of diffrax's ``Solution``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MapResult:
    """Maximum a posteriori fit.

    Attributes:
        params: Constrained values of every sample and deterministic site.
        unconstrained: The optimum in NumPyro's unconstrained space.
        losses: Negative log joint density after each step (Adam, then L-BFGS).
        n_adam: Number of Adam steps (the L-BFGS steps follow).
        converged: Whether the L-BFGS gradient norm fell below its tolerance.
        grad_norm: Final gradient norm in unconstrained space.
    """

    params: dict
    unconstrained: dict
    losses: np.ndarray
    n_adam: int
    converged: bool
    grad_norm: float


@dataclass(frozen=True)
class SviResult:
    """Stochastic variational inference from the MAP point.

    Attributes:
        samples: Posterior draws of every site, each with leading axis ``n_draws``.
        guide_params: Variational parameters of the autoguide.
        losses: ELBO loss (negative ELBO) at each step.
        guide: Name of the autoguide used.
    """

    samples: dict
    guide_params: dict
    losses: np.ndarray
    guide: str
