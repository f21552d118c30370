r"""The discrepancy in μ at the Hopf point and the fold: where the rig's bifurcations lie.

The model discrepancy (:mod:`bayeshopf.model.discrepancy`) is *vertical*: it
changes the orbit's size at each point ``x`` of the diagram. A smooth vertical
change keeps a curve's vertical tangents, so the fold, where the two branches
meet, and the Hopf point, where the orbit and its relative discrepancy vanish,
stay where the normal form puts them, however much the recordings disagree with
the model. Their *horizontal* twin is an error in μ along the diagram:

.. math::

    μ^*(x) = μ(x) + κ\, \sqrt{η^2 + φ^2}\, G\, h(x),\qquad
    h \sim \mathcal{GP}\big(0, e^{-|x - x'|^2 / 2ℓ^2}\big),\quad h(x_i) = 0,

with ``x = (μ̃, s²/\overline{s^2})`` the discrepancy's coordinates, its scale
``η`` and length ``ℓ`` (the same draws), ``G = μ_0 − μ_{SN}`` the fold–Hopf gap
(``Δμ`` without a fold), ``κ`` the size of the error in μ relative to the
gap per unit of the orbit's relative error, and ``φ`` a floor on that error:
recordings that the model fits closely (``η`` small) do not show that it
extrapolates well, so the error beyond them keeps at least the scale ``κφG``.
Below, ``η_φ = \sqrt{η^2 + φ^2}``. The process is held at zero at
the training recordings ``x_i``, whose μ is known and through which the fit
passes, so it is the error of the *extrapolation*: it grows with the distance
of the Hopf point ``x_0 = (μ̃_0, 0)`` and the fold ``x_{SN} = (μ̃_{SN}, ½/\overline{s^2})``
from the recordings, in units of ``ℓ``, and with the disagreement ``η``. The
true bifurcation points are ``μ_0 + κη_φG\,h(x_0)`` and ``μ_{SN} + κη_φG\,h(x_{SN})``
to first order, ``h`` at the two drawn jointly from the Gaussian-process
conditional (:func:`endpoint_factor`); each moves in the log of its distance
beyond the recordings that bound it (the fold stays below the lowest recording,
the Hopf point above the highest unstable one), as the model's own points do.

The recordings do not see ``h`` (it vanishes where they are), so the
likelihood is unchanged and the shift is drawn after NUTS, one standard
normal pair per posterior draw (:func:`shift_draws`): the posterior predictive
of the rig's bifurcation points under this discrepancy.

The same process moves every point of the branches, not only their ends
(:func:`branch_knots`): per draw, ``h`` is drawn at points along each branch
given zero at the recordings and the values that put the ends at the rig's
Hopf point and fold, and each point moves by ``κη_φG h``. A prediction at μ is
the model's (orbit, discrepancy, network, frequency) at the point that moves
to μ (:func:`model_mu`), so the rig's branches pass through every recording and
end at the rig's points, and a new measurement beyond the recordings carries
the horizontal error as well as the vertical one.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from bayeshopf._x64 import ensure_x64
from bayeshopf.model import discrepancy as dm
from bayeshopf.model.collapsed import spec_jit
from bayeshopf.model.spec import CollapsedSpec, radius, reference_radius

#: Jitter of the conditional covariance's Cholesky factor (the endpoints may
#: coincide with a recording's coordinates, where the conditional vanishes).
JITTER = 1e-12


def endpoint_factor(x, x_end, ell):
    """Cholesky factor ``(m, m)`` of the unit process's covariance at ``x_end`` given ``h(x) = 0``.

    ``x``: the recordings' coordinates ``(n, 2)``; ``x_end``: the endpoints'
    ``(m, 2)``; ``ell``: the length. The covariance is
    ``k(x_e, x_e) − k(x_e, x) k(x, x)⁻¹ k(x, x_e)`` (noise-free conditioning).
    """
    L = dm.unit_factor(x, ell)
    V = jax.scipy.linalg.solve_triangular(L, dm.kernel(x, x_end, 1.0, ell), lower=True)
    C = dm.kernel(x_end, x_end, 1.0, ell) - V.T @ V
    C = 0.5 * (C + C.T) + JITTER * jnp.eye(x_end.shape[0])
    return jnp.linalg.cholesky(C)


def scale_in_mu(theta: dict, kappa, floor, gap):
    """The error in μ per unit of ``h``: ``κ √(η² + φ²) G`` (module docstring)."""
    return kappa * jnp.hypot(theta["eta"], floor) * gap


def _one(spec: CollapsedSpec, theta: dict, mu, sign, kappa, floor, xi):
    """The shifts of one posterior draw ``theta`` (scalars), ``(m,)``: Hopf point, then fold."""
    a2 = theta.get("a2", -1.0)
    s = radius(spec, mu, sign, theta) / reference_radius(spec, a2)
    mean_s2 = jnp.mean(s**2)
    x = dm.coordinate(spec.mu_tilde(mu), s, s)
    ends = [jnp.stack([spec.mu_tilde(theta["mu0"]), 0.0])]
    if spec.criticality == "subcritical":
        # the fold's radius: r² = a2/2 (a2² + 4β = 0), r_ref² = a2
        ends.append(jnp.stack([spec.mu_tilde(theta["mu_fold"]), 0.5 / mean_s2]))
        gap = theta["mu0"] - theta["mu_fold"]
    else:
        gap = spec.mu_span
    F = endpoint_factor(x, jnp.stack(ends), theta["ell"])
    return scale_in_mu(theta, kappa, floor, gap) * (F @ xi[: len(ends)])


def _moved(spec: CollapsedSpec, theta: dict, eps):
    """The points moved by ``eps`` (Hopf, fold), each beyond the recordings it must lie beyond.

    A point at distance ``d`` beyond its anchor (the model's gaps: the fold
    ``g_fold`` below the lowest recording, the Hopf point ``g_hopf`` above the
    highest unstable one, or below the lowest recording without a fold) moves
    to ``d e^{±ε/d}`` from it: by ``ε`` to first order, never across the anchor.
    """
    g_h = theta["gap_hopf"]
    if spec.criticality != "subcritical":
        return [theta["mu0"] - g_h * jnp.expm1(-eps[0] / g_h)]
    g_f = theta["gap_fold"]
    return [theta["mu0"] + g_h * jnp.expm1(eps[0] / g_h),
            theta["mu_fold"] - g_f * jnp.expm1(-eps[1] / g_f)]


def shift_draws(spec: CollapsedSpec, theta: dict, mu, sign, kappa: float, key,
                floor: float = 0.0) -> dict:
    """Draws of the rig's Hopf point (and fold) under the discrepancy in μ (module docstring).

    Args:
        spec: The model (with the discrepancy, ``spec.has_discrepancy``).
        theta: Posterior draws of the sites, each ``(S,)`` (``mu0``, ``gap_hopf``,
            ``a2``, ``eta``, ``ell``, and ``mu_fold``, ``gap_fold`` and ``w_unfold``
            when subcritical).
        mu: μ of the training recordings ``(n,)``.
        sign: Their branch signs ``(n,)``.
        kappa: ``κ``; 0 gives the model's own points.
        key: JAX random key of the standard normal pair of each draw.
        floor: ``φ``, the floor on ``η`` in the scale (0: none).

    Returns:
        ``{"mu0": (S,), "mu_fold": (S,)}`` (``mu_fold`` only when subcritical).

    Raises:
        ValueError: Without the discrepancy (no ``η`` and ``ℓ`` to draw from).
    """
    if not spec.has_discrepancy:
        raise ValueError("the discrepancy in μ needs the model discrepancy (its η and ℓ); "
                         "got a model without it")
    names = ["mu0"] + (["mu_fold"] if spec.criticality == "subcritical" else [])
    th = {k: jnp.asarray(v, dtype=float) for k, v in theta.items()}
    xi = jax.random.normal(key, (th["mu0"].shape[0], 2))
    moved = spec_jit(spec, _all)(th, xi, jnp.asarray(mu, dtype=float),
                                 jnp.asarray(sign, dtype=float), jnp.asarray(kappa, dtype=float),
                                 jnp.asarray(floor, dtype=float))
    return {n: np.asarray(moved[:, j]) for j, n in enumerate(names)}


def _all(spec: CollapsedSpec, theta: dict, xi, mu, sign, kappa, floor):
    """The moved points of every draw, ``(S, m)`` (compiled once per spec, :func:`shift_draws`)."""
    return jax.vmap(lambda t, z: jnp.stack(
        _moved(spec, t, _one(spec, t, mu, sign, kappa, floor, z))))(theta, xi)


# ------------------------------------------------------------------ along the branches
#: Points drawn on each branch between its ends (:func:`branch_knots`); the move
#: is interpolated linearly between them, the recordings and the ends.
N_ALONG = 24
#: How far above the highest recording the stable branch's points reach, in
#: units of Δμ; beyond the last, its move is held.
REACH = 2.0
#: Jitter of the unit kernel's diagonal over the recordings, the two ends and
#: the points along the branches (one joint factor).
KNOT_JITTER = 1e-8


def _branches(spec: CollapsedSpec) -> tuple[float, ...]:
    """The branches' signs: unstable then stable (subcritical), or stable."""
    return (-1.0, 1.0) if spec.criticality == "subcritical" else (1.0,)


