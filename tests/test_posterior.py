"""The collapsed core end to end on planted systems (small problems; statistics in benchmarks)."""

import json
from dataclasses import replace

import numpy as np
import pytest

from bayeshopf.data.recording import RecordingSet
from bayeshopf.data.synthetic import demo_system
from bayeshopf.features.harmonics import reconstruct
from bayeshopf.inference.collapsed import CollapsedSettings
from bayeshopf.posterior import fit_hybrid, orbit_error_parts

#: The model without the discrepancy, under NUTS (16 hidden units): the layers these
#: tests check one at a time; ``planted_discrepancy`` adds the discrepancy, and the
#: default model (the discrepancy at infinite width, importance sampling) is fitted
#: by the tests of the network at infinite width, of the CLI and of the demo.
SETTINGS = replace(CollapsedSettings.fast(), num_chains=2, inference="nuts", discrepancy=False,
                   nn_width=16)


@pytest.fixture(scope="module")
def planted():
    rs, truth = demo_system(seed=11, fast=True)
    return fit_hybrid(rs, "subcritical", seed=0, settings=SETTINGS, progress=False), rs, truth


@pytest.fixture(scope="module")
def planted_discrepancy():
    """The same recordings fitted with the model discrepancy."""
    rs, truth = demo_system(seed=11, fast=True)
    return (fit_hybrid(rs, "subcritical", seed=0, settings=replace(SETTINGS, discrepancy=True),
                       progress=False), rs, truth)


def test_planted_hopf_and_fold_inside_their_intervals(planted):
    post, _, truth = planted
    assert post.interval("mu0").contains(truth.mu0)
    assert post.interval("mu_fold").contains(truth.mu_fold)
    # the data pin μ0 to a fraction of the span of the recordings (4.2)
    assert post.interval("mu0").width < 0.5


def test_planted_orbits_fitted_and_diagnostics_reported(planted):
    post, rs, truth = planted
    d = post.diagnostics
    assert d["map"]["converged"] and d["map"]["grad_norm"] < 1e-4
    assert set(d["posterior"]["sites"]) >= {"mu0", "a2", "mu_fold"}
    # NUTS started from the MAP's Laplace covariance, and its cost is reported
    assert d["posterior"]["mass_matrix_start"] == "laplace"
    assert 1 <= d["posterior"]["leapfrog_steps_draws"] <= 2**SETTINGS.max_tree_depth
    assert post.samples["mu0"].shape == (SETTINGS.num_chains * SETTINGS.num_samples,)
    for e in d["fit"]["orbit_error"]:
        assert e["relative"] < 0.03, e
    # the posterior-median orbit against the planted orbit (not the noisy data)
    for rec in rs:
        pred = np.median(post.orbits(rec.mu, rec.branch), axis=0)
        true = truth.orbit(rec.mu, rec.branch, n_points=pred.shape[0])
        # phases differ: compare as point clouds (distance to the nearest true point)
        dist = np.min(np.linalg.norm(pred[:, None] - true[None], axis=-1), axis=1)
        size = np.sqrt(np.mean(np.sum((true - true.mean(0)) ** 2, -1)))
        assert np.sqrt(np.mean(dist**2)) / size < 0.02


def test_planted_diagram_band_holds_the_true_branches(planted):
    post, _, truth = planted
    mu = np.linspace(15.4, 17.9, 12)
    for branch, band in (("stable", post.diagram(mu).stable),
                         ("unstable", post.diagram(mu).unstable)):
        true = truth.amplitude(mu, branch)
        lo, hi = band.quantiles[0], band.quantiles[4]
        assert np.all((lo <= true) & (true <= hi)), (branch, lo, true, hi)


def test_a_fit_that_does_not_fit_says_so():
    """Recordings whose μ labels are scrambled: the map cannot follow them, diagnostics warn.

    The model without the discrepancy: with it, this set is fitted without a warning
    (``docs/changelog.md``, 2026-11-29)."""
    rs, _ = demo_system(seed=12, fast=True)
    mus = [15.3, 19.5, 16.7, 18.1, 16.0, 17.4]       # stable sizes no longer grow with μ
    recs = tuple(replace(r, mu=m) if r.branch == "stable" else r
                 for r, m in zip(rs, mus, strict=False))
    bad = RecordingSet(recs, rs.planar, rs.mu_label, rs.mu_units)
    post = fit_hybrid(bad, "subcritical", seed=0, settings=replace(SETTINGS, discrepancy=False),
                      progress=False)
    assert any(w.startswith("fit:") for w in post.diagnostics["warnings"])


