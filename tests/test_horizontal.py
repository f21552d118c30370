"""The horizontal discrepancy's curve (a Gaussian process in its curvature, or a window at
the fold) against SciPy's quadrature and root finds, and the closed form."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from bayeshopf import ensure_x64
from bayeshopf.model import horizontal as hz
from bayeshopf.model import normal_form

ensure_x64()


def _coefficients(seed, eta=0.5, ell=0.3):
    z = np.random.default_rng(seed).standard_normal(hz.N_BASIS)
    return hz.coefficients(eta, ell, jnp.asarray(z))


def test_basis_reproduces_the_squared_exponential_kernel():
    """Σ_k S(ω_k) φ_k(x) φ_k(x') against η² exp(−(x−x')²/2ℓ²), where the docs say it holds."""
    eta, ell = 0.2, 0.5
    x = np.linspace(0.0, 1.2, 9)
    w = hz.frequencies()
    phi = np.sin((x[:, None] + hz.HALF_WIDTH) * w) / np.sqrt(hz.HALF_WIDTH)
    s = np.asarray(hz.coefficients(eta, ell, jnp.ones(hz.N_BASIS))) ** 2
    approx = (phi * s) @ phi.T
    exact = eta**2 * np.exp(-0.5 * (x[:, None] - x[None]) ** 2 / ell**2)
    np.testing.assert_allclose(approx, exact, atol=0.03 * eta**2)


def _curve_by_quad(c):
    """``H`` by SciPy's adaptive quadrature of the module's formula, written apart."""
    w = hz.frequencies()
    cn = np.asarray(c)

    def e(t):
        return float(np.sum(np.sin(w * (t + hz.HALF_WIDTH)) * cn) / np.sqrt(hz.HALF_WIDTH))

    norm = quad(lambda t: t * np.exp(e(t)), 0.0, 0.5, epsabs=1e-14)[0]
    return lambda x: quad(lambda t: (x - t) * np.exp(e(t)), 0.5, x, epsabs=1e-14)[0] / norm


def _check_roots(H, c, mus, hopf=18.0, fold=14.0, tol=1e-8, form="process"):
    """The module's roots of ``H(x) = (μ − μ_SN)/Δ`` against ``brentq`` on both branches."""
    for mu in mus:
        v = (mu - fold) / (hopf - fold)
        x_s = brentq(lambda t, v=v: H(t) - v, 0.5, 4.0, xtol=1e-14)
        assert float(hz.position(mu, 1.0, hopf, fold, c, form)) == pytest.approx(x_s, abs=tol)
        if mu < hopf:
            x_u = brentq(lambda t, v=v: H(t) - v, 0.0, 0.5, xtol=1e-14)
            assert float(hz.position(mu, -1.0, hopf, fold, c, form)) == pytest.approx(x_u, abs=tol)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_curve_and_roots_match_scipy(seed):
    c = _coefficients(seed)
    H = _curve_by_quad(c)
    for x in (0.0, 0.2, 0.5, 0.9, 1.6):
        assert float(hz.curve(jnp.asarray(x), c)) == pytest.approx(H(x), abs=1e-9)
    assert H(0.0) == pytest.approx(1.0, abs=1e-12)
    _check_roots(H, c, (14.3, 15.5, 17.2, 17.95, 19.0))
    hopf, fold = 18.0, 14.0
    # no limit cycle below the fold; no unstable one above the Hopf point
    assert np.isnan(float(hz.position(13.9, 1.0, hopf, fold, c)))
    assert np.isnan(float(hz.position(18.1, -1.0, hopf, fold, c)))


def test_without_discrepancy_the_curve_is_the_normal_form():
    c = jnp.zeros(hz.N_BASIS)
    a2 = 2.0 * np.sqrt(18.0 - 14.0)
    mu = np.array([14.5, 16.0, 17.5])
    for sign in (1.0, -1.0):
        r = np.sqrt(a2 * np.asarray(hz.position(jnp.asarray(mu), sign, 18.0, 14.0, c)))
        np.testing.assert_allclose(r, np.asarray(normal_form.lco_radius(mu, 18.0, a2, sign)),
                                   rtol=1e-10)


def test_derivatives_of_a_root_match_finite_differences():
    c = _coefficients(4)

    @jax.jit
    def x_of(c, hopf=18.0):
        return hz.position(15.0, -1.0, hopf, 14.0, c) + hz.position(16.0, 1.0, hopf, 14.0, c)

    grad = np.asarray(jax.grad(x_of)(c))
    h = 1e-6
    for k in range(hz.N_BASIS):
        d = np.zeros(hz.N_BASIS)
        d[k] = h
        fd = (float(x_of(c + d)) - float(x_of(c - d))) / (2 * h)
        assert grad[k] == pytest.approx(fd, rel=1e-5, abs=1e-8)
    g_hopf = float(jax.grad(x_of, argnums=1)(c, 18.0))
    fd = (float(x_of(c, 18.0 + h)) - float(x_of(c, 18.0 - h))) / (2 * h)
    assert g_hopf == pytest.approx(fd, rel=1e-5)


