"""Results in the ArviZ and xarray world: posterior.nc, load_fit without refitting, ci levels."""

from __future__ import annotations

import json
import os
import warnings

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from bayeshopf import fit_folder  # noqa: E402
from bayeshopf.errors import DataError  # noqa: E402

with warnings.catch_warnings():
    warnings.simplefilter("ignore", FutureWarning)
    import arviz as az  # noqa: E402

GROUPS = {"posterior", "log_likelihood", "posterior_predictive", "observed_data",
          "constant_data"}


@pytest.fixture(scope="module")
def saved(fast_demo_fit, tmp_path_factory):
    """The session's fast demo fit written to a folder (no figures): ``(folder, fit, rs)``."""
    fit, rs, _ = fast_demo_fit
    folder = fit_folder.save_hybrid(fit, tmp_path_factory.mktemp("outputs") / "fit")
    return folder, fit, rs


def test_posterior_nc_opens_in_arviz_with_groups_and_coordinates(saved) -> None:
    folder, fit, _ = saved
    idata = az.from_netcdf(folder / "posterior.nc")
    assert GROUPS <= set(idata.groups())
    f = fit.features
    names = list(f.names)
    K = fit.spec.n_harmonics
    for g in ("log_likelihood", "posterior_predictive", "observed_data", "constant_data"):
        assert list(getattr(idata, g)["recording"].values) == names, g
    post = idata.posterior
    n_chain, n_draw = fit.run.chains["mu0"].shape[:2]
    assert (post.sizes["chain"], post.sizes["draw"]) == (n_chain, n_draw)
    np.testing.assert_allclose(post["mu0"].values, fit.run.chains["mu0"])
    assert post["sigma"].dims == ("chain", "draw", "frame_axis")
    assert list(post["frame_axis"].values) == ["w1", "w2"]
    assert list(post["channel"].values) == ["h", "alpha"]          # the planar channels
    assert post["beta"].dims[2:] == ("basis", "frame_axis") and "1" in post["basis"].values
    # the posterior predictive: a replicated recording per draw, beside what was measured
    pp, obs = idata.posterior_predictive, idata.observed_data
    assert pp["amplitude"].dims == ("chain", "draw", "recording")
    assert pp["coeffs"].dims == ("chain", "draw", "recording", "frame_axis", "coefficient")
    assert list(pp["coefficient"].values) == (["a0"] + [f"a{k}" for k in range(1, K + 1)]
                                              + [f"b{k}" for k in range(1, K + 1)])
    assert list(obs["harmonic"].values) == [0, *range(1, K + 1), *range(1, K + 1)]
    np.testing.assert_allclose(obs["amplitude"].values, f.amplitude)
    np.testing.assert_allclose(obs["coeffs"].values, f.coeffs)
    np.testing.assert_allclose(obs["frequency"].values, f.frequency_hz)
    lo, hi = np.nanquantile(pp["amplitude"].values, [0.005, 0.995], axis=(0, 1))
    assert np.all((lo < f.amplitude) & (f.amplitude < hi))          # each measured in its own
    assert not np.allclose(pp["amplitude"].values[0, 0], pp["amplitude"].values[0, 1])
    lo, hi = np.nanquantile(pp["frequency"].values, [0.005, 0.995], axis=(0, 1))
    assert np.all((lo < f.frequency_hz) & (f.frequency_hz < hi))
    np.testing.assert_allclose(idata.constant_data["mu"].values, f.mu)
    assert idata.posterior.attrs["mu_label"] == "airspeed"
    # az.loo reads the log_likelihood group
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loo = az.loo(idata, pointwise=True)
    assert np.isfinite(loo["elpd_loo"]) and loo["loo_i"].shape == (len(names),)
    np.testing.assert_allclose(idata.log_likelihood["y"].values, fit.log_likelihood)


