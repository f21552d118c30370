r"""Truncated Fourier series of closed curves in polar form (paper eqs. FS, Galerkin).

A closed curve that winds once round the origin is written ``R(θ)`` and projected
by least squares onto

.. math::  R(θ) = a_0 + \\sum_{k=1}^{n_h} a_k \\cos kθ + \\sum_{k=1}^{n_h} b_k \\sin kθ,

giving the coefficient vector ``Φ(R) = [a_0, a_1..a_{n_h}, b_1..b_{n_h}]``. The
functions here are written with ``jax.numpy`` so the same code serves the
measured orbits (once) and the model's predicted orbits (inside the likelihood,
differentiably).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np


def _xp(*arrays):
    """Numpy for numpy inputs (the data path), jax.numpy otherwise (the model path)."""
    return np if all(isinstance(a, np.ndarray | float | int) for a in arrays) else jnp


def n_coefficients(n_h: int) -> int:
    """Length ``2 n_h + 1`` of the coefficient vector."""
    return 2 * n_h + 1


def design_matrix(theta, n_h: int):
    """Columns ``[1, cos θ, …, cos n_h θ, sin θ, …, sin n_h θ]``, shape ``(n, 2n_h+1)``."""
    xp = _xp(theta)
    kt = theta[..., None] * xp.arange(1, n_h + 1)
    return xp.concatenate([xp.ones_like(theta)[..., None], xp.cos(kt), xp.sin(kt)], axis=-1)


def polar(w):
    """Polar form ``(R, θ)`` about the origin of points ``w``, shape ``(..., 2)`` (eq. R_theta)."""
    xp = _xp(w)
    return xp.hypot(w[..., 0], w[..., 1]), xp.arctan2(w[..., 1], w[..., 0])


def project(theta, R, n_h: int):
    """Least-squares Fourier coefficients of samples ``R(θ)`` (eq. FS).

    Solved with a QR factorisation (not the normal equations), which is stable
    and differentiable.

    Args:
        theta: Polar angles, shape ``(n,)``; ``n >= 2 n_h + 1``.
        R: Radii, shape ``(n,)``.
        n_h: Number of harmonics.

    Returns:
        Coefficients ``[a_0, a_1..a_{n_h}, b_1..b_{n_h}]``, shape ``(2 n_h + 1,)``.
    """
    xp = _xp(theta, R)
    q, r = xp.linalg.qr(design_matrix(theta, n_h))
    return xp.linalg.solve(r, q.T @ R)


def evaluate(coeffs, theta):
    """``R(θ)`` from coefficients of shape ``(..., 2 n_h + 1)`` at angles ``theta``."""
    n_h = (coeffs.shape[-1] - 1) // 2
    return _xp(coeffs).einsum("...c,tc->...t", coeffs, design_matrix(theta, n_h))


def curve(coeffs, n_points: int = 256):
    """Points ``w(θ) = R(θ) [cos θ, sin θ]`` on a uniform θ grid, shape ``(..., n_points, 2)``."""
    xp = _xp(coeffs)
    theta = xp.linspace(0.0, 2.0 * np.pi, n_points, endpoint=False)
    R = evaluate(coeffs, theta)
    return xp.stack([R * xp.cos(theta), R * xp.sin(theta)], axis=-1)