def test_planted_frequency_curve_inside_its_band_and_recordings_in_theirs(planted):
    """Ω(r, μ) against the planted ω0 (1 + κ r²): the curve band holds the truth."""
    post, _, truth = planted
    for branch in ("stable", "unstable"):
        lo_mu, hi_mu = (post.features.mu[post.features.unstable == (branch == "unstable")]
                        .min(), post.features.mu.max())
        mu = np.linspace(lo_mu, hi_mu, 8)
        band = post.frequency_band(mu, branch)
        true = truth.frequency_hz(mu, branch)
        ok = np.isfinite(true)
        assert np.all((band.lo[ok] <= true[ok]) & (true[ok] <= band.hi[ok])), (branch, band, true)
        # and the band is narrow against the frequency's change over the branch
        assert np.nanmax(band.hi - band.lo) < 0.5 * (np.nanmax(true) - np.nanmin(true))
    checks = post.diagnostics["fit"]["frequency"]
    assert sum(c["inside_ci90"] for c in checks) >= len(checks) - 1


def test_predicted_time_series_follows_the_recording(planted):
    """Started at the recording's phase, the median time series stays on the measured one."""
    post, rs, _ = planted
    bands = post.time_series_bands(rs, n_periods=3.0)
    assert len(bands) == len(rs)
    for b in bands:
        scale = np.ptp(b.measured)
        err = np.sqrt(np.mean((b.median - b.measured) ** 2)) / scale
        assert err < 0.05, (b.name, err)
        # the curve band (no measurement noise) is narrow against the oscillation
        assert np.max(b.hi - b.lo) < 0.1 * scale, b.name


def test_new_measurement_band_widens_away_from_the_recordings_only(planted, tmp_path):
    """The model error away from the data: nil at a training μ, wide beyond the last recording,
    and the same band from the saved fit (``bayeshopf predict --predictive``)."""
    from bayeshopf import fit_folder

    post, _, _ = planted
    off = replace(post, settings=replace(post.settings, extrapolation=False))
    f = post.features
    i = int(np.argmax(np.where(f.unstable, -np.inf, f.mu)))   # the stable recording of largest μ
    q = [0.05, 0.5, 0.95]
    at = np.quantile(post.amplitude([f.mu[i]], "stable", predictive=True)[:, 0], q)
    np.testing.assert_allclose(at, np.quantile(off.amplitude([f.mu[i]], "stable",
                                                             predictive=True)[:, 0], q), rtol=1e-4)
    beyond = [f.mu[i] + 0.5 * post.spec.mu_span]
    # over a grid of μ, each column is that μ's prediction alone (the same draws), so a
    # band over μ is smooth and each μ's marginal exact
    grid = np.linspace(f.mu[i], beyond[0], 5)
    many = post.amplitude(grid, "stable", predictive=True)
    for j, m in enumerate(grid):
        np.testing.assert_allclose(many[:, j], post.amplitude([m], "stable",
                                                              predictive=True)[:, 0], rtol=1e-12)
    on_b = np.quantile(post.amplitude(beyond, "stable", predictive=True)[:, 0], q)
    off_b = np.quantile(off.amplitude(beyond, "stable", predictive=True)[:, 0], q)
    assert on_b[2] - on_b[0] > 3 * (off_b[2] - off_b[0]), (on_b, off_b)
    assert on_b[1] == pytest.approx(off_b[1], rel=0.02)          # wider, not shifted
    fit_folder.save_hybrid(post, tmp_path / "fit")
    saved = fit_folder.load_fit(tmp_path / "fit").predict(beyond[0], "stable", predictive=True)
    np.testing.assert_allclose([saved.lo, saved.median, saved.hi], on_b, rtol=1e-9)
    # a larger prior scale (CollapsedSettings.extrapolation_scale) widens the band away
    # from the data only, and a saved fit keeps it
    wide = replace(post, settings=replace(post.settings, extrapolation_scale=0.3))
    np.testing.assert_allclose(np.quantile(wide.amplitude([f.mu[i]], "stable",
                                                          predictive=True)[:, 0], q), at,
                               rtol=1e-4)
    wide_b = np.quantile(wide.amplitude(beyond, "stable", predictive=True)[:, 0], q)
    assert wide_b[2] - wide_b[0] > 2 * (on_b[2] - on_b[0]), (wide_b, on_b)
    fit_folder.save_hybrid(wide, tmp_path / "wide")
    saved = fit_folder.load_fit(tmp_path / "wide").predict(beyond[0], "stable", predictive=True)
    np.testing.assert_allclose([saved.lo, saved.median, saved.hi], wide_b, rtol=1e-9)


