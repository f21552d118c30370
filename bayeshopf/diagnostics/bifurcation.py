"""Bifurcation diagram with credible bands: amplitude against μ on each branch.

Both records convert to xarray (:meth:`DiagramBands.to_dataset`) and
pandas (:meth:`DiagramBands.to_dataframe`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayeshopf.diagnostics.summaries import CI, Interval

#: Quantile levels stored per μ at the default 90% level: the band's ends, the
#: 50% band and the median (:func:`levels`).
LEVELS = (0.05, 0.25, 0.5, 0.75, 0.95)


def levels(ci: float = CI) -> tuple[float, float, float, float, float]:
    """Quantile levels ``(lower, 25%, median, 75%, upper)`` of a ``ci`` band and the 50% band.

    Raises:
        ValueError: Unless ``0 < ci < 1``.
    """
    if not 0.0 < float(ci) < 1.0:
        raise ValueError(f"ci must lie strictly between 0 and 1; got {ci!r}")
    return (0.5 - ci / 2, 0.25, 0.5, 0.75, 0.5 + ci / 2)


@dataclass(frozen=True)
class BranchBand:
    """Posterior of one branch of the diagram on a μ grid.

    Attributes:
        sign: +1 stable, −1 unstable.
        mu: The μ grid, shape ``(n_mu,)``.
        quantiles: Amplitude quantiles at ``levels``, shape ``(5, n_mu)``,
            over the draws in which the branch exists there (``nan`` where it
            exists in fewer than 5% of draws).
        p_exists: Posterior probability that the branch exists at each μ.
        predictive: Quantiles of the posterior predictive amplitude of a new
            recording at each μ (the curve's uncertainty plus the measurement
            and model-error scatter σ), shape ``(5, n_mu)``.
        levels: The quantile levels (:func:`levels`): the ``ci`` band's ends,
            the 50% band's and the median.
        to_hopf: Amplitude quantiles (same levels) with the draws past their own
            Hopf point counted at amplitude 0, where the branch has shrunk into
            the equilibrium; ``None`` for a branch that does not end at the Hopf
            point (the stable branch of a subcritical system). They equal
            ``quantiles`` where the branch exists in every draw and fall to 0
            across the Hopf point's interval, so a drawn branch reaches it.
        p_to_hopf: Share of draws in which the branch exists or has shrunk into
            the Hopf point (the draws ``to_hopf`` is over); ``None`` with it.
    """

    sign: int
    mu: np.ndarray
    quantiles: np.ndarray
    p_exists: np.ndarray
    predictive: np.ndarray
    levels: tuple = LEVELS
    to_hopf: np.ndarray | None = None
    p_to_hopf: np.ndarray | None = None

    @property
    def median(self) -> np.ndarray:
        """Posterior median amplitude."""
        return self.quantiles[2]

    @property
    def ci(self) -> float:
        """Probability mass of the outer band."""
        return float(round(self.levels[4] - self.levels[0], 10))

    @property
    def branch(self) -> str:
        """``"stable"`` or ``"unstable"``."""
        return "stable" if self.sign > 0 else "unstable"


@dataclass(frozen=True)
class DiagramBands:
    """The posterior's bifurcation diagram: bands of both branches with the Hopf and fold points.

    (Named apart from :class:`~bayeshopf.simulators.BifurcationDiagram`, a
    simulated system's continued orbits.)

    Attributes:
        stable: The stable branch.
        unstable: The unstable branch, or ``None`` (supercritical).
        mu0: Interval of the Hopf point μ0.
        mu_fold: Interval of the fold μ, or ``None`` (supercritical).
        fold_amplitude: Interval of the amplitude at the fold, or ``None``.
    """

    stable: BranchBand
    unstable: BranchBand | None
    mu0: Interval
    mu_fold: Interval | None
    fold_amplitude: Interval | None

    @property
    def branches(self) -> tuple[BranchBand, ...]:
        """The branches drawn: the stable one, then the unstable one if any."""
        return (self.stable,) if self.unstable is None else (self.stable, self.unstable)

    def to_dataset(self):
        """The diagram as an :class:`xarray.Dataset`.

        Dimensions ``branch`` (``"stable"``, ``"unstable"``) and ``mu``; variables
        ``median``, ``lower``/``upper`` (the ``ci`` band), ``q25``/``q75``,
        ``predictive_lower``/``predictive_upper`` (a new recording's ``ci``
        band), ``p_exists`` and, where a branch ends at the Hopf point,
        ``to_hopf_lower``/``to_hopf_median``/``to_hopf_upper``
        (:attr:`BranchBand.to_hopf`); the Hopf point, the fold and its amplitude
        as variables over ``stat`` (``median``, ``lower``, ``upper``). The
        level is the attribute ``ci``.
        """
        import xarray as xr

        mu = np.asarray(self.stable.mu, float)
        for b in self.branches:
            if not np.array_equal(np.asarray(b.mu, float), mu):
                raise ValueError("to_dataset: the branches must share one μ grid")
        names = [b.branch for b in self.branches]
        dims = ("branch", "mu")

        def stack(get):
            return (dims, np.array([np.asarray(get(b), float) for b in self.branches]))

        nan = np.full(mu.shape, np.nan)
        data = {
            "median": stack(lambda b: b.quantiles[2]),
            "lower": stack(lambda b: b.quantiles[0]),
            "upper": stack(lambda b: b.quantiles[4]),
            "q25": stack(lambda b: b.quantiles[1]),
            "q75": stack(lambda b: b.quantiles[3]),
            "predictive_lower": stack(lambda b: b.predictive[0]),
            "predictive_upper": stack(lambda b: b.predictive[4]),
            "p_exists": stack(lambda b: b.p_exists),
            "to_hopf_lower": stack(lambda b: nan if b.to_hopf is None else b.to_hopf[0]),
            "to_hopf_median": stack(lambda b: nan if b.to_hopf is None else b.to_hopf[2]),
            "to_hopf_upper": stack(lambda b: nan if b.to_hopf is None else b.to_hopf[4]),
        }

        def point(iv):
            return ("stat", np.array([np.nan] * 3 if iv is None else [iv.median, iv.lo, iv.hi]))

        data["mu0"] = point(self.mu0)
        data["mu_fold"] = point(self.mu_fold)
        data["fold_amplitude"] = point(self.fold_amplitude)
        return xr.Dataset(data, coords={"branch": names, "mu": mu,
                                        "stat": ["median", "lower", "upper"]},
                          attrs={"ci": self.stable.ci})

    def to_dataframe(self):
        """One row per branch and μ (:meth:`to_dataset`, per-μ variables): a pandas DataFrame."""
        ds = self.to_dataset()
        return ds.drop_vars(["mu0", "mu_fold", "fold_amplitude", "stat"]).to_dataframe()


def quantiles(amp: np.ndarray, at=LEVELS) -> tuple[np.ndarray, np.ndarray]:
    """Quantiles at levels ``at`` of amplitude draws ``(n, n_mu)`` and the share that exist.

    ``nan`` (no LCO in a draw) is left out; where fewer than 5% of draws have
    an LCO the quantiles are ``nan``.
    """
    exists = np.isfinite(amp)
    p = exists.mean(axis=0)
    q = np.full((len(at), amp.shape[1]), np.nan)
    for j in np.flatnonzero(p >= 0.05):
        q[:, j] = np.quantile(amp[exists[:, j], j], at)
    return q, p
