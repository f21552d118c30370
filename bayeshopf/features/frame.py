r"""The common planar frame in which orbits are put in polar form.

The paper writes every orbit in polar form about the origin of the measured
(z1, z2) plane, ``R = |z|, θ = atan2(z2, z1)`` (eq. R_theta). Raw channels have
different units and a sensor offset, and the wind-tunnel orbits are thin
ellipses that pass close to any fixed centre. bayeshopf therefore fixes, once for
the whole data set, an affine frame

.. math::  z = c + L\\,w, \\qquad w = L^{-1}(z - c),

with ``c`` the mean of the recordings' mean positions (one common offset; the
model's T_s is learnt in this frame, no recording is re-centred on its own) and
``L`` the Cholesky factor of twice the pooled within-recording covariance, so
that a typical orbit is close to a unit circle in ``w``. Both the measured and
the predicted orbits go through the same frame, so the comparison is the
paper's, only better conditioned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PlanarFrame:
    """Affine frame ``z = centre + L w`` shared by every recording of a fit.

    Attributes:
        centre: Common centre c in physical units, shape ``(2,)``.
        L: Lower-triangular scale matrix, shape ``(2, 2)``.
        names: Names of the planar channels (z1, z2).
        units: Units of the planar channels.
    """

    centre: np.ndarray
    L: np.ndarray
    names: tuple[str, str] = ("z1", "z2")
    units: tuple[str, str] = ("", "")

    def __post_init__(self) -> None:
        for name in ("centre", "L"):
            a = np.array(getattr(self, name), dtype=np.float64)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @classmethod
    def from_orbits(
        cls,
        orbits: list[np.ndarray],
        names: tuple[str, str] = ("z1", "z2"),
        units: tuple[str, str] = ("", ""),
    ) -> PlanarFrame:
        """Frame from a list of orbits, each of shape ``(n_t, 2)``.

        ``c`` is the mean of the orbits' means; ``L = chol(2 C)`` with ``C`` the
        pooled within-orbit covariance (each orbit weighted equally).
        """
        means = np.array([o.mean(axis=0) for o in orbits])
        cov = np.mean([np.cov(o.T) for o in orbits], axis=0)
        return cls(means.mean(axis=0), np.linalg.cholesky(2.0 * cov), names, units)

    def to_frame(self, z):
        """``w = L⁻¹ (z − c)`` for points of shape ``(..., 2)``."""
        return np.linalg.solve(self.L, (np.asarray(z) - self.centre).T).T

    def from_frame(self, w):
        """``z = c + L w`` for points of shape ``(..., 2)`` (numpy or jax)."""
        return self.centre + w @ self.L.T

    def to_dict(self) -> dict:
        """JSON-serialisable form."""
        return {
            "centre": self.centre.tolist(),
            "L": self.L.tolist(),
            "names": list(self.names),
            "units": list(self.units),
        }

    @classmethod
    def from_dict(cls, d: dict) -> PlanarFrame:
        """Inverse of :meth:`to_dict`."""
        return cls(np.array(d["centre"]), np.array(d["L"]), tuple(d["names"]), tuple(d["units"]))