def test_the_rigs_bifurcations_are_the_moved_points_and_hold_the_planted_ones(
        planted_discrepancy, tmp_path):
    """With the discrepancy the fit's μ0 and fold are the normal form's moved by the
    discrepancy in μ (its draws, from the fit's seed); they hold the planted points, the
    normal form's own stay in the summary, and a saved fit reports the same."""
    import jax

    from bayeshopf import fit_folder
    from bayeshopf.diagnostics.summaries import interval
    from bayeshopf.fit_summary import summary_hybrid
    from bayeshopf.model.bifurcation_shift import shift_draws

    post, _, truth = planted_discrepancy
    f = post.features
    want = shift_draws(post.spec, post.theta, f.mu, np.where(f.unstable, -1.0, 1.0),
                       post.settings.mu_discrepancy, jax.random.PRNGKey(post.seed),
                       floor=post.settings.mu_discrepancy_floor)
    for k in ("mu0", "mu_fold"):
        np.testing.assert_array_equal(post.samples[k + "_rig"], want[k])
        assert post.interval(k) == interval(want[k], 0.9)
        assert k + "_rig" not in post.theta
    assert post.interval("mu0").contains(truth.mu0)
    assert post.interval("mu_fold").contains(truth.mu_fold)
    s = summary_hybrid(post)
    assert s["normal_form_points"]["mu0"] == interval(post.samples["mu0"], 0.9).to_json()
    fit_folder.save_hybrid(post, tmp_path / "fit")
    saved = fit_folder.load_fit(tmp_path / "fit")
    assert saved.posterior.interval("mu_fold") == post.interval("mu_fold")
    assert saved.posterior.settings.mu_discrepancy_floor == post.settings.mu_discrepancy_floor
    # a folder saved before the floor existed drew its rig's points without one
    path = tmp_path / "fit" / fit_folder.SUMMARY
    old = json.loads(path.read_text())
    del old["settings"]["mu_discrepancy_floor"]
    path.write_text(json.dumps(old))
    assert fit_folder.load_fit(tmp_path / "fit").posterior.settings.mu_discrepancy_floor == 0.0


