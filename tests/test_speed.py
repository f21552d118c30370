"""The oscillation speed Ω: phase ODE vs scipy, initial phase, planted and measured frequencies."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

from bayeshopf.features.frame import PlanarFrame
from bayeshopf.model import speed as sp
from bayeshopf.model.coordinate_map import MLPParams, linear_map, lower_triangular
from bayeshopf.model.hybrid import HopfParams, ModelSpec, orbit_at

CBC_DIR = (Path(__file__).parents[1] / ".." / "shared" / "data" / "flutter_cbc").resolve()


def _random_mlp(key, shapes, scale=1.0):
    ks = jax.random.split(key, 2 * len(shapes))
    W = tuple(scale * jax.random.normal(ks[2 * i], s) for i, s in enumerate(shapes))
    b = tuple(scale * jax.random.normal(ks[2 * i + 1], (s[1],)) for i, s in enumerate(shapes))
    return MLPParams(W, b)


def _speed(n_h=2):
    spec = sp.SpeedSpec(n_h=n_h, nn_width=6, nn_depth=1, omega_ref=15.0, rtol=1e-10, atol=1e-10)
    p = sp.SpeedParams(jnp.asarray(15.0), _random_mlp(jax.random.PRNGKey(1), spec.nn_shapes),
                       jnp.asarray(1.5))
    return spec, p


def test_phase_ode_matches_solve_ivp():
    """θ̇ = Ω(r, θ, μ) with a θ-dependent speed: diffrax Tsit5 vs scipy DOP853, and the period."""
    spec, p = _speed()
    r, mt = 0.8, 0.3
    t = jnp.linspace(0.0, 3.0, 301)
    th = np.asarray(sp.integrate_phase(p, r, mt, 0.4, t, spec))
    om = jax.jit(lambda x: sp.speed(p, r, x, mt, spec))
    ref = solve_ivp(lambda s, y: [float(om(y[0]))], (0.0, 3.0), [0.4], method="DOP853",
                    t_eval=np.asarray(t), rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(th, ref.y[0], atol=1e-7)
    assert np.ptp(np.asarray(om(jnp.linspace(0, 2 * np.pi, 100)))) > 0.5  # not constant
    T_quad = float(sp.period(p, r, mt, spec))
    T_ref = quad(lambda x: 1.0 / float(om(x)), 0.0, 2 * np.pi, epsabs=1e-13, epsrel=1e-13)[0]
    assert T_quad == pytest.approx(T_ref, rel=1e-10)


def _map():
    spec = ModelSpec(criticality="subcritical", frame=PlanarFrame(np.zeros(2), np.eye(2)),
                     n_h=4, mu_centre=16.5, mu_span=1.5, mu_min=15.0, mu_unstable_max=17.4,
                     orbit_scale=1.0)
    params = HopfParams(
        mu0=jnp.asarray(18.0), a2=jnp.asarray(3.4),
        T_L=linear_map(jnp.array([0.8, 0.5]), jnp.asarray(0.3), jnp.array([0.05, -0.02])),
        T_L1=lower_triangular(jnp.array([0.05, 0.02]), jnp.asarray(0.01)),
        T_s=jnp.array([0.03, -0.02]),
        nn=_random_mlp(jax.random.PRNGKey(0), spec.nn_shapes), nn_scale=jnp.asarray(0.08),
    )
    return spec, params


@pytest.mark.parametrize("mu,sign", [(16.0, 1.0), (17.0, -1.0), (15.5, -1.0)])
@pytest.mark.parametrize("theta0", [0.0, 2.0, -2.5, np.pi - 1e-4, -np.pi + 1e-4, 3.1])
def test_initial_phase_recovers_planted(mu, sign, theta0):
    """eq. zp_ang: the root find returns the planted phase, across ±π, on both branches."""
    spec, params = _map()
    w1 = orbit_at(params, mu, sign, jnp.asarray(theta0), spec)
    for scale in (1.0, 1.15):  # on the orbit, and a point off it along the same ray
        got = float(sp.initial_phase(params, mu, sign, scale * w1, spec))
        assert abs(np.angle(np.exp(1j * (got - theta0)))) < 1e-9, (got, theta0, scale)


def test_mean_frequency_likelihood_is_the_documented_normal():
    """Site ``f``: log N(f_i; f̂_i, √(s_i² + (τ f̂_i)²)) with f̂_i = 1/∮dθ/Ω (scipy reference)."""
    from numpyro import handlers
    from scipy.stats import norm

    from bayeshopf.inference.speed import speed_model
    from bayeshopf.model.hybrid import params_from_sites

    mspec, mp = _map()
    spec, p = _speed()
    map_sites = {"mu0": mp.mu0, "a2": mp.a2, "T_L_diag": jnp.array([0.8, 0.5]),
                 "T_L_21": jnp.asarray(0.3), "T_L_mu": jnp.array([0.05, -0.02]),
                 "T_L1": jnp.array([0.05, 0.02, 0.01]), "T_s": mp.T_s, "nn_scale": mp.nn_scale}
    for i in range(len(mspec.nn_shapes)):
        map_sites[f"nn_W{i}"], map_sites[f"nn_b{i}"] = mp.nn.weights[i], mp.nn.biases[i]
    speed_sites = {"omega0": p.omega0, "om_scale": p.nn_scale, "tau_f": jnp.asarray(0.004)}
    for i in range(len(spec.nn_shapes)):
        speed_sites[f"om_W{i}"], speed_sites[f"om_b{i}"] = p.nn.weights[i], p.nn.biases[i]
    mu, sign = jnp.array([16.0, 17.0]), jnp.array([1.0, -1.0])
    f_obs, f_se = jnp.array([2.40, 2.47]), jnp.array([1e-3, 2e-3])
    t = jnp.tile(jnp.linspace(0.0, 1.0, 11), (2, 1))
    model = handlers.substitute(handlers.seed(speed_model, 0), data=speed_sites)
    tr = handlers.trace(model).get_trace(
        spec, mspec, map_sites, mu, sign, jnp.zeros(2), t, jnp.ones(2), f_se, f_obs=f_obs)
    got = float(tr["f"]["fn"].log_prob(tr["f"]["value"]).sum())
    params = params_from_sites(map_sites, mspec)
    f_hat = np.array([float(sp.frequency_hz(p, params, m, s, spec, mspec))
                      for m, s in zip(mu, sign, strict=True)])
    sd = np.sqrt(np.asarray(f_se) ** 2 + (0.004 * f_hat) ** 2)
    assert got == pytest.approx(float(norm.logpdf(np.asarray(f_obs), f_hat, sd).sum()), rel=1e-10)


def test_measured_frequency_and_its_standard_error():
    """A 2.45 Hz rotation with noise: frequency to 1e-4 Hz, standard error from the segments."""
    from bayeshopf.inference.speed import measured_frequency, measured_frequency_se

    t = np.arange(0, 20, 1 / 500)
    rng = np.random.default_rng(0)
    ph = 2 * np.pi * 2.45 * t + 0.3 * np.sin(2 * np.pi * 0.05 * t)  # slow wander
    w = np.stack([np.cos(ph), np.sin(ph)], -1) + 0.01 * rng.standard_normal((t.size, 2))
    # reference: the least-squares slope of the planted phase itself
    assert measured_frequency(w, t) == pytest.approx(np.polyfit(t, ph, 1)[0] / (2 * np.pi),
                                                     abs=1e-4)
    se = measured_frequency_se(w, t)
    f_seg = [measured_frequency(w[k], t[k]) for k in np.array_split(np.arange(t.size), 5)]
    assert se == pytest.approx(np.std(f_seg, ddof=1) / np.sqrt(5))
    assert 1e-4 < se < 1e-2


# -- fitted: planted speed on synthetic data, and the wind-tunnel recordings ------------------


@pytest.fixture(scope="module")
def synthetic():
    from bayeshopf.data.synthetic import demo_system
    from bayeshopf.inference.speed import fit_speed
    from bayeshopf.pipeline import FitSettings, fit

    rs, truth = demo_system(seed=0)
    hf = fit(rs, "subcritical", seed=0, settings=FitSettings.fast(), progress=False)
    return rs, truth, fit_speed(hf, rs, seed=0, progress=False), hf


@pytest.mark.xfail(strict=True, reason=(
    "regression from the map's second-order term L2 (issue 3): at the stable 15.3, next to the "
    "fold, the curve band [2.6021, 2.6059] Hz misses the planted 2.6068 by 0.035%; the measured "
    "mean frequency there is 2.6068 ± 0.0014, and the time-series likelihood pulls the curve "
    "0.11% below it through the map's orbit-shape error, which L2 changed"))
@pytest.mark.slow  # legacy speed stage (--core legacy --speed)
def test_planted_frequency_inside_band(synthetic):
    """The 90% frequency band covers the planted ω(r(μ))/2π at training and held-out μ.

    Stable branch: every band covers the truth, up to two Monte Carlo standard
    errors of its end points (quantiles of a few hundred draws; one planted
    value sits 4e-6 Hz outside an edge whose Monte Carlo error is ~1e-4 Hz).
    Unstable branch (small orbits, near the Hopf point; map fitted with the
    fast settings): the bands are biased by up to about 0.1%, so only the
    relative error is bounded there.
    """
    rs, truth, sf, _ = synthetic
    cases = [(r.mu, r.branch) for r in rs] + [(16.0, "stable"), (19.0, "stable"),
                                               (16.0, "unstable")]
    missed, rel = [], []
    for mu, branch in cases:
        x = sf.frequency(mu, branch)[:, 0]
        x = x[np.isfinite(x)]
        iv = sf.frequency_interval(mu, branch)
        f = float(truth.frequency_hz(mu, branch))
        # Monte Carlo standard error of a 5% quantile: √(p(1−p)/n) / density there,
        # the density from the draws in a window about the quantile
        win = 0.1 * (iv.hi - iv.lo)
        dens = np.mean(np.abs(x - iv.lo) < win) / (2 * win)
        mc = np.sqrt(0.05 * 0.95 / x.size) / dens
        print(f"{branch:8s} mu={mu:5.2f}  true {f:.4f} Hz  band [{iv.lo:.4f}, {iv.hi:.4f}]"
              f"  inside: {iv.contains(f)}  (Monte Carlo error of the edges {mc:.1e} Hz)")
        rel.append(abs(iv.median / f - 1.0))
        if branch == "stable" and not (iv.lo - 2 * mc <= f <= iv.hi + 2 * mc):
            missed.append((mu, branch, f, iv, mc))
    assert not missed, missed
    assert max(rel) < 3e-3, rel


@pytest.mark.slow  # legacy speed stage (--core legacy --speed)
def test_training_frequencies_inside_predictive_band(synthetic):
    """Every training recording's measured frequency lies in its 90% predictive band (curve + τ)."""
    rs, _, sf, _ = synthetic
    assert "tau_f" in sf.samples and np.all(np.asarray(sf.samples["tau_f"]) >= 0)
    for i, r in enumerate(rs):
        pv = sf.frequency_interval(r.mu, r.branch, predictive=True)
        cv = sf.frequency_interval(r.mu, r.branch)
        tol = 1e-4 * cv.median  # the two bands' quantiles come from different draws
        assert pv.lo <= cv.lo + tol and cv.hi <= pv.hi + tol  # the predictive band is the wider
        assert pv.contains(abs(sf.data.measured_hz[i])), (r.name, pv, sf.data.measured_hz[i])