def test_load_fit_draws_everything_again_without_refitting(saved, tmp_path) -> None:
    folder, fit, rs = saved
    loaded = fit_folder.load_fit(folder)
    post = loaded.posterior
    mu = fit.default_mu_grid(40)
    a, b = fit.diagram(mu), loaded.diagram(mu)
    for x, y in ((a.stable, b.stable), (a.unstable, b.unstable)):
        np.testing.assert_allclose(x.quantiles, y.quantiles, equal_nan=True)
        np.testing.assert_allclose(x.to_hopf if x.to_hopf is not None else np.nan,
                                   y.to_hopf if y.to_hopf is not None else np.nan,
                                   equal_nan=True)
    assert a.mu0 == b.mu0 and a.mu_fold == b.mu_fold
    np.testing.assert_allclose(fit.ppc().coeff_z, loaded.ppc().coeff_z)
    np.testing.assert_allclose(post.log_likelihood, fit.log_likelihood)    # read, not redone
    np.testing.assert_allclose(post.frequency_band(mu, "stable").median,
                               fit.frequency_band(mu, "stable").median, equal_nan=True)
    assert post.features.names == fit.features.names
    # without the recordings: what needs no raw record; with them: everything
    paths = loaded.plot(tmp_path / "a", fmt="pdf", dpi=60)
    assert [p.name for p in paths] == ["bifurcation.pdf", "ppc.pdf", "frequency.pdf"]
    paths = loaded.plot(tmp_path / "b", recordings=rs, dpi=60)
    assert [p.name for p in paths] == ["bifurcation.png", "phase_portraits.png", "ppc.png",
                                       "frequency.png", "time_series.png"]
    assert all(p.stat().st_size > 10_000 for p in paths)
    assert sorted(os.listdir(tmp_path)) == ["a", "b"]      # no staging folder left
    # recordings that are not the fit's are refused with one line
    from bayeshopf.data.recording import RecordingSet

    fewer = RecordingSet(tuple(rs)[1:], planar=rs.planar, mu_label=rs.mu_label,
                         mu_units=rs.mu_units)
    with pytest.raises(DataError, match="missing stable_mu15.30"):
        loaded.plot(tmp_path / "c", recordings=fewer)
    assert not (tmp_path / "c").exists() or not os.listdir(tmp_path / "c")


def test_a_folder_without_the_saved_features_says_what_to_do(saved, tmp_path) -> None:
    import shutil

    folder, _, _ = saved
    old = tmp_path / "old"
    shutil.copytree(folder, old)
    idata = az.from_netcdf(old / "posterior.nc")
    del idata.observed_data["amplitude"]
    os.remove(old / "posterior.nc")
    idata.to_netcdf(str(old / "posterior.nc"))
    loaded = fit_folder.load_fit(old)
    assert loaded.predict(17.0).median > 0                          # predict still works
    with pytest.raises(DataError, match="observed_data variables amplitude.*fit the "
                                        "recordings again"):
        loaded.posterior  # noqa: B018


def test_ci_levels(saved, tmp_path) -> None:
    folder, fit, _ = saved
    mu = fit.default_mu_grid(30)
    d50, d90 = fit.diagram(mu, ci=0.5), fit.diagram(mu, ci=0.9)
    assert d50.stable.levels == (0.25, 0.25, 0.5, 0.75, 0.75) and d50.stable.ci == 0.5
    ok = np.isfinite(d90.stable.quantiles[0])
    assert np.all(d50.stable.quantiles[0][ok] >= d90.stable.quantiles[0][ok])
    assert np.any(d50.stable.quantiles[0][ok] > d90.stable.quantiles[0][ok])
    assert d50.mu0.mass == 0.5 and d50.mu0.width < d90.mu0.width
    p50 = fit.ppc(0.5)
    assert p50.ci == 0.5 and all(a.width < b.width for a, b in zip(
        p50.predictive, fit.ppc().predictive, strict=True))
    loaded = fit_folder.load_fit(folder)
    assert loaded.predict(17.0, ci=0.5).width < loaded.predict(17.0).width
    assert loaded.frequency(17.0, ci=0.5).width < loaded.frequency(17.0).width
    band = fit.frequency_band(mu, "stable", ci=0.5)
    wide = fit.frequency_band(mu, "stable")
    ok = np.isfinite(band.lo)
    assert np.all(band.hi[ok] - band.lo[ok] < wide.hi[ok] - wide.lo[ok])
    s = fit_folder.summary_hybrid(fit, ci=0.95)
    assert s["ci"] == 0.95 and "ci95" in s["mu0"] and "inside_ci95" in s["recordings"][0]
    assert "amplitudes_inside_ci95" in s["ppc"]
    assert json.loads((folder / "summary.json").read_text())["ci"] == 0.9
    with pytest.raises(ValueError, match="ci must lie"):
        fit.diagram(mu, ci=1.0)