def test_the_rigs_branches_end_at_its_points_and_pass_through_the_recordings(
        planted_discrepancy, tmp_path):
    """Each draw's predicted branches exist exactly between that draw's rig fold and Hopf
    point (not the normal form's); at the training recordings the orbits are the normal
    form's own; the frequency, and a saved fit's prediction, follow the same branches."""
    from dataclasses import replace

    from bayeshopf import fit_folder
    from bayeshopf.predictive import N_BAND_DRAWS

    post, _, _ = planted_discrepancy
    own = replace(post, run=replace(post.run, chains={
        k: v for k, v in post.run.chains.items() if not k.endswith("_rig")}))
    idx = post._draw_indices(N_BAND_DRAWS)
    mu0, fold = (post.samples[k + "_rig"][idx][:, None] for k in ("mu0", "mu_fold"))
    assert np.mean(np.abs(post.samples["mu0_rig"] - post.samples["mu0"]) > 1e-3) > 0.2
    lo, hi = np.quantile(fold, 0.02), np.quantile(mu0, 0.98)
    mu = np.linspace(lo, hi, 41)
    edge = (np.abs(mu[None] - mu0) < 1e-9) | (np.abs(mu[None] - fold) < 1e-9)
    unstable = np.isfinite(post.amplitude(mu, "unstable"))
    np.testing.assert_array_equal(unstable | edge, ((mu[None] > fold) & (mu[None] < mu0)) | edge)
    stable = np.isfinite(post.amplitude(mu, "stable"))
    np.testing.assert_array_equal(stable | edge, (mu[None] > fold) | edge)
    np.testing.assert_array_equal(np.isfinite(post.frequency(mu, "unstable")) | edge,
                                  unstable | edge)
    assert not np.array_equal(unstable, np.isfinite(own.amplitude(mu, "unstable")))
    f = post.features
    for i in range(f.n_recordings):
        b = "unstable" if f.unstable[i] else "stable"
        np.testing.assert_allclose(post.orbit_coefficients([f.mu[i]], b),
                                   own.orbit_coefficients([f.mu[i]], b), rtol=0, atol=1e-12)
    between = float(np.quantile(post.samples["mu0"], 0.9))     # past most of the model's own
    fit_folder.save_hybrid(post, tmp_path / "fit")
    saved = fit_folder.load_fit(tmp_path / "fit")
    p = saved.p_exists(between, "unstable")
    assert p == pytest.approx(np.mean(post.samples["mu0_rig"][idx] > between), abs=1e-12)
    iv = saved.frequency(between, "unstable")
    want = post.frequency([between], "unstable")[:, 0]
    assert iv.median == pytest.approx(np.nanmedian(want), rel=1e-12)


def test_the_discrepancy_is_known_at_the_recordings_and_the_prior_far_away(planted_discrepancy):
    """The discrepancy's smooth part: known at a training orbit given the latent draws (its
    conditional variance a tiny fraction of the prior's), back to the prior's far beyond
    the recordings; over a grid of μ each column is that μ's prediction alone."""
    import jax.numpy as jnp

    from bayeshopf.model import collapsed as cm
    from bayeshopf.model import discrepancy as dm
    from bayeshopf.predictive import discrepancy_moments

    post, _, _ = planted_discrepancy
    f = post.features
    i = int(np.argmax(np.where(f.unstable, -np.inf, f.mu)))   # the stable recording of largest μ
    idx = post._draw_indices(200)
    theta = {k: v[idx] for k, v in post.theta.items()}
    betas = post.run.betas[idx]
    far = f.mu[i] + 3 * post.spec.mu_span
    _, var, _ = discrepancy_moments(post.spec, theta, betas, f, [f.mu[i], far], 1.0)
    smooth = np.flatnonzero(dm.smooth_mask(2 * post.spec.n_harmonics + 1))
    g_sq = {}
    ref = jnp.where(jnp.asarray(f.unstable), -1.0, 1.0)
    for j, m in enumerate((f.mu[i], far)):
        g = np.stack([np.asarray(cm.discrepancy_geometry(
            post.spec, {k: v[d] for k, v in theta.items()}, jnp.asarray([m]), jnp.asarray([1.0]),
            jnp.asarray(f.mu), ref)[0])[0] for d in range(len(idx))])
        g_sq[j] = (np.asarray(theta["eta"])[:, None, None] * g) ** 2
    at = var[:, 0][..., smooth] / g_sq[0][..., smooth]
    beyond = var[:, 1][..., smooth] / g_sq[1][..., smooth]
    ok = np.isfinite(at) & np.isfinite(beyond)
    assert np.median(at[ok]) < 1e-4, np.median(at[ok])
    assert np.median(beyond[ok]) > 0.9, np.median(beyond[ok])
    grid = np.linspace(f.mu[i], f.mu[i] + 0.5 * post.spec.mu_span, 5)
    many = post.amplitude(grid, "stable", predictive=True)
    for j, m in enumerate(grid):
        np.testing.assert_allclose(many[:, j], post.amplitude([m], "stable",
                                                              predictive=True)[:, 0], rtol=1e-12)