def _grid(spec: CollapsedSpec, theta: dict, mu_top):
    """Model μ of the points drawn on each branch, ``(B, N_ALONG)``, ends excluded."""
    k = jnp.arange(1, N_ALONG + 1)
    if spec.criticality == "subcritical":
        f, h = theta["mu_fold"], theta["mu0"]
        return jnp.stack([f + (h - f) * k / (N_ALONG + 1), f + (mu_top - f) * k / N_ALONG])
    return (theta["mu0"] + (mu_top - theta["mu0"]) * k / N_ALONG)[None]


def _along_one(spec: CollapsedSpec, theta: dict, ends_move, z, mu, sign, kappa, floor, mu_top):
    """One draw's moves ``κη_φG h`` at the points of :func:`_grid`, ``(B, N_ALONG)``.

    ``h`` given zero at the recordings and ``ends_move / (κη_φG)`` at the ends.
    """
    a2 = theta.get("a2", -1.0)
    r_ref = reference_radius(spec, a2)
    s = radius(spec, mu, sign, theta) / r_ref
    x = dm.coordinate(spec.mu_tilde(mu), s, s)
    ends = [jnp.stack([spec.mu_tilde(theta["mu0"]), 0.0])]
    gap = spec.mu_span
    if spec.criticality == "subcritical":
        ends.append(jnp.stack([spec.mu_tilde(theta["mu_fold"]), 0.5 / jnp.mean(s**2)]))
        gap = theta["mu0"] - theta["mu_fold"]
    grid = _grid(spec, theta, mu_top)
    xg = jnp.concatenate([dm.coordinate(spec.mu_tilde(g), radius(spec, g, b, theta) / r_ref, s)
                          for g, b in zip(grid, _branches(spec), strict=True)])
    # one factor of the joint covariance: its blocks give the conditional's mean
    # weights and factor (the jitter on the joint diagonal keeps both well posed)
    xj = jnp.concatenate([x, jnp.stack(ends), xg])
    nc = x.shape[0] + len(ends)
    L = jnp.linalg.cholesky(dm.kernel(xj, xj, 1.0, theta["ell"])
                            + KNOT_JITTER * jnp.eye(xj.shape[0]))
    known = jnp.concatenate([jnp.zeros(x.shape[0]), ends_move[: len(ends)]])
    mean = L[nc:, :nc] @ jax.scipy.linalg.solve_triangular(L[:nc, :nc], known, lower=True)
    move = mean + scale_in_mu(theta, kappa, floor, gap) * (L[nc:, nc:] @ z[: xg.shape[0]])
    return grid, move.reshape(grid.shape)


