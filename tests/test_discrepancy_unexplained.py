""""Unexplained" as a model (bayeshopf.discrepancy.unexplained).

The evidence with the discrepancy integrated out is checked against the dense
Gaussian marginal likelihood written out here; the model is then checked on
simulated recordings where the truth is known: with the parameters off only,
the smooth discrepancy must not be preferred; with a smooth misfit that no
parameter can take up, it must be.
"""

import numpy as np
import pytest
from scipy import stats

from bayeshopf.discrepancy.unexplained import evidence_grid


def test_evidence_with_discrepancy_is_the_dense_gaussian_marginal():
    rng = np.random.default_rng(0)
    R, P, d = 6, 5, 3                        # 6 recordings, 5 features, 3 parameters
    N = R * P
    e = rng.normal(size=N)
    J = rng.normal(size=(N, d))
    x = rng.normal(size=d) * 0.3
    E = np.concatenate([e, x])               # prior rows last, as the package stacks them
    G = np.concatenate([J, np.eye(d)])
    X = rng.uniform(size=(R, 2))
    K = np.exp(-np.sum((X[:, None] - X[None]) ** 2, axis=-1) / (2 * 0.4**2))
    rows = {0: np.arange(R) * P + 0, 3: np.arange(R) * P + 3}
    W = {0: rng.uniform(1, 5, R), 3: rng.uniform(1, 5, R)}
    r = e - J @ x

    def dense(eta, Kc):
        """∫ N(u; 0, I) exp(-½ (r + J u)ᵀ C⁻¹ (r + J u)) / sqrt(det C) du, r = e − J x:
        the package's normalisation (2π)^(N/2) times the Gaussian density of r."""
        C = np.eye(N)
        for j, rr in rows.items():
            C[np.ix_(rr, rr)] += eta**2 * np.outer(W[j], W[j]) * Kc
        return stats.multivariate_normal(np.zeros(N), C + J @ J.T).logpdf(r) + 0.5 * N * (
            np.log(2 * np.pi))

    # over a grid of η and kernels, η = 0 (the plain Laplace evidence) among them
    kernels = np.array([K, K**2, np.eye(R)])
    etas = np.array([0.0, 0.2, 0.7, 3.0])
    grid = evidence_grid(E, G, rows, W, etas, kernels)
    for b, et in enumerate(etas):
        for c, Kc in enumerate(kernels):
            assert grid[b, c] == pytest.approx(dense(et, Kc), abs=1e-8)
    want0 = stats.multivariate_normal(np.zeros(N), np.eye(N) + J @ J.T).logpdf(r) + 0.5 * N * (
        np.log(2 * np.pi))
    assert grid[0, 0] == pytest.approx(want0, abs=1e-8)


def test_scale_mixture_bayes_factor_is_the_closed_form():
    """A 1-D Gaussian likelihood: mixture BF = mean over f of N(ẑ; 0, σ²+f²)/N(ẑ; 0, σ²)."""
    from bayeshopf.discrepancy.nested import SCALES, CoefficientPosterior, mixture_log_bf

    for zhat, sd in ((0.02, 0.005), (0.3, 0.1), (0.0, 0.01), (3.0, 0.2)):
        prec = 1.0 + 1.0 / sd**2                      # the posterior under the N(0, 1) prior
        post = CoefficientPosterior(np.array([1.0]), np.array([[zhat / sd**2 / prec]]),
                                    np.array([[[1.0 / prec]]]), (False,))
        want = np.log(np.mean([stats.norm.pdf(zhat, 0, np.hypot(sd, f)) for f in SCALES])
                      / stats.norm.pdf(zhat, 0, sd))
        assert mixture_log_bf(post) == pytest.approx(want, abs=1e-9)
    # three decades, log-uniform: the factors' quantiles
    assert SCALES[0] == pytest.approx(1e-3 * 10 ** (3 / 24)) and len(SCALES) == 12


def test_bivariate_orthant_probability_matches_genz():
    """The positive quadrant of a bivariate normal against scipy's Genz integration."""
    from bayeshopf.discrepancy.nested import _orthant2

    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(200):
        m = rng.normal(size=2) * rng.choice([0.3, 2.0, 6.0])
        s = np.exp(rng.normal(size=2))
        rho = rng.uniform(-0.99, 0.99)
        C = np.array([[s[0] ** 2, rho * s[0] * s[1]], [rho * s[0] * s[1], s[1] ** 2]])
        ref = stats.multivariate_normal.cdf(np.zeros(2), mean=-m, cov=C, abseps=1e-13,
                                            releps=1e-10)
        if ref < 1e-10:
            continue
        checked += 1
        assert _orthant2(m, C) == pytest.approx(np.log(ref), abs=1e-6)
    assert checked > 100


@pytest.fixture(scope="module")
def fitter():
    from bayeshopf._x64 import ensure_x64

    ensure_x64()
    from bayeshopf.discrepancy.prepare import prepare
    from bayeshopf.simulators import FLUTTER3DOF, simulate_recordings

    mus = [15.5, 16.5, 17.5, 15.5, 16.5, 17.0]
    rs = simulate_recordings(FLUTTER3DOF, mus, ["stable"] * 3 + ["unstable"] * 3, noise=0.01,
                             duration_s=4.0, sample_rate_hz=250.0, seed=2)
    unc = FLUTTER3DOF.uncertain
    return prepare(rs, FLUTTER3DOF, parameters=[u.name for u in unc])[0].with_model_error(1e-3)


def _calibration(fitter, e, J):
    from bayeshopf.discrepancy.records import Calibration

    d = J.shape[1]
    return Calibration(parameters=(), z_mode=np.zeros(d), cov=np.eye(d), log_z=-10.0, chi2=0.0,
                       p_eff=0.0, e_mode=e, jac=J, jac_nominal=J, orbits=fitter.base,
                       fitter=fitter)


@pytest.mark.parametrize("eta_true", [0.0, 0.03, 0.2])   # 0.2: four prior scales out
def test_a_smooth_misfit_the_parameters_cannot_take_is_unexplained(fitter, eta_true):
    """Residuals: white noise, plus (η_true > 0) a smooth relative error of the fundamentals
    over the diagram, drawn here; two parameters whose columns are random."""
    from bayeshopf.discrepancy.unexplained import diagram_inputs, smooth_columns, unexplained

    rng = np.random.default_rng(11)
    R, P = fitter.mf.y.shape
    e = rng.normal(size=(R, P))
    X = diagram_inputs(fitter)
    for j in smooth_columns(fitter):
        # one smooth function of the diagram per feature, relative to ref, whitened by σ
        a, b = rng.normal(size=2)
        g = a * np.sin(2.0 * X[:, 0] + 0.5) + b * np.cos(1.5 * X[:, 1])
        e[:, j] += eta_true * g * fitter.ref[:, j] / fitter.sigma[:, j]
    J = rng.normal(size=(R * P, 2))
    md = unexplained(_calibration(fitter, e, J))
    assert md.log_z == pytest.approx(-10.0 + md.log_bf)
    if eta_true == 0.0:
        assert md.log_bf < 0.0                  # the discrepancy pays its Occam factor
        assert md.eta_ci90[1] < 0.01
    else:
        assert md.log_bf > 10.0
        assert md.eta_ci90[0] < eta_true < md.eta_ci90[1]