def test_fit_auto_compares_both_normal_forms_by_exact_conditional_loo(planted):
    """Both models fitted to the same features; the ELPD alone prefers the subcritical one.

    The planted set holds unstable CBC orbits that the supercritical model (labels
    ignored) must take for its one LCO per μ.
    """
    from bayeshopf.posterior import fit_auto

    post, _, _ = planted
    ll = post.log_likelihood
    n_chains, n_draws = post.run.chains["mu0"].shape
    assert ll.shape == (n_chains, n_draws, post.features.n_recordings)
    assert np.isfinite(ll).all()
    # dispatched early (the CLI's figures run beside it); chain 1's draw 3 is the
    # model's own pointwise log-likelihood at that draw
    from bayeshopf.inference.collapsed import model_arguments
    from bayeshopf.model.collapsed import pointwise_log_likelihood

    again = replace(post)
    again.dispatch()
    assert "_log_likelihood_dispatched" in again.__dict__
    kw = model_arguments(post.spec, post.features)
    th = {k: v[1, 3] for k, v in post.run.chains.items() if k in post.map_point.params}
    one = pointwise_log_likelihood(post.spec, th, kw["mu"], kw["sign"], kw["coeffs"],
                                   kw["coeffs_se"], kw["omega"], kw["omega_se"])
    np.testing.assert_allclose(again.log_likelihood[1, 3], one, rtol=1e-9)
    best, ev = fit_auto(post.features, seed=0, settings=SETTINGS, progress=False)
    assert best.criticality == "subcritical" and ev["preferred"] == "subcritical"
    assert ev["elpd_preferred"] == "subcritical" and ev["z"] > 2
    assert set(ev["loo"]) == {"subcritical", "supercritical"}
    assert ev["branch_labels"] == "used by the subcritical model only"


def test_orbit_error_parts_add_up_and_find_a_planted_harmonic():
    """Parseval's split against the distance sampled over the orbit, and a planted difference."""
    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((2, 2, 9))          # two orbits, K = 4, on two axes
    phi = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    sampled = np.sqrt(np.mean(np.sum((reconstruct(a, phi) - reconstruct(b, phi)) ** 2, -1)))
    parts = orbit_error_parts(a, b)
    assert parts.shape == (5,)
    assert np.sqrt(np.sum(parts**2)) == pytest.approx(sampled, rel=1e-12)
    # a difference in the second harmonic only (a2 of axis 0, b2 of axis 1)
    c = a.copy()
    c[0, 2] += 0.3
    c[1, 6] -= 0.4
    parts = orbit_error_parts(c, a)
    assert parts[2] == pytest.approx(np.sqrt(0.5 * (0.3**2 + 0.4**2)), rel=1e-12)
    assert np.all(np.delete(parts, 2) == 0)


def _with_planted_control(rs, gain, seed):
    """Each recording plus a control channel ``u`` and the planar channels' linear response.

    Written apart from the model: ``u(t) = A cos(ωt + ψ)`` at the recording's own
    frequency (the periodogram's peak of z1, refined by a dense grid), ``A`` and ``ψ``
    drawn per recording, and ``Δz_c(t) = Re(G_c A e^{i(ωt + ψ)})`` with ``G = gain``.
    """
    rng = np.random.default_rng(seed)
    recs = []
    for r in rs:
        t, z1 = r.t, r.channels[rs.planar[0]]
        z = z1 - z1.mean()

        def peak(grid, z=z, t=t):
            power = [abs(np.sum(z * np.exp(-2j * np.pi * f * t))) for f in grid]
            return grid[int(np.argmax(power))]

        coarse = peak(np.linspace(0.5, 10.0, 1901))              # 0.005 Hz apart
        omega = 2 * np.pi * peak(np.linspace(coarse - 0.01, coarse + 0.01, 401))
        U = rng.uniform(0.5, 1.5) * np.exp(1j * rng.uniform(-np.pi, np.pi))
        phasor = U * np.exp(1j * omega * t)
        ch = dict(r.channels)
        for c, g in zip(rs.planar, gain, strict=True):
            ch[c] = ch[c] + np.real(g * phasor)
        ch["u"] = np.real(phasor)
        recs.append(replace(r, channels=ch, units={**r.units, "u": "V"}))
    return RecordingSet(tuple(recs), rs.planar, rs.mu_label, rs.mu_units, control="u")


