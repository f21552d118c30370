r"""The least-squares problem of a calibration: stacked residuals, Jacobian, minimiser.

**Coordinates.** Uncertain parameter :math:`j` is written through its
standard normal coordinate :math:`z_j` (:meth:`UncertainParameter.value`:
:math:`\theta_j = \theta_{0j} e^{\sigma_j z_j}` or :math:`\theta_{0j}(1 + s_j z_j)`),
and the term's coefficient as :math:`c = s_k\zeta` with the library's prior
scale :math:`s_k`, so every unknown :math:`x = (z, \zeta)` has a standard normal
prior (half-normal, :math:`\zeta \ge 0`, for a freeplay gap and a dissipative term).

**Residuals.** With the whitened feature residuals :math:`e(x)` of
:class:`~bayeshopf.discrepancy.select.Fitter` (sensor offsets profiled out,
orbits re-shot at every :math:`x` by homotopy from the nearest point already
solved, an orbit lost when it no longer exists or changes its Floquet
stability), the negative log posterior is half the squared norm of the
stacked vector

.. math::  E(x) = \begin{bmatrix} e(x) \\ x \end{bmatrix}, \qquad
           -\log p(x \mid y) = \tfrac12 \lVert E(x)\rVert^2 + \text{const},

the prior rows :math:`x` being the standard normal priors. The mode is found by
:func:`scipy.optimize.least_squares` (trust-region Gauss–Newton, a bound
:math:`\zeta \ge 0` for a gap), with the exact Jacobian :math:`G = \partial E/\partial x`
from the implicit derivatives of the orbits found at :math:`x`
(:func:`~bayeshopf.discrepancy.orbits.sensitivities`); rows of lost orbits are
zero.

**Recorded orbits must exist.** An orbit that the simulator has at the start
of a fit (the nominal parameters) but loses at a trial point (its fold moved
past the recording's μ, or it changed its Floquet stability) gives every one
of its features the whitened residual :data:`BARRIER`: a recorded orbit exists,
so a model without it has (practically) zero likelihood, and the trust region
rejects the step. :mod:`~bayeshopf.discrepancy.select` instead charges a lost
orbit a finite :math:`\chi^2` per feature (``LOST_CHI2``); from far away, where
the misfit per feature is larger than that, losing an orbit is cheaper than
fitting it, and the minimiser stalls on that discontinuity. An orbit already
missing at the start keeps the finite charge.

**The linearisation checked** (:func:`polish`). The Laplace evidence
(:mod:`~bayeshopf.discrepancy.evidence`) credits the step to the mode of the
linear model at a fit's end point; the orbits re-shot there must agree.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from scipy import optimize

from bayeshopf.discrepancy.evidence import _at_tau, _rewhiten, laplace_evidence
from bayeshopf.discrepancy.orbits import OrbitBatch, track
from bayeshopf.discrepancy.select import Fitter
from bayeshopf.discrepancy.terms import Term
from bayeshopf.simulators.base import UncertainParameter

__all__ = ["BARRIER", "MAX_NFEV", "TOL", "Charge", "Problem", "charge", "charge_at_every_tau",
           "minimise", "polish"]

#: Largest number of residual evaluations of one least-squares fit.
MAX_NFEV = 40
#: ``ftol``, ``xtol`` and ``gtol`` of the least-squares fits: a change of the log
#: posterior below ~1e-5 is far below anything the evidence resolves.
TOL = 1e-6
#: Whitened residual of every feature of a recorded orbit that a trial point loses.
BARRIER = 1e5


class Problem:
    """Stacked whitened residuals :math:`E(x)` and their exact Jacobian.

    Orbits are memoised by ``x``; a new ``x`` is reached by homotopy
    (:func:`~bayeshopf.discrepancy.orbits.track`) from the solved point with the
    fewest lost orbits, nearest in ``x``.
    """

    def __init__(self, fitter: Fitter, unc: Sequence[UncertainParameter],
                 term: Term | Sequence[Term] | None,
                 seeds: Sequence[tuple[np.ndarray, OrbitBatch]], *,
                 known: Sequence[tuple[np.ndarray, np.ndarray]] = ()):
        self.terms = (() if term is None else (term,) if isinstance(term, Term)
                      else tuple(term))
        self.fitter, self.unc = fitter, tuple(unc)
        self.term = self.terms[0] if len(self.terms) == 1 else None
        self.d = len(self.unc)
        self.n = self.d + len(self.terms)
        self.nominal = np.array([fitter.params0[u.name] for u in self.unc])
        self.memo: list[tuple[np.ndarray, OrbitBatch, np.ndarray]] = []
        # the orbits found at the start must stay found: a recorded orbit exists
        self.must = np.logical_or.reduce([ob.ok for _, ob in seeds])
        for x, ob in seeds:
            self._store(np.asarray(x, float), ob)
        self.n_track = 0
        # data rows of Jacobian columns already known at some points (the calibration's)
        self.known = list(known)
        self.last: tuple[np.ndarray, np.ndarray] | None = None
        self.first: tuple[np.ndarray, np.ndarray] | None = None
        # the orbits' derivatives in x where a Jacobian was formed: (x, (∂x0/∂x, ∂T/∂x, known))
        self.tangents: list[tuple[np.ndarray, tuple]] = []

    def params(self, x: np.ndarray) -> dict:
        """The simulator's parameters at ``x = (z, ζ...)``."""
        p = dict(self.fitter.params0)
        for j, u in enumerate(self.unc):
            p[u.name] = float(u.value(x[j], self.nominal[j]))
        for k, t in enumerate(self.terms):
            p[t.param] = float(t.scale * x[self.d + k])
        return p

    def _E(self, x: np.ndarray, ob: OrbitBatch) -> np.ndarray:
        e = self.fitter.residuals(ob)
        e[self.must & ~ob.ok] = BARRIER
        return np.concatenate([e.ravel(), x])

    def _store(self, x, ob) -> np.ndarray:
        E = self._E(x, ob)
        self.memo.append((x.copy(), ob, E))
        if len(self.memo) > 48:
            del self.memo[1]                                  # keep the seed
        return E

    def _track(self, x_from, ob_from, x_to) -> OrbitBatch:
        self.n_track += 1
        return track(self.fitter.system, self.params(x_from), self.params(x_to), ob_from,
                     self.fitter.stable, guess=self._predict(x_from, ob_from, x_to))

    def _predict(self, x_from, ob_from, x_to):
        """Orbits at ``x_to`` to first order from those at ``x_from``, or ``None``.

        The first-order step needs the orbits' derivatives in every unknown that
        moves, known where a Jacobian was formed at ``x_from``.
        """
        t = next((d for xk, d in self.tangents if np.array_equal(xk, x_from)), None)
        if t is None:
            return None
        dx = np.asarray(x_to, float) - x_from
        dx0, dT, have = t
        if np.any(dx[~have] != 0):
            return None
        dx = np.where(have, dx, 0.0)
        return ob_from.x0 + dx0 @ dx, ob_from.period + dT @ dx

    def solve(self, x: np.ndarray) -> tuple[OrbitBatch, np.ndarray]:
        """The orbits and stacked residuals :math:`E(x)` (memoised)."""
        x = np.asarray(x, float)
        for xm, ob, E in self.memo:
            if np.array_equal(xm, x):
                return ob, E
        xm, ob, _ = min(self.memo, key=lambda m: (-int(m[1].ok.sum()),
                                                  float(np.sum((m[0] - x) ** 2))))
        ob_new = self._track(xm, ob, x)
        return ob_new, self._store(x, ob_new)

    def residual(self, x: np.ndarray) -> np.ndarray:
        """:math:`E(x)`, for :func:`scipy.optimize.least_squares`."""
        return self.solve(x)[1]

    def _column_params(self, j: int) -> str:
        return self.unc[j].name if j < self.d else self.terms[j - self.d].param

    def _slope(self, j: int, x: np.ndarray) -> float:
        """``∂p_j/∂x_j``: the prior map's slope (a term's scale for a term's coefficient)."""
        if j >= self.d:
            return float(self.terms[j - self.d].scale)
        u, eps = self.unc[j], 1e-6
        return float((u.value(x[j] + eps, self.nominal[j])
                      - u.value(x[j] - eps, self.nominal[j])) / (2 * eps))

    def jacobian(self, x: np.ndarray, *_) -> np.ndarray:
        r""":math:`G = \partial E/\partial x`, exactly (prior rows the identity).

        The orbits' derivatives in every unknown come from one implicit solve at
        the orbits found (:func:`~bayeshopf.discrepancy.orbits.sensitivities`);
        a lost orbit's rows are 0. Columns known at ``x`` (``known``) are reused.
        """
        x = np.asarray(x, float)
        if self.last is not None and np.array_equal(self.last[0], x):
            return self.last[1].copy()
        ob, E = self.solve(x)
        R, P = self.fitter.mf.y.shape
        G = np.zeros((E.size, self.n))
        kn = next((J for xk, J in self.known if np.array_equal(xk[: J.shape[1]], x[: J.shape[1]])
                   and not np.any(x[J.shape[1]:])), None)
        n_known = 0 if kn is None else min(kn.shape[1], self.n)
        if n_known:
            G[: R * P, :n_known] = kn[:, :n_known]
        need = list(range(n_known, self.n))
        if need:
            D, dx0, dT = self.fitter.derivatives(ob, self.params(x),
                                                 [self._column_params(j) for j in need],
                                                 orbits=True)
            slopes = np.array([self._slope(j, x) for j in need])
            for c, j in enumerate(need):
                G[: R * P, j] = slopes[c] * D[..., c].ravel()
            have = np.zeros(self.n, bool)
            have[need] = True
            Dx0 = np.zeros((*dx0.shape[:2], self.n))
            DT = np.zeros((dT.shape[0], self.n))
            Dx0[..., need] = dx0 * slopes
            DT[:, need] = dT * slopes
            self.tangents = [*self.tangents[-7:], (x.copy(), (Dx0, DT, have))]
        G[R * P:] = np.eye(self.n)                             # the prior rows, exactly
        self.last = (x.copy(), G.copy())
        if self.first is None:
            self.first = self.last
        return G


