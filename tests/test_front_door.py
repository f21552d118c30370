"""The front door: ``import bayeshopf as bh``, ``bh.fit`` → an immutable ``Fit``, save and load."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

import bayeshopf as bh
from bayeshopf.diagnostics.checks import Diagnostics, Status
from bayeshopf.errors import FitError


@pytest.fixture(scope="module")
def front(fast_demo_fit):
    """The session's fast demo fit, fitted again through ``bh.fit`` (same seed, same settings)."""
    reference, rs, truth = fast_demo_fit
    fit = bh.fit(rs, bh.Settings.fast(), seed=0, progress=False)
    return fit, reference, rs, truth


def test_every_exported_name_resolves():
    for name in bh.__all__:
        assert getattr(bh, name) is not None, name
    with pytest.raises(AttributeError, match="no attribute 'fitt'"):
        bh.fitt  # noqa: B018


def test_import_leaves_jax_unloaded():
    code = ("import sys, bayeshopf as bh; bh.Status; "
            "print('jax' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "False"


def test_fit_is_the_pipeline_and_immutable(front):
    fit, reference, _, _ = front
    assert isinstance(fit, bh.Fit)
    for k in ("mu0", "mu_fold", "a2"):
        np.testing.assert_allclose(fit.samples[k], reference.samples[k], rtol=1e-9, atol=0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        fit.posterior = None
    assert fit.interval("mu0") == reference.interval("mu0")


def test_fit_refuses_unknown_criticality_and_settings(fast_demo_fit):
    _, rs, _ = fast_demo_fit
    with pytest.raises(FitError, match="criticality must be one of"):
        bh.fit(rs, criticality="transcritical")
    with pytest.raises(FitError, match="settings must be bayeshopf.Settings"):
        bh.fit(rs, {"num_chains": 2})


def test_predict_dataset_against_the_draws_and_the_truth(front):
    fit, _, rs, truth = front
    stable_mu = sorted({r.mu for r in rs if r.branch == "stable"})
    ds = fit.predict(stable_mu, branch="stable", ci=0.9)
    assert ds.sizes["mu"] == len(stable_mu)
    assert ds.attrs["branch"] == "stable" and ds.attrs["ci"] == 0.9
    # the planted system's noiseless amplitude lies inside a new recording's 90% band
    for m, lo, hi in zip(stable_mu, ds.amplitude_lo.values, ds.amplitude_hi.values, strict=True):
        assert lo <= truth.amplitude(m, "stable") <= hi
    # the model's curve is narrower than a new recording's band
    curve = fit.predict(stable_mu, branch="stable", predictive=False)
    assert np.all(curve.amplitude_hi - curve.amplitude_lo < ds.amplitude_hi - ds.amplitude_lo)


def test_predict_is_empty_where_the_branch_does_not_exist(front):
    fit, _, _, truth = front
    above = truth.mu0 + 0.5 * (truth.mu0 - truth.mu_fold)     # no unstable orbit past μ0
    below = truth.mu_fold - 0.5 * (truth.mu0 - truth.mu_fold)  # no orbit at all below the fold
    ds = fit.predict([above, below], branch="unstable")
    assert np.all(ds.p_exists.values < 0.5)
    assert np.all(np.isnan(ds.amplitude.values)) and np.all(np.isnan(ds.amplitude_hi.values))


def test_predict_refuses_bad_arguments(front):
    fit = front[0]
    with pytest.raises(FitError, match="ci must lie strictly between"):
        fit.predict(16.0, ci=90)
    with pytest.raises(FitError, match="mu must be finite"):
        fit.predict([16.0, np.nan])


def test_diagnostics_are_typed_with_a_status_per_check(front):
    fit = front[0]
    d = fit.diagnostics
    assert isinstance(d, Diagnostics)
    assert all(isinstance(c.status, Status) for c in d.checks)
    assert d.ok == (len(d.warnings) == 0)
    with pytest.raises(TypeError):
        d.details["warnings"] = []


def test_diagnostics_place_each_warning_with_its_check():
    base = {"map": {"converged": False}, "posterior": {"method": "nuts", "divergences": 3,
                                                       "sites": {"mu0": {"ok": True}}},
            "fit": {"orbit_error": [{"ok": True}], "amplitude_covered": [False]},
            "warnings": ["MAP: gradient norm 0.1 after 300 L-BFGS steps",
                         "NUTS: 3 divergent transitions",
                         "fit: run02: measured amplitude outside its 90% predictive band",
                         "fit: relative model error 3.1% (limit 2%): the model misses"]}
    d = Diagnostics.from_dict(base)
    assert d.map.status is Status.WARNING and d.map.messages == (base["warnings"][0],)
    assert d.sampler.status is Status.WARNING
    assert d.orbits.ok and not d.amplitudes.ok and not d.model_error.ok
    assert d.frequency is None and d.leave_one_out is None and not d.ok


def test_saved_fit_predicts_the_same(front, tmp_path):
    fit = front[0]
    saved = fit.save(tmp_path / "fit", recordings=front[2])
    names = sorted(p.name for p in (tmp_path / "fit" / "figures").iterdir())
    assert "bifurcation.png" in names and "time_series.png" in names
    assert saved.folder == tmp_path / "fit"
    loaded = bh.load_fit(tmp_path / "fit")
    assert isinstance(loaded, bh.Fit)
    a = fit.predict([15.5, 16.0], branch="unstable")
    b = loaded.predict([15.5, 16.0], branch="unstable")
    np.testing.assert_allclose(b.amplitude.values, a.amplitude.values, rtol=1e-9)
    assert [c.status for c in loaded.diagnostics.checks] == [c.status for c in
                                                             fit.diagnostics.checks]


def test_plots_draw_into_the_users_axes_with_the_fits_labels(front):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fit = front[0]
    fig, (ax1, ax2) = plt.subplots(1, 2)
    assert fit.plot.bifurcation(ax=ax1, zoom=False) is fig
    assert fit.posterior.mu_label in ax1.get_xlabel()
    assert "peak-to-peak of" in ax1.get_ylabel()
    if fit.posterior.has_frequency:
        fit.plot.frequency(ax=ax2)
        assert "Hz" in ax2.get_ylabel()
    plt.close(fig)


def test_fit_leaves_out_unconverged_cbc_recordings(fast_demo_fit, monkeypatch):
    from dataclasses import replace

    from bayeshopf import posterior
    from bayeshopf.data.convergence import Convergence
    from bayeshopf.data.recording import RecordingSet

    _, rs, _ = fast_demo_fit
    bad = next(i for i, r in enumerate(rs) if r.branch == "unstable")
    recs = [replace(r, convergence=Convergence(success=True, error=-0.33, tolerance=0.01))
            if i == bad else r for i, r in enumerate(rs)]
    marked = RecordingSet(tuple(recs), planar=rs.planar, mu_label=rs.mu_label,
                          mu_units=rs.mu_units)
    seen = []
    monkeypatch.setattr(posterior, "fit_hybrid",
                        lambda recordings, *a, **k: seen.append(recordings) or "fitted")
    with pytest.warns(UserWarning, match=rf"{rs[bad].name}: the controller did not converge"):
        bh.fit(marked, progress=False)
    assert [r.name for r in seen[0]] == [r.name for i, r in enumerate(rs) if i != bad]
    bh.fit(marked, progress=False, keep_unconverged=True)
    assert len(seen[1]) == len(rs)


def test_the_command_line_screens_with_the_same_function(fast_demo_fit, capsys, monkeypatch):
    from dataclasses import replace

    from bayeshopf.cli import fit as cli_fit
    from bayeshopf.cli.main import build_parser
    from bayeshopf.data.convergence import Convergence
    from bayeshopf.data.recording import RecordingSet

    _, rs, _ = fast_demo_fit
    recs = [replace(r, convergence=Convergence(success=False)) if i == 0 else r
            for i, r in enumerate(rs)]
    marked = RecordingSet(tuple(recs), planar=rs.planar)
    for keep, n in ((False, len(rs) - 1), (True, len(rs))):
        args = build_parser().parse_args(
            ["fit", "somewhere", "--out", "x"] + (["--keep-unconverged"] if keep else []))
        monkeypatch.setattr(cli_fit, "_read", lambda a: marked)
        assert len(cli_fit.recordings(args)) == n
        err = capsys.readouterr().err
        assert f"data: {rs[0].name}: the controller did not converge" in err
        assert ("kept" if keep else "left out") in err
