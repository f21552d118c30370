r""""Unexplained" as a model: the calibrated simulator plus a smooth discrepancy.

A mismatch that neither the parameters nor a library term account for is not
the absence of a model; it is a model with its own evidence. :math:`M_D` is
:math:`M_P` (the uncertain parameters calibrated, no term) plus a discrepancy
:math:`\Delta` on the orbits' fundamentals, the same kind as the core's model
discrepancy (:mod:`bayeshopf.model.discrepancy`, Kennedy & O'Hagan 2001):

.. math::

    y_{rj} = f_{rj}(\theta) + \Delta_j(x_r) + \varepsilon_{rj}, \qquad
    \operatorname{Cov}\big(\Delta_j(x_r), \Delta_j(x_{r'})\big)
        = \eta^2\,\mathrm{ref}_{rj}\,\mathrm{ref}_{r'j}\,
          e^{-\lVert x_r - x_{r'}\rVert^2 / 2\ell^2},

independent between the features :math:`j` of the fundamental (each channel's
first-harmonic coefficients) and the frequency, zero on the other features.
:math:`\mathrm{ref}` is the scale of the relative model error τ
(:class:`~bayeshopf.discrepancy.select.Fitter`: the channel's first-harmonic
magnitude; a tenth of the frequency for the frequency), so :math:`\eta` is a
relative error of the fundamental that varies smoothly over the diagram, where
:math:`x_r = (\tilde\mu_r, s_r^2/\overline{s^2})`: :math:`\tilde\mu = (\mu -
\mu_c)/\Delta\mu` and :math:`s_r` the first channel's first-harmonic magnitude
(orbits on both sides of a fold that are nearly the same orbit share their
discrepancy; a stable and an unstable orbit at one μ need not). Priors as the
core's: :math:`\eta \sim \mathrm{HalfNormal}` (:data:`ETA_PRIOR`),
:math:`\ell \sim \mathrm{LogNormal}` (:data:`LENGTH_PRIOR`), τ log-uniform as
in every model.

**Evidence.** :math:`\Delta` is Gaussian and linear, so it is integrated out
exactly: at each :math:`(\tau, \eta, \ell)` the rows of each smooth feature
(found orbits only) are whitened by the Cholesky factor of
:math:`I + \eta^2 W K W`, :math:`W = \mathrm{diag}(\mathrm{ref}/\sigma(\tau))`,
and the Laplace evidence of the parameters is taken on the linear model at
:math:`M_P`'s mode (:mod:`~bayeshopf.discrepancy.evidence`). The hyperparameters
are integrated on geometric grids (:data:`ETA_RANGE`, :data:`ELL_RANGE`), each
point weighted by its cell's prior mass (the end cells reach to the prior's
ends), and τ on every :data:`TAU_STRIDE`-th point of
:data:`~bayeshopf.discrepancy.evidence.TAU`.
The Bayes factor against :math:`M_P` is formed between the two linear models on
the same grids, and added to :math:`M_P`'s evidence, so that :math:`M_D` pays
the same linearisation charge as :math:`M_P` and equals it at :math:`\eta = 0`.
"""

from __future__ import annotations

import numpy as np
from scipy import special, stats

from bayeshopf.discrepancy.evidence import TAU, _rewhiten, laplace_evidence
from bayeshopf.discrepancy.records import Calibration, Unexplained
from bayeshopf.discrepancy.select import Fitter
from bayeshopf.model.discrepancy import ETA_PRIOR, LENGTH_PRIOR, coordinate

__all__ = ["ELL_RANGE", "ETA_PRIOR", "ETA_RANGE", "LENGTH_PRIOR", "N_ELL", "N_ETA",
           "TAU_STRIDE", "Unexplained",
           "diagram_inputs", "evidence_grid", "smooth_columns", "unexplained"]