def _log_joint(unfolding, extra=None):
    """log p of the collapsed model on a small data set, at fixed values of its sites.

    ``numpyro.factor`` is a sample site of a unit distribution whose log_prob is the
    factor, so the sum over sample sites is the log joint.
    """
    from numpyro.handlers import substitute, trace

    from bayeshopf.features.frame import PlanarFrame
    from bayeshopf.model import collapsed as cm

    spec = cm.CollapsedSpec("subcritical", PlanarFrame(np.zeros(2), np.eye(2)), 2, 16.0,
                            2.0, 15.0, 16.5, 1.0, cm.hidden_layer(4), unfolding=unfolding)
    rng = np.random.default_rng(5)
    mu = jnp.array([15.0, 15.6, 16.5, 17.0, 15.4, 16.5])
    sign = jnp.array([1.0, 1.0, 1.0, 1.0, -1.0, -1.0])
    y = jnp.asarray(rng.standard_normal((6, 2, 5)) * 0.3)
    se = jnp.full((6, 2, 5), 0.02)
    values = {"gap_fold": 0.4, "gap_hopf": 0.7, "tau_mu": 0.2, "tau_shape": 0.1,
              "sigma": jnp.array([0.01, 0.02]), "sigma_rel": 0.01, **(extra or {})}
    tr = trace(substitute(cm.collapsed_model, data=values)).get_trace(spec, mu, sign, y, se)
    return sum(float(jnp.sum(s["fn"].log_prob(s["value"]))) for s in tr.values()
               if s["type"] == "sample"), tr


def test_model_with_a_flat_discrepancy_is_the_linear_unfolding():
    """log p of the model at ``z_h = 0`` is the linear model's plus the new sites' priors."""
    import numpyro.distributions as dist

    lin, tr_lin = _log_joint("linear")
    hor, tr_hor = _log_joint("horizontal", {"eta_h": 0.3, "ell_h": 0.6,
                                            "z_h": jnp.zeros(hz.N_BASIS)})
    priors = (float(dist.HalfNormal(hz.ETA_PRIOR).log_prob(0.3))
              + float(dist.LogNormal(np.log(hz.LENGTH_PRIOR[0]), hz.LENGTH_PRIOR[1])
                      .log_prob(0.6))
              + float(jnp.sum(dist.Normal(0.0, 1.0).log_prob(jnp.zeros(hz.N_BASIS)))))
    assert hor == pytest.approx(lin + priors, rel=1e-10)
    assert float(tr_hor["a2"]["value"]) == pytest.approx(float(tr_lin["a2"]["value"]), rel=1e-12)


# the Gaussian process's fit compiles a larger program than the window's: slow
@pytest.mark.parametrize(("unfolding", "site"), [
    ("window", "depth_h"), pytest.param("horizontal", "eta_h", marks=pytest.mark.slow)])
def test_a_fit_with_it_predicts_saves_and_loads(tmp_path, unfolding, site):
    """The front door with a horizontal unfolding: diagram, predictions, a saved fit."""
    from dataclasses import replace

    import bayeshopf as bh
    from bayeshopf.data.synthetic import demo_system

    rs, truth = demo_system(seed=0, fast=True)
    # the wiring, not the statistics: one short chain of NUTS, without the discrepancy
    settings = replace(bh.Settings.fast(), unfolding=unfolding, num_chains=1,
                       num_warmup=100, num_samples=100, max_samples=100, inference="nuts",
                       discrepancy=False, nn_width=16)
    fit = bh.fit(rs, settings, seed=0, progress=False)
    assert fit.interval(site) is not None and fit.interval("w_unfold") is None
    d = fit.diagram()
    assert d.mu_fold.lo < d.mu_fold.hi < d.mu0.lo < d.mu0.hi
    assert np.isfinite(d.fold_amplitude.lo)
    a = fit.predict([15.5, 16.0], branch="unstable")
    assert np.all(np.isfinite(a.amplitude.values))
    fit.save(tmp_path / "fit", figures=False)
    b = bh.load_fit(tmp_path / "fit").predict([15.5, 16.0], branch="unstable")
    np.testing.assert_allclose(b.amplitude.values, a.amplitude.values, rtol=1e-9)
    if unfolding == "window":
        # the demo's fold is the normal form's: its window stays within the prior
        window = fit.diagnostics.details["fit"]["fold_window"]
        assert window["depth_in_prior_sds"] < window["limit_in_prior_sds"]
        assert not [w for w in fit.diagnostics.warnings if "fold's window" in w]


