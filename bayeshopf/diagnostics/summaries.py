"""Interval summaries of posterior draws."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Probability mass of the reported credible intervals.
CI = 0.90


@dataclass(frozen=True)
class Interval:
    """Median and equal-tailed credible interval of a scalar quantity.

    Attributes:
        median: Posterior median.
        lo: Lower end of the ``mass`` equal-tailed interval.
        hi: Upper end.
        mass: Probability mass of the interval (0.9 by default).
    """

    median: float
    lo: float
    hi: float
    mass: float = CI

    def contains(self, x: float) -> bool:
        """Whether ``lo ≤ x ≤ hi``."""
        return bool(self.lo <= x <= self.hi)

    @property
    def width(self) -> float:
        """``hi − lo``."""
        return self.hi - self.lo

    def to_json(self) -> dict:
        """``{"median": m, "ci90": [lo, hi]}``."""
        return {"median": self.median, f"ci{round(100 * self.mass)}": [self.lo, self.hi]}


def interval(draws, mass: float = CI) -> Interval:
    """Median and central ``mass`` interval of 1-D draws (``nan`` draws dropped).

    Raises:
        ValueError: When no finite draw remains.
    """
    x = np.asarray(draws, dtype=float).ravel()
    x = x[np.isfinite(x)]
    if x.size == 0:
        raise ValueError("interval: expected at least one finite draw; found none")
    q = np.quantile(x, [0.5, 0.5 - mass / 2, 0.5 + mass / 2])
    return Interval(float(q[0]), float(q[1]), float(q[2]), mass)
