"""The collapsed model's algebra against direct computations (scipy, closed forms)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import multivariate_normal

from bayeshopf.features.frame import PlanarFrame
from bayeshopf.model import collapsed as cm
from bayeshopf.model import normal_form


def _spec(unfolding="curved"):
    return cm.CollapsedSpec("subcritical", PlanarFrame(np.zeros(2), np.eye(2)), 3, 16.0, 2.0,
                            15.0, 16.5, 1.0, cm.hidden_layer(6), unfolding=unfolding)


@pytest.mark.parametrize("n, J", [(30, 8), (12, 20)])    # through A (J ≤ n) and through Σ̃
def test_log_marginal_equals_the_gaussian_it_collapses(n, J):
    rng = np.random.default_rng(0)
    Phi = rng.standard_normal((n, J))
    sd = np.exp(rng.standard_normal(J))
    d = np.exp(rng.standard_normal(n)) * 0.1
    y = rng.standard_normal(n)
    direct = multivariate_normal(np.zeros(n), Phi @ np.diag(sd**2) @ Phi.T + np.diag(d)).logpdf(y)
    np.testing.assert_allclose(cm.log_marginal(Phi, y, d, sd), direct, rtol=1e-10)


@pytest.mark.parametrize("n, J", [(24, 7), (10, 18)])    # through A (J ≤ n) and through Σ̃
def test_log_marginal_derivatives_equal_those_of_the_dense_gaussian(n, J):
    # the hand-written JVPs against reverse mode through the dense n x n Cholesky
    # (jax.scipy's multivariate normal), first and second derivatives, on one
    # smooth path through all four arguments
    rng = np.random.default_rng(2)
    Phi0, dPhi = rng.standard_normal((n, J)), rng.standard_normal((n, J))
    y0, dy = rng.standard_normal(n), rng.standard_normal(n)
    d0, dd = np.exp(rng.standard_normal(n)) * 0.2, rng.standard_normal(n)
    sd0, dsd = np.exp(rng.standard_normal(J)), rng.standard_normal(J)

    def args(x):
        return (Phi0 + x[0] * dPhi + x[1] ** 2 * dPhi[::-1], y0 + x[1] * dy,
                d0 * jnp.exp(0.3 * x[2] * dd), sd0 * jnp.exp(0.3 * (x[0] - x[2]) * dsd))

    def dense(x):
        Phi, y, d, sd = args(x)
        cov = (Phi * sd**2) @ Phi.T + jnp.diag(d)
        return jax.scipy.stats.multivariate_normal.logpdf(y, jnp.zeros(n), cov)

    def collapsed(x):
        return cm.log_marginal(*args(x))

    x = jnp.array([0.3, -0.4, 0.5])
    for derivative, rtol in ((lambda f: f, 1e-10), (jax.grad, 1e-8), (jax.hessian, 1e-7)):
        # compiled: op by op, the Hessians alone took 27 s of compiling
        np.testing.assert_allclose(jax.jit(derivative(collapsed))(x),
                                   jax.jit(derivative(dense))(x), rtol=rtol, atol=1e-9)


def test_conditional_draws_have_the_closed_form_moments():
    rng = np.random.default_rng(1)
    Phi = rng.standard_normal((20, 4))
    sd, d, y = np.array([1.0, 0.5, 2.0, 0.1]), np.full(20, 0.3), rng.standard_normal(20)
    V = np.diag(sd**2)
    cov = np.linalg.inv(np.linalg.inv(V) + Phi.T @ Phi / 0.3)
    mean = cov @ Phi.T @ y / 0.3
    eps = jax.random.normal(jax.random.PRNGKey(0), (20000, 4))
    draws = np.asarray(jax.lax.map(lambda e: cm.conditional_draw(Phi, y, d, sd, e)[0], eps))
    np.testing.assert_allclose(cm.conditional_draw(Phi, y, d, sd, jnp.zeros(4))[1], mean,
                               atol=1e-10)
    np.testing.assert_allclose(draws.mean(0), mean, atol=4 * np.sqrt(np.diag(cov).max() / 2e4))
    np.testing.assert_allclose(np.cov(draws.T), cov, atol=0.05 * np.abs(cov).max())


def test_design_is_the_projection_of_the_mapped_circle():
    spec = _spec()
    theta = {"mu0": 17.0, "mu_fold": 14.5, "a2": 2.0, "w_unfold": 0.8}
    mu, sign = jnp.array([15.5, 16.0]), jnp.array([1.0, -1.0])
    beta = jnp.asarray(np.random.default_rng(2).standard_normal((spec.n_basis, 2)))
    Phi = cm.design(spec, mu, sign, theta, n_phi=64)
    phi = jnp.linspace(0, 2 * jnp.pi, 64, endpoint=False)
    for i in range(2):
        w = cm.orbit(spec, theta, beta, mu[i], sign[i], phi)
        coeffs = cm.projection(3, 64) @ w                       # (2K+1, 2)
        np.testing.assert_allclose(Phi[i] @ beta, coeffs, atol=1e-12)


def test_control_columns_are_the_complex_gain_times_the_control():
    """Φ's control columns give Δ(a₁ − i b₁) = H u (u = u_a − i u_b), and the orbit in
    phase (``cm.orbit`` with the control) is the same response."""
    spec = dataclasses.replace(_spec(), control_scale=5.0)
    assert spec.n_basis == spec.n_map + 2 and cm.basis_names(spec)[-2:] == list(cm.CONTROL_TERMS)
    theta = {"mu0": 17.0, "mu_fold": 14.5, "a2": 2.0 * np.sqrt(2.5), "w_unfold": 0.0}
    mu, sign = jnp.array([15.5, 16.0]), jnp.array([1.0, -1.0])
    u = np.array([[0.3, -0.2], [-0.1, 0.4]])
    rng = np.random.default_rng(3)
    beta = jnp.asarray(rng.standard_normal((spec.n_basis, 2)))
    H = np.asarray(beta[-2] + 1j * beta[-1])                     # per channel
    free = np.asarray(cm.design(spec, mu, sign, theta, n_phi=64) @ beta)
    assert np.isfinite(free).all()
    held = np.asarray(cm.design(spec, mu, sign, theta, n_phi=64, control=u) @ beta)
    K = spec.n_harmonics
    delta = held - free                                            # (n, 2K+1, 2)
    for i in range(2):
        got = delta[i, 1] - 1j * delta[i, K + 1]
        np.testing.assert_allclose(got, H * (u[i, 0] - 1j * u[i, 1]), atol=1e-12)
        others = np.delete(delta[i], [1, K + 1], axis=0)
        assert np.abs(others).max() == 0.0
        # the same orbit sampled in phase, then projected
        phi = jnp.linspace(0, 2 * jnp.pi, 64, endpoint=False)
        w = cm.orbit(spec, theta, beta, mu[i], sign[i], phi, control=jnp.asarray(u[i]))
        np.testing.assert_allclose(cm.projection(K, 64) @ w, held[i], atol=1e-12)
    # the response is w2's: w1's design has zeros in the control columns
    w1, w2 = cm.channel_designs(spec, mu, sign, theta, control=u)
    assert np.all(np.asarray(w1)[:, spec.n_map:] == 0)
    np.testing.assert_array_equal(np.asarray(w2), np.asarray(
        cm.design(spec, mu, sign, theta, control=u)).reshape(-1, spec.n_basis))
    # the prior sd of the gain's two parts is the spec's
    sd = np.asarray(cm.prior_sd(spec, 0.1, 0.1))
    assert sd.shape == (spec.n_basis,) and np.all(sd[-2:] == 5.0)


@pytest.mark.parametrize("n_pairs", [4, 1])    # 56 data, 36 columns (A); 14 data (Σ̃)
def test_log_marginal_derivatives_hold_when_the_measurement_errors_are_small(n_pairs):
    # the model's own design (8 recordings on both branches, or 2: more columns than
    # data, so through Σ̃) with errors of 1e-4 of the signal: A = I + Φ'ᵀD⁻¹Φ' is
    # ill-conditioned (about 1e9) and yᵀD⁻¹y − bᵀA⁻¹b a difference of large numbers, as on
    # the demo. The value returned with the gradient must be the primal's (an explicit A⁻¹
    # was off by about 1 here), the gradient that of reverse mode through the Cholesky
    # factorisation of A (JAX's own rules; the dense n × n Gaussian is itself too
    # ill-conditioned to serve)
    spec = _spec()
    theta = {"mu0": 17.0, "mu_fold": 14.5, "a2": 2.0 * np.sqrt(2.5), "w_unfold": 0.0}
    mu = jnp.array([15.0, 15.5, 16.0, 16.5][:n_pairs] * 2)
    sign = jnp.array([1.0] * n_pairs + [-1.0] * n_pairs)
    Phi0 = np.asarray(cm.design(spec, mu, sign, theta)).reshape(-1, spec.n_basis)
    rng = np.random.default_rng(5)
    sd0 = np.asarray(cm.prior_sd(spec, 0.1, 0.1))
    y = Phi0 @ (sd0 * rng.standard_normal(spec.n_basis))
    d0 = np.full(y.size, (1e-4 * np.std(y)) ** 2)
    y = y + np.sqrt(d0) * rng.standard_normal(y.size)

    def reference(Phi, y, d, sd):            # Woodbury, differentiated by JAX's rules
        Ps = Phi * sd
        A = jnp.eye(Ps.shape[1]) + Ps.T @ (Ps / d[:, None])
        L = jnp.linalg.cholesky(A)
        z = jax.scipy.linalg.solve_triangular(L, Ps.T @ (y / d), lower=True)
        logdetA = 2.0 * jnp.sum(jnp.log(jnp.diag(L)))
        return -0.5 * (jnp.sum(y * y / d) - z @ z + jnp.sum(jnp.log(d)) + logdetA
                       + y.size * jnp.log(2 * jnp.pi))

    def path(f):
        return lambda x: f(Phi0, y, d0 * jnp.exp(x[:y.size]), sd0 * jnp.exp(x[y.size:]))

    x = jnp.asarray(0.1 * rng.standard_normal(y.size + spec.n_basis))
    value, grad = jax.jit(jax.value_and_grad(path(cm.log_marginal)))(x)
    ref_value, ref_grad = jax.jit(jax.value_and_grad(path(reference)))(x)
    np.testing.assert_allclose(value, ref_value, rtol=1e-7)     # 3e-9 here; 9e-4 with A⁻¹
    np.testing.assert_allclose(value, jax.jit(path(cm.log_marginal))(x), rtol=1e-7)
    np.testing.assert_allclose(grad, ref_grad, rtol=1e-5, atol=1e-6 * np.abs(ref_grad).max())


def test_predicted_orbit_coefficients_are_the_fourier_coefficients_of_the_mapped_circle():
    # predictive.orbit_coefficients (the bands, the diagram, the checks) against the
    # DFT of the map evaluated on 256 phases of each draw's circle; nan off the branch
    from bayeshopf.predictive import orbit_coefficients

    spec = _spec()
    rng = np.random.default_rng(3)
    theta = {"mu0": np.array([17.0, 16.6]), "mu_fold": np.array([14.5, 14.8]),
             "w_unfold": np.array([0.8, -0.3])}
    theta["a2"] = 2 * np.sqrt(-np.asarray(cm.unfolding(theta["mu_fold"], theta["mu0"],
                                                       theta["w_unfold"], theta["mu_fold"])))
    betas = rng.standard_normal((2, spec.n_basis, 2))
    mu = np.array([14.0, 15.5, 16.3])
    phi = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    K = spec.n_harmonics
    for sign in (normal_form.STABLE, normal_form.UNSTABLE):
        got = orbit_coefficients(spec, theta, betas, mu, sign)      # (draw, μ, channel, 2K+1)
        for n in range(2):
            t = {k: v[n] for k, v in theta.items()}
            for i in range(mu.size):
                w = np.asarray(cm.orbit(spec, t, betas[n], mu[i], sign, phi))     # (256, 2)
                F = np.fft.rfft(w, axis=0) / phi.size
                ref = np.concatenate([F[:1].real, 2 * F[1:K + 1].real, -2 * F[1:K + 1].imag]).T
                if np.isnan(w).any():
                    assert np.isnan(got[n, i]).all()
                else:
                    np.testing.assert_allclose(got[n, i], ref, atol=1e-9 * np.abs(ref).max())
    assert np.isnan(orbit_coefficients(spec, theta, betas, mu, normal_form.STABLE)[:, 0]).all()


def test_curved_unfolding_keeps_the_hopf_point_and_is_monotone():
    mu = np.linspace(13.0, 19.0, 401)
    lin = cm.unfolding(mu, 17.0, 0.0, 14.5)
    np.testing.assert_allclose(lin, mu - 17.0, atol=1e-12)
    for w in (-2.0, 1.5, 4.0):
        b = np.asarray(cm.unfolding(mu, 17.0, w, 14.5))
        assert np.all(np.diff(b) > 0)
        slope = jax.grad(lambda m, w=w: cm.unfolding(m, 17.0, w, 14.5))(17.0)
        assert abs(float(cm.unfolding(17.0, 17.0, w, 14.5))) < 1e-14
        np.testing.assert_allclose(slope, 1.0, rtol=1e-10)


def test_branches_meet_at_the_sampled_fold():
    """With a2 from β(μ_SN) = −a2²/4, both radii coincide at μ_SN (closed form)."""
    mu0, mu_fold, w = 17.0, 14.5, 1.7
    beta_fold = -float(cm.unfolding(mu_fold, mu0, w, mu_fold))
    theta = {"mu0": mu0, "mu_fold": mu_fold, "a2": 2 * np.sqrt(beta_fold), "w_unfold": w}
    spec = _spec()
    rs = cm.radius(spec, mu_fold + 1e-9, normal_form.STABLE, theta)
    ru = cm.radius(spec, mu_fold + 1e-9, normal_form.UNSTABLE, theta)
    np.testing.assert_allclose(rs, ru, rtol=1e-3)
    assert np.isnan(cm.radius(spec, mu_fold - 0.01, normal_form.STABLE, theta))
    assert np.isnan(cm.radius(spec, mu0 + 0.01, normal_form.UNSTABLE, theta))
    # on the curved branch the radius solves r⁴ − a2 r² − β(μ) = 0
    r = float(cm.radius(spec, 16.0, normal_form.STABLE, theta))
    b = float(cm.unfolding(16.0, mu0, w, mu_fold))
    np.testing.assert_allclose(r**4 - theta["a2"] * r**2 - b, 0.0, atol=1e-12)


def test_amplitude_is_the_peak_to_peak_of_z1_in_physical_units():
    """``amplitude_of`` (z1's coefficients only) against the full orbit mapped point by point."""
    from types import SimpleNamespace

    from bayeshopf.predictive import amplitude_of

    rng = np.random.default_rng(3)
    frame = PlanarFrame(np.array([0.6, 0.7]), np.array([[0.02, 0.01], [0.05, 0.3]]))
    K = 3
    c = rng.standard_normal((4, 5, 2, 2 * K + 1)) * np.array([1.0, 1, 0.3, 0.1, 0, 0.3, 0.1])
    phi = np.linspace(0, 2 * np.pi, 20000, endpoint=False)
    k = np.arange(1, K + 1)
    w = (c[..., :1] + np.einsum("...k,kp->...p", c[..., 1:K + 1], np.cos(k[:, None] * phi))
         + np.einsum("...k,kp->...p", c[..., K + 1:], np.sin(k[:, None] * phi)))  # (..., 2, P)
    z = frame.centre + np.swapaxes(w, -1, -2) @ frame.L.T                          # (..., P, 2)
    ref = np.ptp(z[..., 0], axis=-1)
    got = amplitude_of(SimpleNamespace(frame=frame), c)
    np.testing.assert_allclose(got, ref, rtol=1e-3)     # 256 phases: a crest falls between two
    c[0, 0, 0, 0] = np.nan
    assert np.isnan(amplitude_of(SimpleNamespace(frame=frame), c)[0, 0])


@pytest.mark.parametrize("shape", [(7, 5, 2, 9), (301, 1, 2, 9), (5, 3, 4, 2, 9)])
def test_amplitude_in_chunks_equals_one_product(monkeypatch, shape):
    """A diagram's band reconstructs its orbits a few draws at a time; the values
    are those of one product over every draw, bit for bit."""
    from types import SimpleNamespace

    import bayeshopf.predictive as bp

    spec = SimpleNamespace(frame=PlanarFrame(np.array([0.6, 0.7]),
                                             np.array([[0.02, 0.01], [0.05, 0.3]])))
    c = np.random.default_rng(4).standard_normal(shape)
    monkeypatch.setattr(bp, "_CHUNK_POINTS", 1 << 40)        # one chunk
    whole = bp.amplitude_of(spec, c)
    monkeypatch.setattr(bp, "_CHUNK_POINTS", 2 * 256 * int(np.prod(shape[1:-2])))
    chunked = bp.amplitude_of(spec, c)                       # two rows a chunk
    assert chunked.shape == shape[:-2]
    np.testing.assert_array_equal(chunked, whole)


def test_extrapolation_sd_is_the_gaussian_process_conditional():
    """Zero at the data, the one-point closed form √(1 − e^{−d²/ℓ²}), 1 far away or without data."""
    ell = 0.8
    d = np.array([0.0, 0.3, 0.8, 2.0])
    np.testing.assert_allclose(cm.extrapolation_sd(15.0 + d, [15.0], ell),
                               np.sqrt(1 - np.exp(-(d / ell) ** 2)), atol=2e-5)  # jitter 1e-10
    data = [14.9, 15.7, 16.5, 16.5]                         # a repeated μ is one point
    np.testing.assert_allclose(cm.extrapolation_sd(data, data, ell), 0.0, atol=1e-4)
    far = cm.extrapolation_sd([30.0], data, ell)
    assert far[0] == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_array_equal(cm.extrapolation_sd([15.0, 16.0], [], ell), [1.0, 1.0])
    # between two recordings it is below its value beside one: a second neighbour explains more
    mid = cm.extrapolation_sd([15.3], [14.9, 15.7], ell)[0]
    one = cm.extrapolation_sd([15.3], [14.9], ell)[0]
    assert mid < one


def test_block_log_predictive_is_the_gaussian_conditional():
    """Against the partitioned covariance: ``y_b | y_−b`` by scipy, block by block."""
    rng = np.random.default_rng(4)
    n_blocks, m = 4, 3
    Phi = rng.standard_normal((n_blocks * m, 5))
    sd = np.exp(0.3 * rng.standard_normal(5))
    d = np.exp(rng.standard_normal(n_blocks * m)) * 0.2
    y = rng.standard_normal(n_blocks * m)
    S = Phi @ np.diag(sd**2) @ Phi.T + np.diag(d)
    got = np.asarray(cm.block_log_predictive(Phi, y, d, sd, n_blocks))
    for b in range(n_blocks):
        i = np.arange(b * m, (b + 1) * m)
        o = np.setdiff1d(np.arange(n_blocks * m), i)
        K = S[np.ix_(i, o)] @ np.linalg.inv(S[np.ix_(o, o)])
        cond = multivariate_normal(K @ y[o], S[np.ix_(i, i)] - K @ S[np.ix_(o, i)])
        np.testing.assert_allclose(got[b], cond.logpdf(y[i]), rtol=1e-9)
    # the blocks' densities do not sum to the joint (they are conditionals), but the chain
    # rule does: log p(y) = log p(y_rest) + log p(y_last | y_rest)
    rest = np.arange((n_blocks - 1) * m)
    joint = multivariate_normal(np.zeros(n_blocks * m), S).logpdf(y)
    marg = multivariate_normal(np.zeros(rest.size), S[np.ix_(rest, rest)]).logpdf(y[rest])
    np.testing.assert_allclose(marg + got[-1], joint, rtol=1e-9)