def _along_all(spec: CollapsedSpec, theta: dict, ends_move, z, mu, sign, kappa, floor, mu_top):
    """:func:`_along_one` for every draw (compiled once per spec, :func:`branch_knots`)."""
    return jax.vmap(lambda t, e, zz: _along_one(spec, t, e, zz, mu, sign, kappa, floor, mu_top))(
        theta, ends_move, z)


def branch_knots(spec: CollapsedSpec, theta: dict, rig: dict, mu, sign, kappa: float,
                 key, floor: float = 0.0) -> dict:
    """Where each branch of the rig lies: knots ``(model μ, rig μ)`` per draw and branch.

    The discrepancy in μ moves every point of the diagram, not only the two
    ends (module docstring): per draw, ``h`` is drawn jointly at
    :data:`N_ALONG` points of each branch between its ends (the stable branch
    up to :data:`REACH` ``Δμ`` above the highest recording), given zero at the
    recordings and, at the Hopf point and the fold, the values that move them to
    the rig's points ``rig`` (drawn by :func:`shift_draws`); each point moves by
    ``κη_φG h``; a point moved beyond one of its branch's ends is left out. Where
    the moves reorder two points (the process's slope above one), the knots are
    taken in the rig's order, so that the branch is a curve over μ through
    every recording.

    Args:
        spec: The model (with the discrepancy).
        theta: Posterior draws of the sites, each ``(S,)``.
        rig: The rig's points, ``{"mu0": (S,), "mu_fold": (S,)}`` (``mu_fold``
            when subcritical).
        mu: μ of the training recordings ``(n,)``.
        sign: Their branch signs ``(n,)``.
        kappa: ``κ``, as the rig's points were drawn with.
        key: JAX random key of the standard normals along the branches.
        floor: ``φ``, as the rig's points were drawn with.

    Returns:
        ``{sign: (model_mu, rig_mu)}``, each ``(S, K)``, ``rig_mu`` non-decreasing;
        a prediction at μ on that branch is the model's at :func:`model_mu`.
    """
    ensure_x64()
    sub = spec.criticality == "subcritical"
    names = ["mu0"] + (["mu_fold"] if sub else [])
    th = {k: jnp.asarray(v, dtype=float) for k, v in theta.items()}
    mu, sign = np.asarray(mu, dtype=float), np.asarray(sign, dtype=float)
    moves = np.stack([np.asarray(rig[n], float) - np.asarray(theta[n], float) for n in names]
                     + ([] if sub else [np.zeros_like(np.asarray(rig["mu0"], float))]), axis=1)
    n_draws = moves.shape[0]
    branches = _branches(spec)
    z = jax.random.normal(key, (n_draws, len(branches) * N_ALONG))
    mu_top = float(mu.max() + REACH * spec.mu_span)
    grid, move = spec_jit(spec, _along_all)(th, jnp.asarray(moves), z, jnp.asarray(mu),
                                            jnp.asarray(sign), jnp.asarray(kappa, dtype=float),
                                            jnp.asarray(floor, dtype=float), jnp.asarray(mu_top))
    grid, move = np.asarray(grid), np.asarray(move)
    start = "mu_fold" if sub else "mu0"           # where every branch starts
    out = {}
    for b, g, m in zip(branches, np.moveaxis(grid, 1, 0), np.moveaxis(move, 1, 0),
                       strict=True):
        rec = np.broadcast_to(mu[sign == b], (n_draws, int(np.sum(sign == b))))
        cols_mu = [np.asarray(theta[start], float)[:, None], g, rec]
        cols_move = [moves[:, [names.index(start)]], m, np.zeros_like(rec)]
        if sub and b < 0:                        # the unstable branch ends at the Hopf point
            cols_mu.append(np.asarray(theta["mu0"], float)[:, None])
            cols_move.append(moves[:, [0]])
        model = np.concatenate(cols_mu, axis=1)
        moved = model + np.concatenate(cols_move, axis=1)
        # a branch ends at its ends: a point moved beyond one is left out (it
        # becomes a copy of that end)
        for e in [0] + ([-1] if sub and b < 0 else []):
            beyond = moved < moved[:, :1] if e == 0 else moved > moved[:, -1:]
            model = np.where(beyond, model[:, [e]], model)
            moved = np.where(beyond, moved[:, [e]], moved)
        order = np.argsort(moved, axis=1, kind="stable")
        out[b] = (np.take_along_axis(model, order, axis=1),
                  np.take_along_axis(moved, order, axis=1))
    return out


def model_mu(mu, model, rig) -> np.ndarray:
    """The model's μ whose point the rig has at ``mu``, ``(S, n_mu)``, from :func:`branch_knots`.

    Linear between the knots of each draw; below the first and above the last,
    μ minus that knot's move (so a branch that ends there ends at the rig's point).
    """
    mu = np.atleast_1d(np.asarray(mu, dtype=float))
    out = np.empty((model.shape[0], mu.size))
    for s in range(model.shape[0]):
        out[s] = np.interp(mu, rig[s], model[s])
        lo, hi = mu < rig[s, 0], mu > rig[s, -1]
        out[s, lo] = mu[lo] - (rig[s, 0] - model[s, 0])
        out[s, hi] = mu[hi] - (rig[s, -1] - model[s, -1])
    return out
