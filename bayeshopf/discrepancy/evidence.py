r"""Evidence of the linearised models, and the relative model error τ integrated out.

**Evidence (Laplace).** For stacked whitened residuals :math:`E(x)` whose last
rows are the standard normal prior rows of the unknowns
(:mod:`~bayeshopf.discrepancy.problem`), linearising
:math:`E(\hat x + \delta) \approx E + G\delta` at the mode, with
:math:`H = G^\top G = J^\top J + I`,

.. math::  \log Z_P = -\tfrac12\big(\lVert E\rVert^2 - b^\top H^{-1} b\big)
                     - \tfrac12 \log\det H, \qquad b = G^\top E

(the prior's :math:`(2\pi)^{-d/2}` cancels the Gaussian integral's
:math:`(2\pi)^{d/2}`), and :math:`\log Z_0 = -\tfrac12\lVert e(0)\rVert^2`. For
:math:`M_k` the parameters are integrated out analytically and the term's
coefficient in closed form (a normal in :math:`\zeta`, truncated at 0 for a
gap or a dissipative term, whose half-normal prior adds :math:`\log 2`): with
:math:`G = [G_z, g]`,
:math:`P_\perp = I - G_z (G_z^\top G_z)^{-1} G_z^\top`,

.. math::  \log Z_k = \log\int \exp\!\big(-\tfrac12 \lVert P_\perp (E + g(\zeta - \hat\zeta))
           \rVert^2\big)\, d\zeta - \tfrac12\log 2\pi\ [+\log 2]
           - \tfrac12 \log\det G_z^\top G_z ,

whose integrand is also the marginal posterior of :math:`\zeta`: its median and
90% interval are the term's (mixed over the model error :math:`\tau`, below).
These formulas hold at one whitening :math:`\sigma`.

**Model error, inferred.** Every feature's standard deviation is
:math:`\sigma_{rj}(\tau)^2 = \sigma_{{\rm noise},rj}^2 + (\tau\,\mathrm{ref}_{rj})^2`: the
segments' standard error of the mean and a relative model error :math:`\tau`
(a fraction of the channel's first-harmonic magnitude; of a tenth of the
frequency for the frequency), which no rig or simulator is free of. :math:`\tau`
has a log-uniform prior on :data:`TAU` and is integrated out of every model's
evidence on that grid: the residuals and the Jacobian at the mode are
re-whitened at each :math:`\tau` (the sensor offsets profiled again with the
new weights, :func:`_rewhiten`), and the :math:`\tau`-dependent normalisation
:math:`-\sum\log\sigma - \tfrac12\sum_j\log\sum_r\sigma_{rj}^{-2}` (the second sum
from each offset's flat prior) is kept (:func:`_model_error`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import stats

from bayeshopf.discrepancy.records import ModelError
from bayeshopf.discrepancy.select import Fitter

__all__ = ["GRID", "TAU", "laplace_evidence", "term_marginal"]

#: Grid points of the term coefficient's marginal posterior.
GRID = 241
#: Grid of the relative model error τ; its prior is log-uniform over this range.
TAU = np.geomspace(1e-5, 0.3, 201)


def laplace_evidence(E: np.ndarray, G: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    r"""Log evidence of the linearised model :math:`E + G\delta` (priors as rows of ``E``).

    For residuals whose last rows are the standard normal prior rows of the
    unknowns, :math:`\int \mathcal N(\delta; 0, I)\,e^{-\frac12\lVert e + J\delta\rVert^2}\,
    d\delta` with the prior's own :math:`(2\pi)^{-d/2}` folded in:
    :math:`\log Z = -\tfrac12(\lVert E\rVert^2 - b^\top H^{-1}b) - \tfrac12\log\det H`,
    :math:`H = G^\top G`, :math:`b = G^\top E`.

    Args:
        E: Stacked whitened residuals, shape ``(N,)``, or ``(S, N)`` for ``S``
            whitenings at once.
        G: Their Jacobian, shape ``(N, d)`` (``(S, N, d)``).

    Returns:
        ``(log_z, delta, cov)``: the log evidence, the step to the mode of the
        linearised model, and the posterior covariance :math:`H^{-1}`; with a
        leading ``S`` axis when ``E`` has one.
    """
    Gt = np.swapaxes(G, -1, -2)
    H = Gt @ G
    b = (Gt @ E[..., None])[..., 0]
    cov = np.linalg.inv(H)
    delta = -(cov @ b[..., None])[..., 0]
    log_z = (-0.5 * (np.sum(E * E, axis=-1) + np.sum(b * delta, axis=-1))
             - 0.5 * np.linalg.slogdet(H)[1])
    return (float(log_z) if E.ndim == 1 else log_z), delta, cov


def _zeta_gaussian(E: np.ndarray, G: np.ndarray, zeta: float, positive: bool):
    r"""``(log_z, centre, sd)`` of the last unknown with the others integrated out (analytic).

    Floats for ``E`` of shape ``(N,)``; arrays ``(S,)`` for ``(S, N)`` (``S``
    whitenings at once, ``G`` then ``(S, N, d + 1)``).
    """
    Gz, g = G[..., :-1], G[..., -1]
    Q, _ = np.linalg.qr(Gz)
    Qt = np.swapaxes(Q, -1, -2)
    a = E - (Q @ (Qt @ E[..., None]))[..., 0]
    bb = g - (Q @ (Qt @ g[..., None]))[..., 0]
    s2 = np.sum(bb * bb, axis=-1)
    ab = np.sum(a * bb, axis=-1)
    sd = 1.0 / np.sqrt(s2)
    centre = zeta - ab / s2                                     # maximum of the quadratic
    mx = -0.5 * (np.sum(a * a, axis=-1) - ab**2 / s2)
    log_z = mx - 0.5 * np.log(s2) - 0.5 * np.linalg.slogdet(np.swapaxes(Gz, -1, -2) @ Gz)[1]
    if positive:
        log_z = log_z + np.log(2.0) + stats.norm.logcdf(centre / sd)
    if E.ndim == 1:
        return float(log_z), float(centre), float(sd)
    return log_z, centre, sd


def _zeta_density(grid: np.ndarray, centre: float, sd: float, positive: bool) -> np.ndarray:
    """The normal (truncated at 0 when ``positive``) density of ζ on ``grid``."""
    dens = stats.norm.pdf(grid, centre, sd)
    if positive:
        dens = np.where(grid >= 0, dens, 0.0) / max(stats.norm.sf(0.0, centre, sd), 1e-300)
    return dens


def term_marginal(E: np.ndarray, G: np.ndarray, zeta: float, positive: bool, *,
                  n_grid: int = GRID) -> tuple[float, np.ndarray, np.ndarray]:
    r"""Log evidence and marginal posterior of the last unknown ζ, the others integrated out.

    With :math:`G = [G_z, g]` and :math:`P_\perp` the projection off the columns
    of :math:`G_z`, the linearised model gives
    :math:`\log p(y, \zeta') = -\tfrac12\lVert P_\perp(E + g(\zeta' - \zeta))\rVert^2
    - \tfrac12\log 2\pi\,[+\log 2] - \tfrac12\log\det G_z^\top G_z` (module
    docstring), a normal in :math:`\zeta'` (truncated at 0 when ``positive``:
    half-normal prior), integrated in closed form.

    Args:
        E: Stacked whitened residuals (ζ's prior row included), shape ``(N,)``.
        G: Their Jacobian, shape ``(N, d + 1)``, ζ last.
        zeta: The value of ζ at which ``E`` and ``G`` are evaluated.
        positive: Whether ζ ≥ 0 (half-normal prior).
        n_grid: Points of the returned grid (±6 posterior standard deviations).

    Returns:
        ``(log_z, grid, density)``: the log evidence, a grid of ζ and the
        normalised marginal posterior density on it.
    """
    log_z, centre, sd = _zeta_gaussian(E, G, zeta, positive)
    lo = max(centre - 6 * sd, 0.0) if positive else centre - 6 * sd
    grid = np.linspace(lo, max(centre + 6 * sd, lo + 12 * sd), n_grid)
    return log_z, grid, _zeta_density(grid, centre, sd, positive)


def _gauss_evidence(Et: np.ndarray, Gt: np.ndarray, x: np.ndarray, positive: Sequence[int]):
    """Laplace evidence, each ``positive`` unknown's half-normal prior and bound included.

    A float for ``Et`` of shape ``(N,)``; ``(S,)`` for ``(S, N)``.
    """
    lz, delta, cov = laplace_evidence(Et, Gt)
    for k in positive:
        lz = lz + np.log(2.0) + stats.norm.logcdf((x[k] + delta[..., k])
                                                   / np.sqrt(cov[..., k, k]))
    return float(lz) if Et.ndim == 1 else lz


def _rewhiten(fitter: Fitter, E: np.ndarray, G: np.ndarray, ok: np.ndarray, taus
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Residuals and Jacobian whitened at ``fitter.sigma`` → at :math:`\sigma(\tau)`, every τ.

    The data rows of ``E`` (``(N,)``) and ``G`` (``(N, n)``) are rescaled by
    :math:`\sigma_0/\sigma(\tau)` and the sensor offsets are profiled again with
    the new weights (an offset absorbs any constant per mean column, so the
    offsets profiled at :math:`\sigma_0` do not matter); rows of lost orbits keep
    their fixed charge. Also returns the :math:`\tau`-dependent normaliser
    :math:`-\sum\log\sigma - \tfrac12\sum_j \log\sum_r \sigma_{rj}^{-2}` (the
    second sum from integrating each offset under a flat prior).

    Returns:
        ``(E_τ, G_τ, normaliser)`` of shapes ``(S, N)``, ``(S, N, n)`` and
        ``(S,)`` for the ``S`` values of ``taus``.
    """
    R, P = fitter.mf.y.shape
    taus = np.atleast_1d(np.asarray(taus, float))
    s0 = fitter.sigma
    s1 = fitter.sigma_at(taus[:, None, None])                                  # (S, R, P)
    e = E[: R * P].reshape(R, P)
    g = G[: R * P].reshape(R, P, -1)
    ratio = s0 / s1
    e1 = np.where(ok[:, None], e * ratio, e)
    g1 = g * ratio[..., None]
    lognorm = -np.sum(np.log(s1), axis=(1, 2))
    for j in fitter.mean_cols:
        w_all = 1.0 / s1[:, :, j] ** 2                                       # (S, R)
        lognorm -= 0.5 * np.log(w_all.sum(axis=1))
        if not ok.any():
            continue
        w = w_all[:, ok]
        off = np.sum(w * (e[ok, j] * s0[ok, j]), axis=1) / w.sum(axis=1)            # (S,)
        offg = np.einsum("sr,rk->sk", w * s0[ok, j], g[ok, j, :]) / w.sum(axis=1)[:, None]
        e1[:, ok, j] -= off[:, None] / s1[:, ok, j]
        g1[:, ok, j, :] -= offg[:, None, :] / s1[:, ok, j, None]
    S = taus.size
    return (np.concatenate([e1.reshape(S, R * P), np.broadcast_to(E[R * P:], (S, E.size - R * P))],
                           axis=1),
            np.concatenate([g1.reshape(S, R * P, -1),
                            np.broadcast_to(G[R * P:], (S, *G[R * P:].shape))], axis=1),
            lognorm)


def _model_error(fitter: Fitter, E: np.ndarray, G: np.ndarray, ok: np.ndarray,
                 evidence, penalty=None) -> tuple[ModelError, np.ndarray]:
    """τ integrated out: ``evidence(E_τ, G_τ)`` at every point of :data:`TAU`.

    ``evidence`` maps the re-whitened residuals and Jacobian at every τ,
    ``(S, N)`` and ``(S, N, n)``, to the log evidences ``(S,)``.
    ``penalty(taus, E_τ, G_τ)``, when given, is subtracted (``(S,)``: a
    linearisation's charge, which depends on the whitening, so that the
    posterior of τ is that of the charged evidence).

    Returns the :class:`ModelError` and the log evidence at each τ.
    """
    Es, Gs, ln = _rewhiten(fitter, E, G, ok, TAU)
    lz = np.asarray(evidence(Es, Gs), float) + ln
    if penalty is not None:
        lz = lz - penalty(TAU, Es, Gs)
    mx = lz.max()
    w = np.exp(lz - mx)
    w /= w.sum()
    c = np.cumsum(w)
    q = np.interp([0.05, 0.5, 0.95], c, np.log(TAU))
    return (ModelError(median=float(np.exp(q[1])), ci90=(float(np.exp(q[0])),
                                                          float(np.exp(q[2]))),
                       log_z=float(mx + np.log(np.mean(np.exp(lz - mx)))), weights=w), lz)


def _at_tau(fitter: Fitter, E: np.ndarray, G: np.ndarray, ok: np.ndarray, tau: float):
    """``E``, ``G`` whitened at ``tau`` (no normaliser)."""
    Et, Gt, _ = _rewhiten(fitter, E, G, ok, tau)
    return Et[0], Gt[0]


def _null(fitter: Fitter, e0: np.ndarray, ok: np.ndarray) -> ModelError:
    """:math:`M_0` (nominal, nothing fitted) with τ integrated out."""
    E = e0.ravel()
    return _model_error(fitter, E, np.zeros((E.size, 0)), ok,
                        lambda Es, Gs: -0.5 * np.sum(Es * Es, axis=-1))[0]

