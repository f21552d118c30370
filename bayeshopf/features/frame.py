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

**When the mean is not inside every orbit.** An orbit has a polar form about
``c`` only if it encircles ``c``. Where the orbit centre drifts with the
amplitude (a quadratic stiffness shifts the mean pitch of large flutter orbits
by more than the half-amplitude of small ones), the mean of the means can lie
outside the smallest orbits. :meth:`PlanarFrame.from_orbits` with
``centre="deepest"`` then takes the point deepest inside every orbit: with
``m_i`` and ``C_i`` the mean and covariance of orbit ``i`` (an ellipse-like
orbit is the level set ``(z - m_i)^T C_i^{-1} (z - m_i) = 2``),

.. math::  c = \\arg\\min_z \\max_i\\,(z - m_i)^T C_i^{-1} (z - m_i),

a convex problem. :func:`~bayeshopf.features.harmonics.extract_harmonics` does
not need it (its features are time harmonics, which need no centre inside
each orbit) and builds the frame above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize


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
        *,
        centre: str = "mean",
    ) -> PlanarFrame:
        r"""Frame from a list of orbits, each of shape ``(n_t, 2)``.

        ``L = chol(2 C)`` with ``C`` the pooled within-orbit covariance (each
        orbit weighted equally).

        Args:
            orbits: The orbits, each of shape ``(n_t, 2)``.
            names: Names of the planar channels.
            units: Their units.
            centre: ``"mean"``: ``c`` is the mean of the orbits' means;
                ``"deepest"``: ``c`` is the point deepest inside every orbit,
                :math:`\arg\min_z \max_i (z - m_i)^T C_i^{-1} (z - m_i)`
                (module docstring).

        Raises:
            ValueError: For an unknown ``centre``.
        """
        means = np.array([o.mean(axis=0) for o in orbits])
        covs = np.array([np.cov(o.T) for o in orbits])
        L = np.linalg.cholesky(2.0 * covs.mean(axis=0))
        if centre == "mean":
            c = means.mean(axis=0)
        elif centre == "deepest":
            c = _deepest_point(means, covs, L)
        else:
            raise ValueError(f"centre must be 'mean' or 'deepest'; got {centre!r}")
        return cls(c, L, names, units)

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


def _deepest_point(means: np.ndarray, covs: np.ndarray, L: np.ndarray) -> np.ndarray:
    """``argmin_z max_i (z − m_i)ᵀ C_i⁻¹ (z − m_i)``, solved in the whitened frame.

    Written as ``min t`` subject to ``q_i(z) <= t`` (convex), by SLSQP from the
    mean of the means.
    """
    Li = np.linalg.inv(L)
    m = means @ Li.T                                     # means in w = L⁻¹ z
    P = np.array([np.linalg.inv(Li @ C @ Li.T) for C in covs])

    def q(z):
        d = z - m
        return np.einsum("ni,nij,nj->n", d, P, d)

    z0 = m.mean(axis=0)
    x0 = np.append(z0, q(z0).max())
    sol = minimize(lambda x: x[2], x0, method="SLSQP",
                   constraints=[{"type": "ineq", "fun": lambda x: x[2] - q(x[:2])}],
                   options={"ftol": 1e-12, "maxiter": 200})
    z = sol.x[:2] if np.all(np.isfinite(sol.x)) and q(sol.x[:2]).max() <= x0[2] else z0
    return z @ L.T