#: Points of η's grid, geometric over :data:`ETA_RANGE`.
N_ETA = 40
#: η's grid range: from where the discrepancy is M_P's to ten prior scales.
ETA_RANGE = (1e-4, 10 * ETA_PRIOR)
#: Points of ℓ's grid, geometric over :data:`ELL_RANGE`.
N_ELL = 9
#: ℓ's grid range: the prior's median times e^(±3.2 log-sd) (99.9% of its mass).
ELL_RANGE = (LENGTH_PRIOR[0] * np.exp(-3.2 * LENGTH_PRIOR[1]),
             LENGTH_PRIOR[0] * np.exp(3.2 * LENGTH_PRIOR[1]))
#: τ on every this-th point of ``TAU``.
TAU_STRIDE = 5


def smooth_columns(fitter: Fitter) -> list[int]:
    """The features that carry the smooth discrepancy: fundamentals and the frequency."""
    lay = fitter.mf.layout
    return [j for j, (k, h) in enumerate(zip(lay.kind, lay.harmonic, strict=True))
            if k == "f" or (k == "harm" and h == 1)]


def diagram_inputs(fitter: Fitter) -> np.ndarray:
    r"""``x_r = (μ̃_r, s_r²/mean s²)``, shape ``(R, 2)`` (module docstring)."""
    mf = fitter.mf
    mu = np.asarray(mf.mu, dtype=float)
    span = float(mu.max() - mu.min()) or 1.0
    mu_t = (mu - 0.5 * (mu.max() + mu.min())) / span
    lab = mf.layout.labels
    c = mf.layout.channels[0]
    s2 = mf.y[:, lab.index(f"{c}:Re1")] ** 2
    if f"{c}:Im1" in lab:
        s2 = s2 + mf.y[:, lab.index(f"{c}:Im1")] ** 2
    s = np.sqrt(s2)
    return np.asarray(coordinate(mu_t, s, s))