def minimise(prob: Problem, x0: np.ndarray, max_nfev: int):
    """The mode from ``x0``: :func:`scipy.optimize.least_squares` (``trf``, ζ ≥ 0 for a gap).

    Returns:
        ``(x, orbits, E, G, result)`` at the point found.
    """
    res = optimize.least_squares(prob.residual, x0, jac=prob.jacobian,
                                 bounds=(_lower(prob), np.inf),
                                 method="trf", x_scale=1.0, ftol=TOL, xtol=TOL, gtol=TOL,
                                 max_nfev=max_nfev)
    x = res.x
    ob, E = prob.solve(x)
    return x, ob, E, prob.jacobian(x), res


class Charge(NamedTuple):
    r"""What :func:`charge` found.

    Attributes:
        nats: The charge to the log evidence.
        x: The linear model's mode (clipped to the bounds).
        orbits: The orbits re-shot there.
        E: The stacked residuals there.
        shot: Their misfit :math:`\chi^2_{\rm shot}` at the model error compared.
        here: The misfit :math:`\chi^2_x` at the point the evidence is formed at.
        linear: The linear model's misfit :math:`\chi^2_{\rm lin}` at its mode.
    """

    nats: float
    x: np.ndarray
    orbits: OrbitBatch
    E: np.ndarray
    shot: float
    here: float
    linear: float