# ------------------------------------------------------------ the window at the fold


def _window_by_quad(depth, width):
    """``H`` with ``e(t) = −A exp(−(t − ½)²/2λ²)`` by SciPy's quadrature, written apart."""
    def e(t):
        return -depth * np.exp(-0.5 * ((t - 0.5) / width) ** 2)

    norm = quad(lambda t: t * np.exp(e(t)), 0.0, 0.5, epsabs=1e-14)[0]
    return lambda x: quad(lambda t: (x - t) * np.exp(e(t)), 0.5, x, epsabs=1e-14,
                          points=[0.5])[0] / norm


@pytest.mark.parametrize(("depth", "width"),
                         [(3.0, 0.1), (-1.5, 0.25), (1.0, 0.07), (12.0, 0.27), (14.0, 0.4)])
def test_window_curve_and_roots_match_scipy(depth, width):
    """Deep windows too: a fold far flatter than the normal form's, where the
    stable root's bracket must not grow with ``e^{A}``."""
    c = jnp.array([depth, width])
    H = _window_by_quad(depth, width)
    for x in (0.0, 0.3, 0.45, 0.5, 0.62, 1.3):
        assert float(hz.curve(jnp.asarray(x), c, "window")) == pytest.approx(H(x), abs=1e-9)
    # a deep window spans e^{-A}: the Gauss–Legendre sums keep about 1e-7 in x
    _check_roots(H, c, (14.02, 14.3, 15.5, 17.95, 19.0), tol=1e-8 if depth < 10 else 1e-6,
                 form="window")


def test_an_unknown_form_is_refused():
    with pytest.raises(ValueError, match="form: expected one of process, window; got 'gp'"):
        hz.curve(0.3, jnp.array([1.0, 0.2]), "gp")


def test_a_window_beyond_its_prior_is_reported():
    """Two prior SDs of the depth is the limit, either way, with the fold's shape named."""
    from bayeshopf.diagnostics.fit_checks import fold_window_check
    from bayeshopf.diagnostics.summaries import Interval

    width = Interval(0.25, 0.19, 0.32, 0.9)
    record, line = fold_window_check(Interval(6.5, 4.3, 9.4, 0.9), width)
    assert record["depth_in_prior_sds"] == pytest.approx(6.5 / hz.WINDOW_DEPTH_PRIOR)
    assert "flatter" in line and "6.5 [4.3, 9.4]" in line
    assert "sharper" in fold_window_check(Interval(-4.5, -6.0, -3.0, 0.9), width)[1]
    assert fold_window_check(Interval(3.9, 1.0, 6.0, 0.9), width)[1] is None
    assert fold_window_check(Interval(-3.9, -6.0, -1.0, 0.9), width)[1] is None


def test_a_deep_window_flattens_the_fold():
    """A flatter fold: just above it the branches lie further apart than the normal form's."""
    v = 0.01                                               # 1% of the gap above the fold
    nf = 0.5 * np.sqrt(v)                                  # |x − ½| of 4(x − ½)² = v
    flat = float(hz.position(14.04, 1.0, 18.0, 14.0, jnp.array([3.0, 0.1]), "window")) - 0.5
    sharp = float(hz.position(14.04, 1.0, 18.0, 14.0, jnp.array([-2.0, 0.1]), "window")) - 0.5
    assert sharp < nf < flat
    assert flat > 2 * nf


def test_window_derivatives_match_finite_differences():
    @jax.jit
    def x_of(c):
        return (hz.position(14.5, -1.0, 18.0, 14.0, c, "window")
                + hz.position(16.0, 1.0, 18.0, 14.0, c, "window"))

    c = jnp.array([1.2, 0.12])
    grad = np.asarray(jax.grad(x_of)(c))
    h = 1e-6
    for k in range(2):
        d = np.zeros(2)
        d[k] = h
        fd = (float(x_of(c + d)) - float(x_of(c - d))) / (2 * h)
        assert grad[k] == pytest.approx(fd, rel=1e-5, abs=1e-8)


def test_model_with_a_window_of_no_depth_is_the_linear_unfolding():
    """log p at ``A = 0`` is the linear model's plus the window's priors."""
    import numpyro.distributions as dist

    lin, _ = _log_joint("linear")
    win, _ = _log_joint("window", {"depth_h": 0.0, "width_h": 0.2})
    priors = (float(dist.Normal(0.0, hz.WINDOW_DEPTH_PRIOR).log_prob(0.0))
              + float(dist.LogNormal(np.log(hz.WINDOW_WIDTH_PRIOR[0]), hz.WINDOW_WIDTH_PRIOR[1])
                      .log_prob(0.2)))
    assert win == pytest.approx(lin + priors, rel=1e-10)
