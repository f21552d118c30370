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


# -- fitted: planted speed on synthetic data, and the wind-tunnel recordings ------------------


@pytest.fixture(scope="module")
def synthetic():
    from bayeshopf.data.synthetic import demo_system
    from bayeshopf.inference.speed import fit_speed
    from bayeshopf.pipeline import FitSettings, fit

    rs, truth = demo_system(seed=0)
    hf = fit(rs, "subcritical", seed=0, settings=FitSettings.fast(), progress=False)
    return rs, truth, fit_speed(hf, rs, seed=0, progress=False), hf


def test_planted_frequency_inside_band(synthetic):
    """The 90% frequency band covers the planted ω(r(μ))/2π at training and held-out μ.

    Stable branch: every band covers the truth. Unstable branch (small orbits,
    near the Hopf point; map fitted with the fast settings): the bands are
    biased by up to about 0.1%, so only the relative error is bounded there.
    """
    rs, truth, sf, _ = synthetic
    cases = [(r.mu, r.branch) for r in rs] + [(16.0, "stable"), (19.0, "stable"),
                                               (16.0, "unstable")]
    missed, rel = [], []
    for mu, branch in cases:
        iv = sf.frequency_interval(mu, branch)
        f = float(truth.frequency_hz(mu, branch))
        print(f"{branch:8s} mu={mu:5.2f}  true {f:.4f} Hz  band [{iv.lo:.4f}, {iv.hi:.4f}]"
              f"  inside: {iv.contains(f)}")
        rel.append(abs(iv.median / f - 1.0))
        if branch == "stable" and not iv.contains(f):
            missed.append((mu, branch, f, iv))
    assert not missed, missed
    assert max(rel) < 3e-3, rel


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

    The phase error is predicted from each record's first point (curve; the
    recording offsets are off by default, so both printed errors agree).
    """
    rs, hf, sf = wind_tunnel
    err = sf.phase_error(rs, n_periods=10.0, fitted_offsets=True)
    err_curve = sf.phase_error(rs, n_periods=10.0)
    missed = []
    for i, r in enumerate(rs):
        iv = sf.frequency_interval(r.mu, r.branch, predictive=True)
        cv = sf.frequency_interval(r.mu, r.branch)
        f = abs(sf.data.measured_hz[i])
        print(f"{r.name:22s} mu={r.mu:5.2f} measured {f:.4f} Hz "
              f"(features {abs(hf.features.frequency_hz[i]):.4f})  "
              f"curve {cv.median:.4f} [{cv.lo:.4f}, {cv.hi:.4f}]  "
              f"predictive [{iv.lo:.4f}, {iv.hi:.4f}]  phase err {err[i]:.3f} rad "
              f"(curve only {err_curve[i]:.3f})")
        if not iv.contains(f):
            missed.append((r.name, f, iv))
    # Only 3 of the 7 measured frequencies (mean over the whole 20 s record) are
    # inside their 90% curve bands (about ±0.2%): the curve cannot follow the
    # unstable 16.5 m/s record (1.2% faster than the stable one at the same μ),
    # and three others miss by 0.01-0.3%. The error is bounded instead:
    print(f"{len(rs) - len(missed)} of {len(rs)} measured frequencies inside the 90% band")
    rel = [abs(sf.frequency_interval(r.mu, r.branch).median / abs(sf.data.measured_hz[i]) - 1)
           for i, r in enumerate(rs)]
    assert max(rel) < 0.015, rel
    assert len(missed) <= 4, missed
    stable = ~rs.is_unstable
    assert np.all(err[stable] < 0.5), err
    assert np.all(err < 0.7), err


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
    fig2 = plot_frequency(fb, meas, mu_label="airspeed", mu_units="m/s")
    for f, name in ((fig, "ts.png"), (fig2, "freq.png")):
        assert save_figure(f, tmp_path / name).stat().st_size > 1000