def _lower(prob: Problem) -> np.ndarray:
    """Lower bounds of ``x``: 0 for a coefficient constrained to be ≥ 0, else −∞."""
    lower = np.full(prob.n, -np.inf)
    for k, t in enumerate(prob.terms):
        if t.positive:
            lower[prob.d + k] = 0.0
    return lower


def charge(prob: Problem, x: np.ndarray, ob: OrbitBatch, E: np.ndarray, G: np.ndarray,
           tau: float) -> Charge:
    r"""What the Laplace evidence at ``x`` owes for the linearisation it rests on.

    The evidence of the linear model :math:`E + G\delta` at ``x`` (whitened at
    ``tau``) is :math:`-\tfrac12\chi^2_{\rm lin} - \tfrac12\log\det H`, with
    :math:`\chi^2_{\rm lin} = \lVert E + G\delta\rVert^2` at the linear model's
    mode :math:`x + \delta` (clipped to the bounds): it credits the fall from
    :math:`\chi^2_x = \lVert E\rVert^2` to :math:`\chi^2_{\rm lin}`. The
    orbits are re-shot at :math:`x + \delta`, giving :math:`\chi^2_{\rm shot}`,
    and the charge is

    .. math::  \tfrac12\max\big(0,\ \min(\chi^2_{\rm shot}, \chi^2_x)
               - \chi^2_{\rm lin}\big).

    The misfit promised at the mode is replaced by the lower of the two misfits
    actually computed on the model, at ``x`` and at :math:`x + \delta`: the
    evidence becomes that of a Gaussian of precision :math:`H` about the better
    of the two points, and never falls below the Laplace estimate about ``x``
    taken as it stands, :math:`-\tfrac12\chi^2_x - \tfrac12\log\det H`, which
    uses only the misfit checked at ``x``. The charge is thus at most the
    credit :math:`\tfrac12(\chi^2_x - \chi^2_{\rm lin})` that the linear model
    gave beyond ``x``. Without the cap, a trial point at which a recorded orbit
    is lost (its features at :data:`BARRIER`) would be charged
    :math:`\sim 10^{10}` nats for a step the evidence need not take. A step
    re-shot better than promised earns nothing extra (charge 0).

    Args:
        prob: The residuals.
        x: The point the evidence is formed at.
        ob: Its orbits.
        E: The stacked residuals there (whitened with ``prob.fitter``).
        G: Their Jacobian.
        tau: The model error at which the misfits are compared.

    Returns:
        A :class:`Charge`.
    """
    fitter = prob.fitter
    Et, Gt = _at_tau(fitter, E, G, ob.ok, tau)
    _, delta, _ = laplace_evidence(Et, Gt)
    xl = np.maximum(x + delta, _lower(prob))
    pred = float(np.sum((Et + Gt @ (xl - x)) ** 2))
    ob_l, E_l = prob.solve(xl)
    El_t, _ = _at_tau(fitter, E_l, np.zeros((E_l.size, 0)), ob_l.ok, tau)
    shot = float(El_t @ El_t)
    here = float(Et @ Et)
    return Charge(0.5 * max(0.0, min(shot, here) - pred), xl, ob_l, E_l, shot, here, pred)