def test_a_planted_response_to_the_control_is_recovered_and_needed():
    """Recordings held with a control whose fundamental moves the pitch (about 7% of a
    typical orbit's, more on the small ones): with the control term the orbits, μ0, the
    fold and the gain itself come back; without it the orbits are missed."""
    rs, truth = demo_system(seed=11, fast=True)
    gain = np.array([0.0, 0.005 * np.exp(-1.0j)])                        # m/V, rad/V
    held = _with_planted_control(rs, gain, seed=5)
    post = fit_hybrid(held, "subcritical", seed=0, settings=SETTINGS, progress=False)
    assert post.spec.control_scale is not None
    assert post.interval("mu0").contains(truth.mu0)
    assert post.interval("mu_fold").contains(truth.mu_fold)
    errors = [e["relative"] for e in post.diagnostics["fit"]["orbit_error"]]
    assert max(errors) < 0.03, errors
    # the gain in the frame: z = c + L w (L lower triangular), so w2's is G_alpha / L22
    want = gain[1] / post.spec.frame.L[1, 1]
    g = post.control_gain()["gain"]
    got = g["re"]["median"] + 1j * g["im"]["median"]
    assert abs(got - want) < 0.1 * abs(want), (got, want)
    # the same recordings without the term: the response is left in the orbits (the
    # model without the discrepancy, which would otherwise take the response up)
    free = fit_hybrid(held, "subcritical", seed=0,
                      settings=replace(SETTINGS, control=False, discrepancy=False),
                      progress=False)
    assert free.spec.control_scale is None and free.control_gain() is None
    missed = [e["relative"] for e in free.diagnostics["fit"]["orbit_error"]]
    assert max(missed) > 2 * max(errors), (missed, errors)


def test_without_the_discrepancy_the_scale_away_from_the_data_is_fixed_and_a_misfit_warns(
        planted, tmp_path):
    """Without the discrepancy a new measurement's band away from the recordings takes the
    fixed scale 0.1 in every draw, whatever the relative model error σ_rel (no rule by
    σ_rel); a relative model error above the 2% limit warns that those bands are not
    calibrated; a saved fit keeps the scale; a user's scale replaces it."""
    from bayeshopf import fit_folder
    from bayeshopf.posterior import SIGMA_REL_MAX, diagnose

    post, _, _ = planted
    draws = np.asarray(post.samples["sigma_rel"])
    assert draws.max() < SIGMA_REL_MAX
    assert post.extrapolation_scale == 0.1
    d = diagnose(post)
    assert not [w for w in d["warnings"] if "relative model error" in w]
    assert d["fit"]["extrapolation_scale"] == {"scale": 0.1,
                                               "chosen_by": "model without the discrepancy"}
    # every σ_rel draw moved so that 70% of them lie above the limit: the scale stays
    chains = {**post.run.chains, "sigma_rel": post.run.chains["sigma_rel"]
              - np.quantile(draws, 0.3) + SIGMA_REL_MAX}
    bad = replace(post, run=replace(post.run, chains=chains))
    assert bad.extrapolation_scale == 0.1
    d = diagnose(bad)
    (w,) = [w for w in d["warnings"] if "relative model error" in w]
    assert "not calibrated for such a fit" in w and "by leave-one-out" in w
    assert "Hopf and fold intervals do not carry this misfit" in w
    f = post.features
    i = int(np.argmax(np.where(f.unstable, -np.inf, f.mu)))   # the stable recording of largest μ
    beyond, q = [f.mu[i] + 0.5 * post.spec.mu_span], [0.05, 0.5, 0.95]

    def band(p, where):
        return np.quantile(p.amplitude(where, "stable", predictive=True)[:, 0], q)

    wide = replace(bad, settings=replace(bad.settings, extrapolation_scale=0.7))
    assert wide.extrapolation_scale == 0.7
    assert diagnose(wide)["fit"]["extrapolation_scale"]["chosen_by"] == "setting"
    np.testing.assert_allclose(band(bad, [f.mu[i]]), band(wide, [f.mu[i]]), rtol=1e-4)
    b, w7 = band(bad, beyond), band(wide, beyond)
    assert 3 * (b[2] - b[0]) < w7[2] - w7[0], (b, w7)
    # every draw takes 0.1, whatever its σ_rel: the band is that of 0.1 set by hand
    set01 = replace(bad, settings=replace(bad.settings, extrapolation_scale=0.1))
    np.testing.assert_array_equal(b, band(set01, beyond))
    fit_folder.save_hybrid(bad, tmp_path / "fit")
    saved = fit_folder.load_fit(tmp_path / "fit")
    assert saved.extrapolation["scale"] is None and saved.posterior.extrapolation_scale == 0.1
    p = saved.predict(beyond[0], "stable", predictive=True)
    np.testing.assert_allclose([p.lo, p.median, p.hi], b, rtol=1e-9)