def test_diagram_and_ppc_convert_to_xarray_and_pandas(fast_demo_fit) -> None:
    fit = fast_demo_fit[0]
    mu = fit.default_mu_grid(25)
    d = fit.diagram(mu)
    ds = d.to_dataset()
    assert list(ds["branch"].values) == ["stable", "unstable"]
    np.testing.assert_allclose(ds["median"].sel(branch="unstable").values, d.unstable.median,
                               equal_nan=True)
    np.testing.assert_allclose(ds["p_exists"].sel(branch="stable").values, d.stable.p_exists)
    assert ds["mu0"].sel(stat="median") == d.mu0.median and ds.attrs["ci"] == 0.9
    assert np.isnan(ds["to_hopf_median"].sel(branch="stable")).all()     # ends at the fold
    df = d.to_dataframe()
    assert df.index.names == ["branch", "mu"] and len(df) == 2 * mu.size
    assert df.loc[("stable", mu[-1]), "median"] == pytest.approx(d.stable.median[-1])

    ppc = fit.ppc()
    ds = ppc.to_dataset()
    assert list(ds["recording"].values) == list(fit.features.names)
    assert ds["coeff_z"].dims == ("recording", "coefficient")
    np.testing.assert_allclose(ds["measured_se"].values, fit.features.amplitude_sd
                               / np.sqrt(fit.features.n_segments))
    df = ppc.to_dataframe()
    assert list(df.index) == list(fit.features.names)
    assert df["covered"].tolist() == ppc.covered.tolist()
    assert df.loc["stable_mu15.30", "predictive_lower"] == ppc.predictive[0].lo
    assert set(df["branch"]) == {"stable", "unstable"}


def test_leave_one_out_converts_to_xarray_and_pandas() -> None:
    from bayeshopf.validation import HeldOut, HeldOutFold, LeaveOneOut

    def held(m, lo, hi):
        return HeldOut(m, lo, hi, 1.0, (15.0, 14.9, 15.1), (18.0, 17.9, 18.1))

    folds = tuple(
        HeldOutFold(f"r{i}", 15.0 + i, "stable", 1.0 + i, 0.01,
            {"bayes": held(1.0 + i, 0.9 + i, 1.2 + i), "map": held(1.1 + i, 1.05 + i, 1.15 + i)})
        for i in range(3))
    loo = LeaveOneOut(folds, ("bayes", "map"))
    ds = loo.to_dataset()
    assert ds["median"].dims == ("recording", "estimator")
    assert ds["inside"].sel(estimator="bayes").all()
    assert not ds["inside"].sel(estimator="map").any()
    np.testing.assert_allclose(ds["mu_fold_upper"].values, 15.1)
    df = loo.to_dataframe()
    assert len(df) == 6 and df.loc[("r1", "map"), "median"] == pytest.approx(2.1)
    assert df.loc[("r2", "map"), "relative_error"] == pytest.approx(0.1 / 3.0)


def test_cli_plot_redraws_into_the_fit_folder(saved, tmp_path, capsys) -> None:
    import shutil

    from bayeshopf.cli.main import main
    from bayeshopf.data import write_interchange

    folder, _, rs = saved
    fit_dir = tmp_path / "fit"
    shutil.copytree(folder, fit_dir)
    (fit_dir / "figures").mkdir()
    (fit_dir / "figures" / "notes.txt").write_text("mine")
    data = write_interchange(rs, tmp_path / "data")
    assert main(["plot", str(fit_dir), "--format", "svg", "--recordings", str(data),
                 "--dpi", "60"]) == 0
    out = capsys.readouterr().out
    assert "wrote bifurcation.svg" in out
    assert sorted(os.listdir(fit_dir / "figures")) == sorted(
        ["notes.txt", "bifurcation.svg", "phase_portraits.svg", "ppc.svg", "frequency.svg",
         "time_series.svg"])
    assert not [p for p in os.listdir(fit_dir) if p.startswith(".")]
    assert main(["plot", str(fit_dir), "--length-unit", "furlong"]) == 2
    assert "--length-unit furlong" in capsys.readouterr().err
    assert main(["plot", str(tmp_path / "none")]) == 2


def test_files_are_written_while_pending_figures_finish(tmp_path, monkeypatch) -> None:
    """``save_hybrid``'s figures stage: a ``figures`` that returns a waiter (figures
    still drawn by another process) has ``meanwhile`` (model.json, posterior.nc)
    run before the wait, inside the figures' time; one that returns its paths has
    it run after, outside their time. A clock that moves only when told."""
    clock, order = [0.0], []
    monkeypatch.setattr(fit_folder.time, "perf_counter", lambda: clock[0])

    def step(name, seconds):
        order.append(name)
        clock[0] += seconds

    def pending(folder):
        step("figures", 1.0)
        return lambda: step("wait", 2.0)

    def done(folder):
        step("figures", 1.0)
        return [folder / "x.png"]

    for name in "abc":
        (tmp_path / name).mkdir()
    timings = fit_folder._draw_figures(pending, tmp_path / "a", lambda: step("files", 5.0))
    assert order == ["figures", "files", "wait"] and timings == {"figures": 8.0}
    assert (tmp_path / "a" / fit_folder.FIGURES).is_dir()
    order.clear()
    timings = fit_folder._draw_figures(done, tmp_path / "b", lambda: step("files", 5.0))
    assert order == ["figures", "files"] and timings == {"figures": 1.0}
    order.clear()
    assert fit_folder._draw_figures(None, tmp_path / "c", lambda: step("files", 5.0)) == {}
    assert order == ["files"]