def charge_at_every_tau(prob: Problem, x: np.ndarray, c: Charge):
    r"""The charge of :func:`charge` as a function of the model error τ.

    ``c`` holds the orbits re-shot once, at the linear model's mode for one τ.
    At every τ the linear model's promise :math:`\chi^2_{\rm lin}(\tau)` (its
    own mode at that whitening) is replaced by the lower of the misfits
    computed on the model, at ``x`` and at the re-shot point, both whitened at
    τ. Integrated over τ (:func:`~bayeshopf.discrepancy.evidence._model_error`'s
    ``penalty``), the model error is inferred from what the model achieves, not
    from what its linearisation promises: a promise of a near-perfect fit
    would otherwise pull τ down to where the point ``x`` itself fits badly.

    Returns:
        ``penalty(taus, E_τ, G_τ)``: the charge in nats at every τ of ``taus``
        (``(S,)``), given the residuals ``(S, N)`` and Jacobian ``(S, N, n)``
        whitened at each.
    """
    fitter, lower = prob.fitter, _lower(prob)
    none = np.zeros((c.E.size, 0))

    def penalty(taus: np.ndarray, Es: np.ndarray, Gs: np.ndarray) -> np.ndarray:
        _, delta, _ = laplace_evidence(Es, Gs)
        step = np.maximum(x + delta, lower) - x                                 # (S, n)
        pred = np.sum((Es + (Gs @ step[..., None])[..., 0]) ** 2, axis=-1)
        El = _rewhiten(fitter, c.E, none, c.orbits.ok, taus)[0]
        achieved = np.minimum(np.sum(El * El, axis=-1), np.sum(Es * Es, axis=-1))
        return 0.5 * np.maximum(0.0, achieved - pred)

    return penalty


def polish(prob: Problem, x: np.ndarray, ob: OrbitBatch, E: np.ndarray, G: np.ndarray,
           tau: float):
    r"""Check the linearisation behind the evidence at a fit's end point, and act on it.

    The Laplace evidence credits the step :math:`\delta` to the mode of the linear
    model at ``x`` (the :math:`b^\top H^{-1} b` term). That credit is earned only if
    the orbits re-shot at :math:`x + \delta` agree: where the fit stopped short of
    its mode on a non-smooth or strongly curved posterior (a freeplay gap), the
    linear model can promise a misfit thousands of times lower than the one
    re-shot. The step is taken (once) when it lowers the re-shot misfit below
    that at ``x``, and the disagreement that remains at the point kept is
    returned, to be charged to the evidence (:func:`charge`: capped at the
    credit the linear model gave beyond that point).

    Returns:
        ``(x, ob, E, G, penalty)`` at the point kept.
    """
    for it in range(2):
        c = charge(prob, x, ob, E, G, tau)
        if it == 0 and c.shot < c.here:
            x, ob, E = c.x, c.orbits, c.E
            G = prob.jacobian(c.x)
            continue
        break
    return x, ob, E, G, c.nats