@pytest.mark.slow  # legacy speed stage (--core legacy --speed)
def test_time_series_shapes_and_units(synthetic):
    rs, _, sf, _ = synthetic
    r = rs[0]
    z = r.planar(rs.planar)
    ts = sf.time_series(r.mu, r.branch, r.t[:50] - r.t[0], initial_point=z[0])
    assert ts.shape == (sf.n_draws, 50, 2)
    med = np.median(ts, axis=0)
    # physical units: the predicted heave stays on the measured scale
    assert np.ptp(med[:, 0]) == pytest.approx(np.ptp(z[:50, 0]), rel=0.2)
    with pytest.raises(ValueError, match="exactly one"):
        sf.time_series(r.mu, r.branch, r.t[:5])


@pytest.mark.slow  # legacy speed stage (--core legacy --speed)
def test_predict_cli_reports_frequency(synthetic, tmp_path, capsys):
    """`bayeshopf predict --json` adds the frequency band when the fit folder has speed.npz."""
    import json

    from bayeshopf import report
    from bayeshopf.cli.main import main
    from bayeshopf.inference.speed import save_speed

    rs, truth, sf, hf = synthetic
    out = tmp_path / "fit"
    report.save_fit(hf, out)
    capsys.readouterr()
    assert main(["predict", str(out), "--mu", "16.0", "--json"]) == 0
    assert "frequency_hz" not in json.loads(capsys.readouterr().out)
    save_speed(sf, out)
    assert main(["predict", str(out), "--mu", "16.0", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)["frequency_hz"]
    iv = sf.frequency_interval(16.0, "stable")
    assert got["median"] == pytest.approx(iv.median, rel=1e-9)
    assert got["ci90"] == pytest.approx([iv.lo, iv.hi], rel=1e-9)


@pytest.fixture(scope="module")
def wind_tunnel():
    if not CBC_DIR.is_dir():
        pytest.skip(f"flutter CBC recordings not found at {CBC_DIR}")
    from bayeshopf.data import load_recordings
    from bayeshopf.inference.speed import fit_speed
    from bayeshopf.pipeline import FitSettings, fit

    rs = load_recordings(CBC_DIR)
    hf = fit(rs, "subcritical", seed=0, settings=FitSettings.fast(), progress=False)
    return rs, hf, fit_speed(hf, rs, seed=0, progress=False)


@pytest.mark.slow
def test_wind_tunnel_frequency_and_phase(wind_tunnel):
    """Measured frequencies against their 90% bands; phase error after 10 periods.

    The phase error is predicted from each record's first point on the curve.
    """
    rs, hf, sf = wind_tunnel
    err = sf.phase_error(rs, n_periods=10.0)
    missed = []
    for i, r in enumerate(rs):
        iv = sf.frequency_interval(r.mu, r.branch, predictive=True)
        cv = sf.frequency_interval(r.mu, r.branch)
        f = abs(sf.data.measured_hz[i])
        print(f"{r.name:22s} mu={r.mu:5.2f} measured {f:.4f} Hz "
              f"(features {abs(hf.features.frequency_hz[i]):.4f})  "
              f"curve {cv.median:.4f} [{cv.lo:.4f}, {cv.hi:.4f}]  "
              f"predictive [{iv.lo:.4f}, {iv.hi:.4f}]  phase err {err[i]:.3f} rad")
        if not iv.contains(f):
            missed.append((r.name, f, iv))
    tau = np.quantile(np.asarray(sf.samples["tau_f"]), [0.05, 0.5, 0.95])
    print(f"frequency scatter between recordings tau = {tau[1]:.4f} [{tau[0]:.4f}, {tau[2]:.4f}]")
    # every measured frequency (mean over its whole 20 s record) lies in its 90%
    # predictive band: the curve Ω(r, θ, μ) plus the scatter τ between recordings
    assert not missed, missed
    rel = [abs(sf.frequency_interval(r.mu, r.branch).median / abs(sf.data.measured_hz[i]) - 1)
           for i, r in enumerate(rs)]
    assert max(rel) < 0.01, rel
    assert 0.001 < tau[1] < 0.01, tau
    stable = ~rs.is_unstable
    assert np.all(err[stable] < 0.5), err
    assert np.all(err < 0.7), err


@pytest.mark.slow
def test_flutter3dof_frequencies_against_the_continuation():
    """3-DOF aerofoil, blind: the true 1/T of every training and held-out orbit in its curve band.

    The truth is the period of the Newton-corrected periodic orbit; the phase
    error after 10 periods is bounded on training and on new (held-out) records.
    """
    from bayeshopf.inference.speed import fit_speed
    from bayeshopf.pipeline import fit
    from bayeshopf.simulators.truth import flutter_experiment, held_out_recordings

    rs, truth = flutter_experiment(0)
    hf = fit(rs, "subcritical", seed=0, progress=False)
    sf = fit_speed(hf, rs, seed=0, progress=False)
    missed = []
    for mu, branch in truth.plan + truth.held_out:
        f = 1.0 / truth.diagram.orbit_at(mu, branch).period
        iv = sf.frequency_interval(mu, branch)
        print(f"{branch:8s} {mu:5.2f} true {f:.4f} Hz band [{iv.lo:.4f}, {iv.hi:.4f}]")
        assert abs(iv.median / f - 1) < 1e-3, (mu, branch, f, iv)
        if not iv.contains(f):
            missed.append((mu, branch, f, iv))
    assert not missed, missed
    err = np.concatenate([sf.phase_error(rs), sf.phase_error(held_out_recordings(truth))])
    print("phase errors after 10 periods (rad):", np.round(err, 3))
    assert np.all(err < 1.0), err


@pytest.mark.slow  # legacy speed stage (--core legacy --speed)
def test_plots_draw(synthetic, tmp_path):
    """Fig. ts_exp with bands and frequency against μ are drawn from the fit's records."""
    from bayeshopf.plotting import save_figure
    from bayeshopf.plotting.timeseries import plot_frequency, plot_time_series

    rs, truth, sf, _ = synthetic
    bands = sf.time_series_bands(rs.subset([0, 4]), n_periods=3.0)
    assert all(np.all(b.lo <= b.hi) for b in bands)
    fig = plot_time_series(bands, mu_label="airspeed", mu_units="m/s")
    mus = np.linspace(15.2, 19.5, 12)
    fb = [sf.frequency_band(mus, "stable"), sf.frequency_band(mus[mus < 18], "unstable")]
    meas = [(r.mu, sf.data.measured_hz[i], r.branch) for i, r in enumerate(rs)]
    pb = [sf.frequency_band(mus, "stable", predictive=True)]
    tol = 1e-4 * np.nanmax(fb[0].median)
    assert np.all(pb[0].lo <= fb[0].lo + tol) and np.all(pb[0].hi >= fb[0].hi - tol)
    fig2 = plot_frequency(fb, meas, predictive=pb, mu_label="airspeed", mu_units="m/s")
    for f, name in ((fig, "ts.png"), (fig2, "freq.png")):
        assert save_figure(f, tmp_path / name).stat().st_size > 1000