def test_the_discrepancy_is_in_every_prediction_and_a_saved_fit_predicts_the_same(
        planted_discrepancy, tmp_path):
    """The fit carries the model discrepancy (η, ℓ sampled); a new measurement's band half a
    span beyond the data is the same from the saved fit (one predictive path); a user's extra
    scale widens it there and leaves a training μ's band as it was; a relative model error
    above the limit is reported as carried by the discrepancy."""
    from bayeshopf import fit_folder
    from bayeshopf.posterior import SIGMA_REL_MAX, diagnose

    post, _, _ = planted_discrepancy
    assert post.spec.has_discrepancy and {"eta", "ell"} <= set(post.samples)
    assert post.extrapolation_scale == 0.0
    d = diagnose(post)
    assert set(d["fit"]["discrepancy"]) == {"eta", "ell", "sigma_rel", "relative"}
    assert "extrapolation_scale" not in d["fit"]
    f = post.features
    i = int(np.argmax(np.where(f.unstable, -np.inf, f.mu)))   # the stable recording of largest μ
    beyond, q = [f.mu[i] + 0.5 * post.spec.mu_span], [0.05, 0.5, 0.95]

    def band(p, where):
        return np.quantile(p.amplitude(where, "stable", predictive=True)[:, 0], q)

    b = band(post, beyond)
    fit_folder.save_hybrid(post, tmp_path / "fit")
    saved = fit_folder.load_fit(tmp_path / "fit")
    p = saved.predict(beyond[0], "stable", predictive=True)
    np.testing.assert_allclose([p.lo, p.median, p.hi], b, rtol=1e-9)
    wide = replace(post, settings=replace(post.settings, extrapolation_scale=0.7))
    np.testing.assert_allclose(band(wide, [f.mu[i]]), band(post, [f.mu[i]]), rtol=1e-4)
    w7 = band(wide, beyond)
    assert w7[2] - w7[0] > 2 * (b[2] - b[0]), (w7, b)
    # every η draw moved above the limit: the warning says the discrepancy carries it
    chains = {**post.run.chains, "eta": post.run.chains["eta"] + 2 * SIGMA_REL_MAX}
    bad = replace(post, run=replace(post.run, chains=chains))
    (w,) = [w for w in diagnose(bad)["warnings"] if "relative model error" in w]
    assert "model discrepancy carries it" in w and "by leave-one-out" in w
    # the fit's Hopf point and fold are moved by the discrepancy in μ: they carry it
    assert "Hopf and fold intervals carry it through the discrepancy in μ" in w
    assert "do not carry" not in w
    # ... unless the user asked for the normal form's own points
    own = replace(bad, settings=replace(bad.settings, mu_discrepancy=0.0))
    (w,) = [w for w in diagnose(own)["warnings"] if "relative model error" in w]
    assert "Hopf and fold intervals do not carry this misfit" in w

@pytest.fixture(scope="module")
def planted_infinite_width():
    """The planted recordings fitted with the map's network at infinite width."""
    rs, truth = demo_system(seed=11, fast=True)
    return (fit_hybrid(rs, "subcritical", seed=0, settings=replace(SETTINGS, nn_width=None),
                       progress=False), truth)