def _grid(dist, lo: float, hi: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A geometric grid on ``[lo, hi]`` and its prior weights (the prior's mass in each cell).

    Cells end at the geometric midpoints; the first reaches down to the
    distribution's lower end and the last up to its upper end, so the weights
    sum to 1 and a posterior that piles at an end of the grid is not cut off
    by the grid's placement.
    """
    g = np.geomspace(lo, hi, n)
    mid = np.sqrt(g[1:] * g[:-1])
    cdf = np.concatenate([[0.0], dist.cdf(mid), [1.0]])
    return g, np.diff(cdf)


def evidence_grid(E: np.ndarray, G: np.ndarray, rows: dict[int, np.ndarray],
                  W: dict[int, np.ndarray], etas: np.ndarray, kernels: np.ndarray
                  ) -> np.ndarray:
    r"""Laplace log evidence of :math:`E + G\delta` with the discrepancy integrated out.

    At every ``(η, kernel K)``, shape ``(len(etas), len(kernels))``: each
    feature ``j``'s rows ``rows[j]`` of the whitened residuals get the
    covariance :math:`C_j = I + \eta^2 (w_j w_j^\top) \circ K` (``w_j = W[j]``,
    the discrepancy's scale over the noise); they are whitened by the Cholesky
    factor :math:`L_j` of :math:`C_j`, and :math:`-\sum \log\operatorname{diag} L_j`
    is added (:func:`~bayeshopf.discrepancy.evidence.laplace_evidence` for the
    rest). The rows off the discrepancy enter :math:`H = G^\top G`,
    :math:`b = G^\top E` and :math:`\lVert E\rVert^2` once.
    """
    gp = np.concatenate(list(rows.values())) if rows else np.zeros(0, int)
    rest = np.setdiff1d(np.arange(E.size), gp)
    H = np.broadcast_to(G[rest].T @ G[rest], (len(etas), len(kernels)) + (G.shape[1],) * 2
                        ).copy()
    b = np.broadcast_to(G[rest].T @ E[rest], (len(etas), len(kernels), G.shape[1])).copy()
    ee = np.full((len(etas), len(kernels)), float(E[rest] @ E[rest]))
    logdet_c = np.zeros((len(etas), len(kernels)))
    K = np.asarray(kernels)
    e2 = np.asarray(etas, float)[:, None, None, None] ** 2
    for j, r in rows.items():
        w = W[j]
        C = np.eye(r.size) + e2 * (np.outer(w, w) * K)[None]       # (η, ℓ, n, n)
        L = np.linalg.cholesky(C)
        rhs = np.concatenate([E[r][:, None], G[r]], axis=1)          # (n, 1 + d)
        Z = np.linalg.solve(L, np.broadcast_to(rhs, L.shape[:2] + rhs.shape))
        ze, zg = Z[..., 0], Z[..., 1:]
        H += np.einsum("...na,...nb->...ab", zg, zg)
        b += np.einsum("...na,...n->...a", zg, ze)
        ee += np.einsum("...n,...n->...", ze, ze)
        logdet_c += np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)
    sol = np.linalg.solve(H, b[..., None])[..., 0]
    logdet_h = np.linalg.slogdet(H)[1]
    return -0.5 * (ee - np.einsum("...a,...a->...", b, sol)) - 0.5 * logdet_h - logdet_c


def unexplained(cal: Calibration) -> Unexplained:
    """:math:`M_D` at the calibration ``cal`` (:math:`M_P`'s mode): evidence and η's posterior.

    Args:
        cal: The parameters calibrated with no term (its ``fitter``, mode,
            residuals, Jacobian and orbits).

    Returns:
        An :class:`Unexplained`.
    """
    fitter: Fitter = cal.fitter
    P = fitter.mf.y.shape[1]
    ok = np.asarray(cal.orbits.ok, bool)
    d = cal.z_mode.size
    E = np.concatenate([np.asarray(cal.e_mode).ravel(), cal.z_mode])
    G = np.concatenate([np.asarray(cal.jac), np.eye(d)])
    X = diagram_inputs(fitter)[ok]
    d2 = np.sum((X[:, None, :] - X[None, :, :]) ** 2, axis=-1)
    etas, p_eta = _grid(stats.halfnorm(scale=ETA_PRIOR), *ETA_RANGE, N_ETA)
    ells, p_ell = _grid(stats.lognorm(s=LENGTH_PRIOR[1], scale=LENGTH_PRIOR[0]), *ELL_RANGE,
                        N_ELL)
    kernels = np.array([np.exp(-d2 / (2.0 * ell**2)) for ell in ells])
    cols = smooth_columns(fitter)
    found = np.nonzero(ok)[0]
    rows = {j: found * P + j for j in cols}
    taus = TAU[::TAU_STRIDE]
    lz = np.empty((taus.size, N_ETA, N_ELL))
    Es, Gs, lns = _rewhiten(fitter, E, G, ok, taus)
    lz0 = laplace_evidence(Es, Gs)[0] + lns
    s1 = fitter.sigma_at(taus[:, None, None])                               # (S, R, P)
    for a in range(taus.size):
        W = {j: fitter.ref[found, j] / s1[a, found, j] for j in cols}
        lz[a] = evidence_grid(Es[a], Gs[a], rows, W, etas, kernels) + lns[a]
    # τ's grid points have equal prior weight; η's and ℓ's carry their cells' prior mass
    lw = (np.log(np.maximum(p_eta, 1e-300))[None, :, None]
          + np.log(np.maximum(p_ell, 1e-300))[None, None, :])
    # the ratio of the two means over the same τ points (their counts cancel)
    log_bf = float(special.logsumexp(special.logsumexp(lz + lw, axis=(1, 2)))
                   - special.logsumexp(lz0))
    w = np.exp(lz + lw - (lz + lw).max())
    w_eta = w.sum(axis=(0, 2))
    w_eta /= w_eta.sum()
    w_ell = w.sum(axis=(0, 1))
    w_ell /= w_ell.sum()
    cdf = np.cumsum(w_eta) - 0.5 * w_eta
    q = np.exp(np.interp([0.05, 0.5, 0.95], cdf, np.log(etas)))
    ell_med = float(np.exp(np.interp(0.5, np.cumsum(w_ell) - 0.5 * w_ell, np.log(ells))))
    return Unexplained(log_z=float(cal.log_z + log_bf), log_bf=float(log_bf),
                       eta_median=float(q[1]), eta_ci90=(float(q[0]), float(q[2])),
                       ell_median=ell_med)
