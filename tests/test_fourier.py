from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from bayeshopf.features import fourier

N_H = 4
# planted R(θ) = c0 + Σ a_k cos kθ + b_k sin kθ, coefficient layout [a0, a1..a4, b1..b4]
PLANTED = np.array([2.0, 0.3, -0.1, 0.05, 0.02, -0.2, 0.15, -0.03, 0.01])


def planted_R(theta: np.ndarray, c: np.ndarray = PLANTED) -> np.ndarray:
    n_h = (c.size - 1) // 2
    k = np.arange(1, n_h + 1)
    return (
        c[0]
        + np.cos(np.outer(theta, k)) @ c[1 : n_h + 1]
        + np.sin(np.outer(theta, k)) @ c[n_h + 1 :]
    )


def rfft_coeffs(R: np.ndarray, n_h: int) -> np.ndarray:
    """[a0, a_k, b_k] from the DFT of samples on θ_j = 2πj/N."""
    n = R.size
    X = np.fft.rfft(R)
    return np.concatenate(
        [[X[0].real / n], 2 * X[1 : n_h + 1].real / n, -2 * X[1 : n_h + 1].imag / n]
    )


def test_design_matrix_layout() -> None:
    theta = np.array([0.0, 0.4, 2.0])
    A = fourier.design_matrix(theta, 2)
    expected = np.stack(
        [np.ones(3), np.cos(theta), np.cos(2 * theta), np.sin(theta), np.sin(2 * theta)], axis=1
    )
    np.testing.assert_allclose(A, expected, atol=1e-15)
    assert fourier.n_coefficients(2) == 5


@pytest.mark.parametrize("n", [64, 101])
def test_project_uniform_grid_equals_rfft(n: int) -> None:
    theta = 2 * np.pi * np.arange(n) / n
    R = planted_R(theta)
    c = fourier.project(theta, R, N_H)
    np.testing.assert_allclose(c, rfft_coeffs(R, N_H), atol=1e-13)
    np.testing.assert_allclose(c, PLANTED, atol=1e-13)


def test_project_uniform_grid_truncates_like_rfft() -> None:
    # a curve with harmonics above n_h: on a uniform grid least squares = truncated DFT
    rng = np.random.default_rng(1)
    full = rng.normal(size=2 * 10 + 1) * 0.1
    full[0] = 3.0
    theta = 2 * np.pi * np.arange(128) / 128
    R = planted_R(theta, full)
    c = fourier.project(theta, R, 3)
    np.testing.assert_allclose(c, rfft_coeffs(R, 3), atol=1e-12)
    np.testing.assert_allclose(c, np.concatenate([full[:4], full[11:14]]), atol=1e-12)


def test_project_non_uniform_grid_recovers_planted() -> None:
    rng = np.random.default_rng(0)
    theta = np.sort(rng.uniform(-np.pi, np.pi, 300)) ** 3 / np.pi**2  # bunched near 0
    R = planted_R(theta)
    np.testing.assert_allclose(fourier.project(theta, R, N_H), PLANTED, atol=1e-10)
    # the plain DFT formula is wrong on such a grid (this is why least squares is used)
    naive = np.concatenate(
        [[R.mean()], 2 * np.cos(np.outer(theta, np.arange(1, N_H + 1))).T @ R / R.size]
    )
    assert np.max(np.abs(naive - PLANTED[: N_H + 1])) > 0.05


def test_project_with_noise_is_least_squares() -> None:
    rng = np.random.default_rng(3)
    theta = rng.uniform(-np.pi, np.pi, 500)
    R = planted_R(theta) + 0.01 * rng.normal(size=theta.size)
    c = fourier.project(theta, R, N_H)
    lstsq = np.linalg.lstsq(fourier.design_matrix(theta, N_H), R, rcond=None)[0]
    np.testing.assert_allclose(c, lstsq, atol=1e-12)
    np.testing.assert_allclose(c, PLANTED, atol=5e-3)


def test_evaluate_and_curve_round_trip() -> None:
    theta = np.linspace(-np.pi, np.pi, 77)
    np.testing.assert_allclose(fourier.evaluate(PLANTED, theta), planted_R(theta), atol=1e-14)
    # batched coefficients
    batch = np.stack([PLANTED, 2 * PLANTED])
    out = fourier.evaluate(batch, theta)
    assert out.shape == (2, 77)
    np.testing.assert_allclose(out[1], 2 * planted_R(theta), atol=1e-14)
    # curve -> polar -> project gives the coefficients back
    pts = fourier.curve(PLANTED, 200)
    assert pts.shape == (200, 2)
    R, th = fourier.polar(pts)
    np.testing.assert_allclose(R, planted_R(th), atol=1e-13)
    np.testing.assert_allclose(fourier.project(th, R, N_H), PLANTED, atol=1e-12)
    assert fourier.curve(batch, 50).shape == (2, 50, 2)


def test_polar_of_circle() -> None:
    phi = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    w = 1.5 * np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    R, theta = fourier.polar(w)
    np.testing.assert_allclose(R, 1.5, atol=1e-14)
    assert np.all((theta > -np.pi) & (theta <= np.pi))
    np.testing.assert_allclose(np.exp(1j * theta), np.exp(1j * phi), atol=1e-14)
    # a circle's coefficients are [1.5, 0, ...]
    c = fourier.project(theta, R, 3)
    np.testing.assert_allclose(c, np.r_[1.5, np.zeros(6)], atol=1e-14)


def test_numpy_and_jax_agree() -> None:
    rng = np.random.default_rng(5)
    theta = rng.uniform(-np.pi, np.pi, 120)
    R = planted_R(theta) + 0.01 * rng.normal(size=theta.size)
    c_np = fourier.project(theta, R, N_H)
    c_jx = fourier.project(jnp.asarray(theta), jnp.asarray(R), N_H)
    assert isinstance(c_np, np.ndarray) and isinstance(c_jx, jax.Array)
    assert c_jx.dtype == jnp.float64
    np.testing.assert_allclose(np.asarray(c_jx), c_np, atol=1e-12)
    np.testing.assert_allclose(
        np.asarray(fourier.evaluate(jnp.asarray(c_np), jnp.asarray(theta))),
        fourier.evaluate(c_np, theta),
        atol=1e-13,
    )
    np.testing.assert_allclose(
        np.asarray(fourier.curve(jnp.asarray(c_np), 64)), fourier.curve(c_np, 64), atol=1e-13
    )
    pts = fourier.curve(c_np, 64)
    for a, b in zip(fourier.polar(jnp.asarray(pts)), fourier.polar(pts), strict=True):
        np.testing.assert_allclose(np.asarray(a), b, atol=1e-13)
    # and the jax path is differentiable (the model uses it inside the likelihood)
    g = jax.grad(lambda s: fourier.project(jnp.asarray(theta), s * jnp.asarray(R), N_H)[0])(1.0)
    assert float(g) == pytest.approx(c_np[0], rel=1e-10)
