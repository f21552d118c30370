r"""The learnt map from normal-form to measured coordinates (paper eq. g).

.. math::

    \\vec U_{12}(u_1, u_2, \\mu) = T_L\\,[u_1, u_2, \\tilde\\mu]^T + T_s
        + \\mathrm{NN}_{\\Theta_U}(u_1, u_2, \\tilde\\mu),

written in the common planar frame (:mod:`bayeshopf.features.frame`), with
``μ̃ = (μ − μ_c)/Δμ`` the bifurcation parameter centred and scaled by the data.
``T_L`` is 2×3: its left 2×2 block is lower-triangular with a positive diagonal.
That fixes the gauge: the normal form is invariant under rotations of
``(u1, u2)``, so a full 2×2 block would leave a ring of equivalent maps.

One term is added to the paper's eq. (g): the 2×2 block varies linearly with μ,
``T_u(μ̃) = L0 + μ̃ L1`` (both lower-triangular). On the wind-tunnel rig the
ratio of heave to pitch amplitude grows by a third across the measured speeds,
which a μ-independent linear map cannot follow; the authors' code learns a
μ-dependent 2×2 matrix with a second network (``ann_l``), and the first-order
term does the same with three interpretable numbers. The
neural network is a small tanh MLP whose output is multiplied by a learnt scale,
so its prior can shrink the correction towards zero.

Two more terms are added, the orbit averages of the quadratic and cubic terms
of a near-identity coordinate change ``z = T u + Q(u, u) + C(u, u, u) + …``
from the normal form (with ``s = |u|²/r̄²``, ``r̄² = √(4Δμ)``):

.. math::

    \\vec U_{12} \\mathrel{+}= Q\\,[u_1^2,\\ u_1u_2,\\ u_2^2]^T/\\bar r^2 + s\\,L_2\\,u,

a general quadratic ``Q`` (2 × 3) and a change ``L2`` (lower-triangular) of the
linear block in proportion to ``r²``. The quadratic moves the centre of a
circle of radius ``r`` by ``(Q_{·1} + Q_{·3}) r²/(2 r̄²)`` and adds its second
harmonic; a cubic changes its size by ``O(r³)``; neither is a function of μ
alone, which is all ``T_s + T_L,μ μ̃`` and ``μ̃ L1`` can follow. (A shift of
the centre alone, without the second harmonic that any quadratic brings with
it, biased the amplitude on planted quadratic maps: the network, shrunk by its
prior, did not supply the missing harmonic.) On the simulated 3-DOF aerofoil
the mean pitch of an orbit moves by 0.035 rad between the smallest and largest
orbits (the quadratic pitch stiffness) and the heave gain by about 10 %; the
small network did not learn either (it stayed at 1 % of the orbit size), the
fitted orbits were displaced from the measured ones and the stable branch came
out 10 % low. With the two terms (five numbers) the orbits match and held-out
orbits fall in their predictive bands.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp


class MLPParams(NamedTuple):
    """Weights of a tanh MLP, one ``(W, b)`` pair per layer (W has shape (fan_in, fan_out))."""

    weights: tuple
    biases: tuple


def mlp_shapes(n_in: int, width: int, depth: int, n_out: int) -> list[tuple[int, int]]:
    """Weight shapes ``[(n_in, width), (width, width)…, (width, n_out)]``."""
    sizes = [n_in] + [width] * depth + [n_out]
    return list(zip(sizes[:-1], sizes[1:], strict=True))


def mlp(params: MLPParams, x):
    """Tanh MLP with a linear output; each layer's weights are scaled by ``1/√fan_in``.

    The scaling lets every weight have a unit-scale prior (a non-centred
    parameterisation, friendlier to SVI).
    """
    h = x
    n = len(params.weights)
    for i, (W, b) in enumerate(zip(params.weights, params.biases, strict=True)):
        h = h @ W / jnp.sqrt(W.shape[0]) + b
        if i < n - 1:
            h = jnp.tanh(h)
    return h


def lower_triangular(diag, off):
    """``[[d1, 0], [o, d2]]`` from ``diag = (d1, d2)`` and ``off = o``."""
    return jnp.stack([jnp.stack([diag[0], jnp.zeros_like(off)]), jnp.stack([off, diag[1]])])


def linear_map(T_L_diag, T_L_21, T_L_mu):
    """Assemble ``T_L`` (2×3) from its free entries.

    ``T_L = [[l11, 0, l13], [l21, l22, l23]]`` with ``(l11, l22) = T_L_diag > 0``,
    ``l21 = T_L_21`` and ``(l13, l23) = T_L_mu``.
    """
    return jnp.concatenate([lower_triangular(T_L_diag, T_L_21), T_L_mu[:, None]], axis=1)


def U12(u, mu_tilde, T_L, T_L1, T_s, nn: MLPParams, nn_scale, *, T_L2=None, T_Q=None,
        r2_scale=1.0):
    """``U12 = T_L [u1, u2, μ̃] + μ̃ L1 u + Q[u1², u1u2, u2²]/r̄² + s L2 u + T_s + nn_scale NN``.

    Eq. (g) of the paper with the μ̃-slope ``L1`` and the ``s = |u|²/r̄²`` terms
    (module docstring).

    Args:
        u: Normal-form points, shape ``(..., 2)``.
        mu_tilde: Scaled bifurcation parameter (a scalar).
        T_L: Linear part, shape ``(2, 3)``.
        T_L1: Lower-triangular μ̃-slope ``L1`` of the 2×2 block, shape ``(2, 2)``.
        T_s: Shift, shape ``(2,)``.
        nn: MLP weights (3 inputs, 2 outputs).
        nn_scale: Output scale of the correction.
        T_L2: Lower-triangular ``r²``-slope ``L2`` of the 2×2 block, shape
            ``(2, 2)``; ``None`` leaves the term out (fits saved without it).
        T_Q: Quadratic coefficients ``Q``, shape ``(2, 3)``; ``None`` leaves them out.
        r2_scale: ``r̄²``, the normal-form radius scale squared.

    Returns:
        Points in the planar frame, shape ``(..., 2)``.
    """
    x = jnp.concatenate([u, jnp.broadcast_to(mu_tilde, u.shape[:-1])[..., None]], axis=-1)
    out = x @ T_L.T + mu_tilde * (u @ T_L1.T) + T_s + nn_scale * mlp(nn, x)
    s = jnp.sum(u**2, axis=-1, keepdims=True) / r2_scale
    if T_L2 is not None:
        out = out + s * (u @ T_L2.T)
    if T_Q is not None:
        quad = jnp.stack([u[..., 0] ** 2, u[..., 0] * u[..., 1], u[..., 1] ** 2], axis=-1)
        out = out + (quad / r2_scale) @ T_Q.T
    return out
