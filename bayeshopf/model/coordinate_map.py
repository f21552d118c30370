r"""The learnt map from normal-form to measured coordinates (paper eq. g).

.. math::

    \\vec U_{12}(u_1, u_2, \\mu) = T_L\\,[u_1, u_2, \\tilde\\mu]^T + T_s
        + \\mathrm{NN}_{\\Theta_U}(u_1, u_2, \\tilde\\mu),

written in the common planar frame (:mod:`bayeshopf.features.frame`), with
``μ̃ = (μ − μ_c)/Δμ`` the bifurcation parameter centred and scaled by the data.
``T_L`` is 2×3: its left 2×2 block is lower-triangular with a positive diagonal.
That fixes the gauge: the normal form is invariant under rotations of
``(u1, u2)``, so a full 2×2 block would leave a ring of equivalent maps.

One term is added to the paper's eq. (g): the 2×2 block varies with μ to second
order, ``T_u(μ̃) = L0 + μ̃ L1 + μ̃² L2`` (all lower-triangular). On the
wind-tunnel rig the ratio of heave to pitch amplitude grows by a third across the
measured speeds, which a μ-independent linear map cannot follow; the authors'
code learns a μ-dependent 2×2 matrix with a second network (``ann_l``), and the
Taylor terms do the same with six interpretable numbers. The second order is
needed for the Hopf point itself: the LCOs are observed only on ``|u| = r(μ)``,
so a gain that changes with μ trades against μ0, and a map restricted to a
linear change biased μ0 of the Van der Pol oscillator by −0.002 (against +0.004
with no change), whose orbits' gain in the frame grows as μ². The neural network
is a small tanh MLP whose output is multiplied by a learnt scale, so its prior
can shrink the correction towards zero.
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


def U12(u, mu_tilde, T_L, T_L1, T_s, nn: MLPParams, nn_scale, T_L2=None):
    """``U12 = T_L [u1, u2, μ̃] + (μ̃ L1 + μ̃² L2) u + T_s + nn_scale · NN(u1, u2, μ̃)`` (eq. g).

    Args:
        u: Normal-form points, shape ``(..., 2)``.
        mu_tilde: Scaled bifurcation parameter (a scalar).
        T_L: Linear part, shape ``(2, 3)``.
        T_L1: Lower-triangular μ̃-slope ``L1`` of the 2×2 block, shape ``(2, 2)``.
        T_s: Shift, shape ``(2,)``.
        nn: MLP weights (3 inputs, 2 outputs).
        nn_scale: Output scale of the correction.
        T_L2: Lower-triangular μ̃²-coefficient ``L2`` of the 2×2 block, shape
            ``(2, 2)``, or ``None`` for none.

    Returns:
        Points in the planar frame, shape ``(..., 2)``.
    """
    x = jnp.concatenate([u, jnp.broadcast_to(mu_tilde, u.shape[:-1])[..., None]], axis=-1)
    slope = T_L1 if T_L2 is None else T_L1 + mu_tilde * T_L2
    return x @ T_L.T + mu_tilde * (u @ slope.T) + T_s + nn_scale * mlp(nn, x)