def test_the_network_at_infinite_width_fits_predicts_and_saves(planted_infinite_width, tmp_path):
    """No hidden layer drawn: the planted μ0 and fold inside their intervals; the network's
    spread is known at a training orbit and grows beyond the recordings; a saved fit
    predicts a new measurement there as the fit does."""
    from bayeshopf import fit_folder
    from bayeshopf.predictive import network_draws

    post, truth = planted_infinite_width
    assert post.spec.nn_training is not None and post.spec.nn_hidden[0].shape == (3, 0)
    assert post.interval("mu0").contains(truth.mu0)
    assert post.interval("mu_fold").contains(truth.mu_fold)
    f = post.features
    i = int(np.argmax(np.where(f.unstable, -np.inf, f.mu)))   # the stable recording of largest μ
    idx = post._draw_indices(200)
    theta = {k: v[idx] for k, v in post.theta.items()}
    beyond = f.mu[i] + 0.5 * post.spec.mu_span
    spread = network_draws(post.spec, theta, [f.mu[i], beyond], 1.0, seed=0)[..., 1]  # a1
    size = np.median(np.abs(post.orbit_coefficients([f.mu[i]], "stable")[:, 0, :, 1]))
    assert np.std(spread[:, 0]) < 1e-3 * size
    assert np.std(spread[:, 1]) > 10 * np.std(spread[:, 0])
    q = [0.05, 0.5, 0.95]
    b = np.quantile(post.amplitude([beyond], "stable", predictive=True)[:, 0], q)
    fit_folder.save_hybrid(post, tmp_path / "fit")
    p = fit_folder.load_fit(tmp_path / "fit").predict(beyond, "stable", predictive=True)
    np.testing.assert_allclose([p.lo, p.median, p.hi], b, rtol=1e-9)


def test_predictions_in_blocks_of_draws_and_padded_mu_are_each_draw_at_each_mu_alone(
        planted_discrepancy):
    """The predictive programs run on blocks of draws with μ padded to a few compiled
    sizes: orbits and frequencies of 1,100 draws at 9 μ (three blocks, the last padded; μ
    padded to 40) are the model's formula for each draw at each μ alone; a training
    recording's orbits from the fit's one computation per branch are those asked for at
    its μ alone by a fresh copy of the fit; the shared arrays are read-only."""
    import jax.numpy as jnp

    from bayeshopf.model import collapsed as cm
    from bayeshopf.predictive import frequency_draws, orbit_coefficients

    post, _, truth = planted_discrepancy
    spec, n = post.spec, 1100
    take = np.resize(np.arange(post.run.betas.shape[0]), n)      # the draws, repeated
    theta = {k: np.asarray(v)[take] for k, v in post.theta.items()}
    betas, gammas = post.run.betas[take], post.run.gammas[take]
    mu = np.linspace(truth.mu_fold, truth.mu0, 11)[1:-1]          # 9 points on both branches
    c = orbit_coefficients(spec, theta, betas, mu, -1.0)
    hz = frequency_draws(spec, theta, gammas, mu, -1.0)
    assert c.shape == (n, 9, 2, 2 * spec.n_harmonics + 1) and hz.shape == (n, 9)
    assert np.isfinite(c).mean() > 0.9 and np.isfinite(hz).mean() > 0.9   # the branch exists
    for j in (0, 499, 500, 1000, 1099):                            # each block, the padded one
        t = {k: jnp.asarray(v[j]) for k, v in theta.items()}
        for k in (0, 4, 8):
            m = jnp.asarray(mu[k:k + 1])
            ref = jnp.einsum("mkj,jc->mck", cm.design(spec, m, -1.0, t), betas[j][:spec.n_basis])
            np.testing.assert_allclose(c[j, k], np.asarray(ref)[0], rtol=1e-9, atol=1e-12)
            om = cm.frequency(spec, t, jnp.asarray(gammas[j]), m, -1.0)
            np.testing.assert_allclose(hz[j, k], float(om[0]) / (2 * np.pi), rtol=1e-12)
    fresh = replace(post)                                          # nothing computed yet
    f = post.features
    for i in range(f.n_recordings):
        branch = "unstable" if f.unstable[i] else "stable"
        alone = fresh.orbit_coefficients([f.mu[i]], branch,
                                         control=fresh.recording_control(i))[:, 0]
        np.testing.assert_allclose(post.training_coefficients[i], alone, rtol=1e-10,
                                   atol=1e-14)
    with pytest.raises(ValueError, match="read-only"):
        post.training_coefficients[0][...] = 0.0
