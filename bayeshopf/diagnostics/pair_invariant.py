r"""A map-free check of the normal form on pairs of coexisting orbits.

At a μ where both LCOs of the subcritical normal form exist, their radii solve
``r⁴ − a2 r² − (μ − μ0) = 0``, so ``r_s² + r_u² = a2`` and
``r_s² r_u² = μ0 − μ``. Hence

.. math::

    x(\mu) = \frac{r_s^2 r_u^2}{(r_s^2 + r_u^2)^2} = \frac{\mu_0 - \mu}{a_2^2},

which is linear in μ, is 1/4 at the fold and 0 at μ0. A map that is linear at
each μ (``T_L``, its μ-dependence and the shift ``T_s`` of eq. g) multiplies
every coordinate's peak-to-peak amplitude of both orbits by one gain, so ``x``
is the same when computed from the measured amplitudes: the only assumption is
that the network's correction is small. Three or more such pairs test the
normal form without fitting any map; two of them predict the third.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayeshopf.diagnostics.comparison import SAME_MU_FRACTION, same_mu_tolerance
from bayeshopf.diagnostics.summaries import Interval, interval


def invariant(stable_amplitude, unstable_amplitude):
    """``x = (A_s A_u)² / (A_s² + A_u²)²``, ``(μ0 − μ)/a2²`` for the normal form."""
    s2, u2 = np.square(stable_amplitude), np.square(unstable_amplitude)
    return s2 * u2 / (s2 + u2) ** 2


def unstable_amplitude_from(x, stable_amplitude):
    """The smaller root ``A_u = A_s √q`` of ``q/(1 + q)² = x`` (``nan`` for x outside (0, 1/4])."""
    x = np.asarray(x, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        q = ((1.0 - 2.0 * x) - np.sqrt(1.0 - 4.0 * x)) / (2.0 * x)
        return np.asarray(stable_amplitude) * np.sqrt(np.where(x > 0, q, np.nan))


@dataclass(frozen=True)
class PairInvariant:
    """The invariant at one unstable recording's μ (immutable).

    Attributes:
        mu: μ of the unstable recording.
        unstable: Its name.
        stable: Name(s) of the stable recording(s) used.
        stable_amplitude: A_s at μ (interpolated linearly in μ between the two
            nearest stable recordings when none is at μ).
        unstable_amplitude: A_u.
        x: ``invariant(A_s, A_u)``.
        draws: ``x`` with the amplitudes drawn from normals of their spreads
            over segments (the recordings' repeatability), shape ``(n_draws,)``.
    """

    mu: float
    unstable: str
    stable: tuple[str, ...]
    stable_amplitude: float
    unstable_amplitude: float
    x: float
    draws: np.ndarray

    @property
    def interval(self) -> Interval:
        """90% interval of ``x`` over the draws."""
        return interval(self.draws)


def _stable_weights(mu, stable_mu, tol):
    """Stable recordings and weights giving A_s at μ: the one at μ, or linear interpolation."""
    near = np.flatnonzero(np.abs(stable_mu - mu) <= tol)
    if near.size:
        return [int(near[np.argmin(np.abs(stable_mu[near] - mu))])], [1.0]
    below, above = np.flatnonzero(stable_mu < mu), np.flatnonzero(stable_mu > mu)
    if not below.size or not above.size:
        return None
    i, j = int(below[np.argmax(stable_mu[below])]), int(above[np.argmin(stable_mu[above])])
    t = (mu - stable_mu[i]) / (stable_mu[j] - stable_mu[i])
    return [i, j], [1.0 - t, t]


def pair_invariants(features, *, same_mu_fraction: float = SAME_MU_FRACTION, n_draws: int = 4000,
                    seed: int = 0) -> list[PairInvariant]:
    """The invariant ``x`` at every unstable recording with stable ones at or beside its μ.

    Args:
        features: :class:`~bayeshopf.features.harmonics.HarmonicFeatures` (``mu``,
            ``unstable``, ``amplitude``, ``amplitude_sd`` and ``names`` are used).
        same_mu_fraction: A stable recording closer in μ than this fraction of
            the μ span is taken as at the same μ (as in
            :func:`~bayeshopf.diagnostics.comparison.coexisting_orbits`);
            otherwise A_s is interpolated.
        n_draws: Draws of the amplitudes for the intervals.
        seed: Seed of those draws.

    Returns:
        One :class:`PairInvariant` per such unstable recording, in increasing μ.
    """
    mu = np.asarray(features.mu, dtype=float)
    unstable = np.asarray(features.unstable, dtype=bool)
    amp = np.asarray(features.amplitude, dtype=float)
    sd = np.asarray(features.amplitude_sd, dtype=float)
    tol = same_mu_tolerance(mu, same_mu_fraction)
    st = np.flatnonzero(~unstable)
    rng = np.random.default_rng(seed)
    out = []
    for j in np.flatnonzero(unstable)[np.argsort(mu[unstable], kind="stable")]:
        found = _stable_weights(mu[j], mu[st], tol)
        if found is None:
            continue
        idx, w = st[found[0]], np.asarray(found[1])
        a_s = float(w @ amp[idx])
        draws_s = sum(w[k] * rng.normal(amp[i], sd[i], n_draws) for k, i in enumerate(idx))
        out.append(PairInvariant(
            mu=float(mu[j]), unstable=features.names[j],
            stable=tuple(features.names[i] for i in idx), stable_amplitude=a_s,
            unstable_amplitude=float(amp[j]), x=float(invariant(a_s, amp[j])),
            draws=invariant(draws_s, rng.normal(amp[j], sd[j], n_draws))))
    return out


@dataclass(frozen=True)
class InvariantLine:
    """Least-squares line ``x = (μ0 − μ)/a2²`` through pair invariants (immutable).

    Attributes:
        mu0: Where the line reaches 0 (the Hopf point), from the measured x.
        a2: ``1/√(−slope)`` (``nan`` for a non-negative slope).
        residuals: ``x − line`` at each pair used.
        draws: ``(slope, intercept)`` of the line through each draw of the
            pairs' x, shape ``(n_draws, 2)``.
    """

    mu0: float
    a2: float
    residuals: tuple[float, ...]
    draws: np.ndarray

    @property
    def mu_fold(self) -> float:
        """Where the line reaches 1/4: ``μ0 − a2²/4``."""
        return self.mu0 - self.a2**2 / 4

    def x_draws(self, mu) -> np.ndarray:
        """The line's x at ``mu`` for each draw, shape ``(n_draws,) + shape(mu)``."""
        mu = np.asarray(mu, dtype=float)
        slope, icpt = self.draws[:, 0], self.draws[:, 1]
        return np.multiply.outer(slope, mu) + icpt.reshape((-1,) + (1,) * mu.ndim)

    def x_at(self, mu):
        """The line's x at ``mu`` (from the measured x)."""
        return (self.mu0 - np.asarray(mu, dtype=float)) / self.a2**2

    def unstable_amplitude(self, mu, stable_amplitude) -> Interval:
        """Predicted A_u at ``mu`` given A_s there: 90% interval over the draws."""
        return interval(unstable_amplitude_from(self.x_draws(mu), stable_amplitude))

    def interval(self, name: str) -> Interval:
        """90% interval of ``"mu0"``, ``"a2"`` or ``"mu_fold"`` over the draws."""
        slope, icpt = self.draws[:, 0], self.draws[:, 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            mu0 = -icpt / slope
            a2 = np.where(slope < 0, 1.0 / np.sqrt(-slope), np.nan)
        return interval({"mu0": mu0, "a2": a2, "mu_fold": mu0 - a2**2 / 4}[name])


def invariant_line(pairs: list[PairInvariant]) -> InvariantLine:
    """Fit ``x = (μ0 − μ)/a2²`` to two or more pairs (ordinary least squares, per draw).

    Raises:
        ValueError: With fewer than two pairs at distinct μ.
    """
    mu = np.array([p.mu for p in pairs])
    if np.unique(mu).size < 2:
        raise ValueError(f"the line needs pairs at two or more distinct μ; got μ = {mu.tolist()}")
    x = np.array([p.x for p in pairs])
    slope, intercept = np.polyfit(mu, x, 1)
    draws = np.polyfit(mu, np.stack([p.draws for p in pairs]), 1).T
    return InvariantLine(
        mu0=float(-intercept / slope),
        a2=float(1.0 / np.sqrt(-slope)) if slope < 0 else float("nan"),
        residuals=tuple((x - (slope * mu + intercept)).tolist()), draws=draws)


def leave_one_pair_out(pairs: list[PairInvariant]) -> list[tuple[PairInvariant, InvariantLine]]:
    """Each pair with the line through the others (where they span two distinct μ)."""
    out = []
    for k, held in enumerate(pairs):
        rest = [p for i, p in enumerate(pairs) if i != k]
        if len({p.mu for p in rest}) >= 2:
            out.append((held, invariant_line(rest)))
    return out
