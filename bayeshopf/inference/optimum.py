"""The deterministic start, the MAP and the Laplace covariance of the collapsed model.

1. **Start.** A grid over the two gaps (fractions of Δμ), the hyperparameters
   at their prior medians; the grid point with the highest log joint is kept.
   Nothing is random, so the answer does not depend on which start won.
2. **MAP** by SciPy's L-BFGS-B from that point, in NumPyro's unconstrained
   space, on the compiled potential and gradient
   (:func:`~bayeshopf.inference.programs.potential_program`), until the
   gradient norm falls below :data:`MAP_GTOL` (finished by a root find on the
   gradient where the line search stops at the value's rounding).
3. **Laplace covariance**: the inverse Hessian of the potential at the MAP,
   NUTS's starting mass matrix (:func:`laplace_covariance`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import scipy.differentiate
import scipy.optimize
from jax.flatten_util import ravel_pytree

from bayeshopf._x64 import ensure_x64
from bayeshopf.errors import FitError
from bayeshopf.inference import programs
from bayeshopf.inference.cache import compiled_call
from bayeshopf.inference.settings import ModelInputs

#: Gradient norm (unconstrained space) below which the MAP counts as converged.
MAP_GTOL = 1e-4
#: Grid of the deterministic start, as fractions of Δμ for both gaps.
START_GRID = (0.03, 0.1, 0.3, 1.0)
#: What L-BFGS-B is told where the potential is not finite (it then shortens the step).
_NOT_FINITE = 1e100
#: First step of the finite differences of the Laplace covariance (unconstrained units).
_HESSIAN_STEP = 0.05


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


def fit_map(inputs: ModelInputs, *, max_steps: int = 300) -> MapPoint:
    """Deterministic start (grid over the gaps), then L-BFGS to the MAP (module docstring).

    Three small compiled programs, each stored for the next process: the grid of
    starts (flat unconstrained vectors), the potential's value and gradient
    (:func:`~bayeshopf.inference.programs.potential_program`) and the constrained
    sites (:func:`~bayeshopf.inference.programs.constrain_program`).
    The optimiser is SciPy's L-BFGS-B, driven from Python: the single compiled
    program of optax's L-BFGS with its zoom line search holds the potential and
    its gradient several times over, and compiling it takes several times longer
    than compiling one value and gradient. Where L-BFGS-B stops short of
    :data:`MAP_GTOL` (its line search needs the value to fall, and on precise
    data the value's rounding stops it), SciPy's root find on the gradient
    (MINPACK's hybrd) finishes, and is kept only where it lowers the gradient
    norm without raising the value.
    """
    ensure_x64()
    spec = inputs["spec"]
    names = ("gap_fold", "gap_hopf") if spec.criticality == "subcritical" else ("gap_hopf",
                                                                                  "kappa")
    scale = [1 / spec.mu_span if n == "kappa" else spec.mu_span for n in names]
    gaps = jnp.log(jnp.array([[g1 * scale[0], g2 * scale[1]]
                              for g1, g2 in itertools.product(START_GRID, repeat=2)]))

    def make_grid():
        info, _, _ = programs.model_functions(inputs)

        def start(g):      # the deterministic start with the two gaps set (unconstrained)
            z = dict(info.param_info.z)
            z[names[0]], z[names[1]] = g[0], g[1]
            return ravel_pytree(z)[0]

        return jax.vmap(start)

    grid = np.asarray(compiled_call("map-grid", make_grid, (gaps,),
                                    key=programs.model_key(inputs)))
    value_and_grad = programs.potential_program(inputs, grid.shape[1])

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
        # on precise data the value carries rounding noise (the marginal's factorisation
        # of an ill-conditioned matrix), so L-BFGS-B's line search, which needs the value
        # to fall, stops once a step gains less, short of the tolerance. The gradient is
        # precise there, so a root find on it (MINPACK's hybrd) finishes
        root = scipy.optimize.root(lambda z: fun(z)[1], x, method="hybr")
        v_root, g_root = fun(np.asarray(root.x, dtype=float))
        if (np.linalg.norm(g_root) < np.linalg.norm(g)
                and v_root <= v + 1e-9 * max(1.0, abs(v))):  # not a saddle above the optimum
            x, v, g, polish = np.asarray(root.x, dtype=float), v_root, g_root, int(root.nfev)
    gnorm = float(np.linalg.norm(g))
    constrain = programs.constrain_program(inputs, grid.shape[1])
    at_map, at_start = constrain(jnp.asarray(x)), constrain(jnp.asarray(grid[best]))
    return MapPoint(
        params={k: np.asarray(val) for k, val in at_map["params"].items()},
        unconstrained={k: np.asarray(val) for k, val in at_map["unconstrained"].items()},
        log_joint=-v, grad_norm=gnorm, converged=gnorm < MAP_GTOL, n_steps=int(res.nit),
        start={k: np.asarray(val) for k, val in at_start["params"].items()},
        polish_evaluations=polish,
    )


def laplace_covariance(value_and_grad, x):
    """The inverse Hessian of the potential at ``x`` (the Laplace approximation's covariance).

    The Hessian is SciPy's finite-difference Jacobian of the compiled gradient
    (:func:`scipy.differentiate.jacobian`: central differences of order 8 with
    Richardson extrapolation), made symmetric. ``jax.hessian`` of the collapsed
    marginal (forward mode over its custom JVP rule) is one more program, whose
    compilation takes as long as the rest of NUTS's start; the differences need no
    program besides the gradient, which the MAP compiled already.

    Args:
        value_and_grad: ``x ↦ (potential, gradient)``
            (:func:`~bayeshopf.inference.programs.potential_program`).
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
