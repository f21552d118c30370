"""Rig descriptions: readers for real rigs, checked on a generated second rig (issue 20)."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from second_rig import (
    DROPOUT_ANGLE,
    FILES,
    HEAVE_M_PER_V,
    HEAVE_OFFSET_V,
    RIG_TOML,
    SENTINEL,
    SecondRig,
    build_second_rig,
)

from bayeshopf.data import (
    ChannelSpec,
    Recording,
    RecordingSet,
    RigDescription,
    load_recordings,
    read_cbc_mat,
    read_interchange,
    write_interchange,
)
from bayeshopf.data.io import dropped_report
from bayeshopf.data.synthetic import PlantedHopf
from bayeshopf.errors import DataError
from bayeshopf.features import extract_harmonics

LONG_TIME = [f for f, *_, long_time in FILES if long_time]


@pytest.fixture(scope="module")
def rig2(tmp_path_factory) -> SecondRig:
    return build_second_rig(tmp_path_factory.mktemp("rig2") / "data")


@pytest.fixture(scope="module")
def read2(rig2) -> RecordingSet:
    return load_recordings(rig2.folder)


def _copy(rig2: SecondRig, dest: Path, files=None, rig_text: str | None = None,
          manifest: bool = True) -> Path:
    """A copy of the fixture folder, optionally with fewer files and another rig.toml."""
    dest.mkdir(parents=True)
    keep = files or [f for f, *_ in FILES]
    for f in keep:
        (dest / f).write_bytes((rig2.folder / f).read_bytes())
    if manifest:
        rows = [line for line in (rig2.folder / "manifest.csv").read_text().splitlines()
                if line.startswith(("#", "file")) or line.split(",")[0] in keep]
        (dest / "manifest.csv").write_text("\n".join(rows) + "\n")
    (dest / "rig.toml").write_text(RIG_TOML if rig_text is None else rig_text)
    return dest


# --------------------------------------------------------------------------- the description


def test_flutter_cbc_is_one_builtin_description():
    rig = RigDescription.flutter_cbc()
    ch = {c.name: c for c in rig.channels}
    assert (ch["h"].row, ch["h"].scale, ch["h"].unit) == (0, 0.18, "m")
    assert (ch["alpha"].row, ch["alpha"].angle) == (3, True)
    assert (rig.sample_rate, rig.data_rows, rig.mu_variable) == (5000.0, 5, "Wind_sped")
    assert rig.planar == ("h", "alpha") and (rig.mu_label, rig.mu_units) == ("airspeed", "m/s")
    assert rig.mu_from_name("CBC_stable_v15_6.mat") == 15.6
    assert rig.control == "actuator" and ch["actuator"].row == 2
    # read from the packaged TOML, which is also an example for users
    import bayeshopf.data

    toml = Path(bayeshopf.data.__file__).with_name("flutter_cbc.toml")
    assert RigDescription.from_file(toml) == rig


def test_python_object_and_json_file_round_trip(tmp_path):
    rig = RigDescription(
        channels=(ChannelSpec("h", row=0, unit="m", scale=0.18, offset=3.3),
                  ChannelSpec("alpha", variable="pitch", unit="rad", angle=True,
                              sentinel=6.28318, missing=("nan", "wrap"))),
        name="mine", time_variable=None, sample_rate=1000.0, mu_variable="U",
        mu_label="airspeed", mu_units="m/s")
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(rig.to_dict()))
    back = RigDescription.from_file(path)
    assert back == rig and back.time_variable is None and back.planar == ("h", "alpha")
    assert back.variables == ("data", "pitch", "U")


def _toml(tmp: Path, text: str) -> Path:
    path = tmp / "rig.toml"
    path.write_text(text)
    return path


BASE = 'sample_rate = 1000.0\n[channels.h]\nrow = 0\n[channels.alpha]\nrow = 1\n'
BAD_DESCRIPTIONS = {
    "unknown top key": ('smaple_rate = 1000.0\n' + BASE, "unknown key 'smaple_rate'"),
    "unknown channel key": (BASE + "scael = 2\n", "channel 'alpha': unknown key 'scael'"),
    "negative row": (BASE.replace("row = 1", "row = -1"), "'row' must be a non-negative"),
    "row beyond data_rows": ("data_rows = 1\n" + BASE, "'row' below data_rows = 1"),
    "no channels": ("sample_rate = 1000.0\n", "a 'channels' table expected"),
    "no row or variable": (BASE.replace("row = 1\n", 'unit = "rad"\n'),
                           "channel 'alpha': 'row' (of 'data') or 'variable' expected"),
    "sentinel listed as a kind": (BASE + 'missing = ["sentinel"]\n',
                                  "give the value as 'sentinel = ...'"),
    "wrap without angle": (BASE + 'missing = ["wrap"]\n', "needs an angle channel"),
    "unknown time_mismatch": ('time_mismatch = "stretch"\n' + BASE, "'time_mismatch' must be"),
    "sample_rate mismatch without rate": (
        'time_mismatch = "sample_rate"\n' + BASE.replace("sample_rate = 1000.0\n", ""),
        "needs 'sample_rate'"),
    "no timing": ('time_variable = ""\n' + BASE.replace("sample_rate = 1000.0\n", ""),
                  "'time_variable' or 'sample_rate' expected"),
    "planar not a channel": ('planar = ["h", "theta"]\n' + BASE, "planar channel 'theta'"),
    "control not a channel": ('control = "u"\n' + BASE, "'control' must name one of the "
                              "channels (h, alpha); found 'u'"),
    "control in the planar pair": ('control = "alpha"\n' + BASE, "'control' must name a "
                                   "channel outside the planar pair ['h', 'alpha']"),
    "scale zero": (BASE + "scale = 0\n", "'scale' must be non-zero"),
    "scale text": (BASE + 'scale = "0.18"\n', "'scale' must be a number"),
    "bad regex": ("mu_pattern = 'v(\\d+'\n" + BASE, "'mu_pattern' must be a regular expression"),
    "not TOML": ("sample_rate = \n" + BASE, "cannot be parsed as TOML"),
}


@pytest.mark.parametrize("case", list(BAD_DESCRIPTIONS), ids=list(BAD_DESCRIPTIONS))
def test_wrong_description_is_one_line(case, tmp_path):
    text, expected = BAD_DESCRIPTIONS[case]
    with pytest.raises(DataError) as err:
        RigDescription.from_file(_toml(tmp_path, text))
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("rig.toml") and expected in msg, msg


def _rows_wrong(rig2, tmp):
    d = _copy(rig2, tmp / "d", files=[FILES[0][0]],
              rig_text=RIG_TOML.replace("row = 3", "row = 7"))
    return d, f"{FILES[0][0]}: row 7 of 'data' expected (channel 'alpha'"


def _variable_missing(rig2, tmp):
    text = RIG_TOML.replace('mu_variable = "Wind_sped"', 'mu_variable = "U"').replace(
        "[channels.alpha]\nrow = 3", '[channels.alpha]\nvariable = "pitch"')
    d = _copy(rig2, tmp / "d", files=[FILES[0][0]], rig_text=text)
    return d, f"{FILES[0][0]}: variable 'pitch' (channel 'alpha'; rig.toml) expected; not " \
              "found (file holds data, time, Wind_sped)"


def _unknown_key(rig2, tmp):
    d = _copy(rig2, tmp / "d", files=[FILES[0][0]], rig_text="colour = 1\n" + RIG_TOML)
    return d, "rig.toml: unknown key 'colour'"


def _branch_needs_manifest(rig2, tmp):
    d = _copy(rig2, tmp / "d", files=["CBC_v22_4.mat"], manifest=False)
    return d, "CBC_v22_4.mat: file name containing 'stable' or 'unstable' (the branch) " \
              "expected; found neither (or list the file with its branch in a manifest.csv"


def _time_refused(rig2, tmp):
    d = _copy(rig2, tmp / "d", files=[LONG_TIME[0]],
              rig_text=RIG_TOML.replace('time_mismatch = "decimate"', ""))
    return d, f"{LONG_TIME[0]}: 'time' with 10000 samples (as 'data') expected; found 100000 " \
              '(set time_mismatch = "decimate"'


def _nan_undeclared(rig2, tmp):
    d = _copy(rig2, tmp / "d", files=[FILES[0][0]],
              rig_text=RIG_TOML.replace('missing = ["nan"]\n', ""))
    v = scipy.io.loadmat(d / FILES[0][0])
    v["data"][3, 5] = np.inf  # NaN is always no reading; inf needs missing = ["nan"]
    scipy.io.savemat(d / FILES[0][0], {k: v[k] for k in ("data", "time", "Wind_sped")})
    return d, "channel 'alpha' has 1 infinite sample(s), first at index 5; " \
              'expected finite numbers or NaN (or missing = ["nan"]'


WRONG = [_rows_wrong, _variable_missing, _unknown_key, _branch_needs_manifest, _time_refused,
         _nan_undeclared]


@pytest.mark.parametrize("case", WRONG, ids=[c.__name__[1:] for c in WRONG])
def test_wrong_description_for_the_files_is_one_line(case: Callable, rig2, tmp_path):
    folder, expected = case(rig2, tmp_path)
    with pytest.raises(DataError) as err:
        load_recordings(folder)
    msg = str(err.value)
    assert "\n" not in msg and expected in msg, msg


# --------------------------------------------------------------------------- each quirk


def test_sentinel_runs_are_left_out_with_their_time_stamps(rig2, read2):
    for rec, clean in zip(read2, rig2.clean, strict=True):
        mask = rig2.dropouts[rec.name]
        assert 0.03 <= mask.mean() <= 0.22            # as planted: 3-22% of the samples
        assert rec.dropped == int(mask.sum())
        np.testing.assert_allclose(rec.t, clean.t[~mask], rtol=1e-12, atol=1e-12)
        for c in ("h", "alpha"):
            np.testing.assert_array_equal(rec.channel(c), clean.channel(c)[~mask])
        alpha = rec.channel("alpha")
        assert 0.27 < alpha.min() and alpha.max() < 0.45    # no sentinel left
        assert rec.has_gaps and rec.dt == pytest.approx(clean.dt)
    lines = dropped_report(read2)
    assert len(lines) == len(FILES)
    first = rig2.dropouts[FILES[0][0]]
    assert lines[0].startswith(f"{FILES[0][0]}: {int(first.sum())} of {first.size} samples (")


def test_dropouts_start_at_one_pitch_angle(rig2):
    """The planted runs start where the pitch passes one angle (same phase every cycle)."""
    for rec in rig2.clean:
        mask = rig2.dropouts[rec.name]
        starts = np.flatnonzero(mask[1:] & ~mask[:-1]) + 1
        alpha = rec.channel("alpha")
        assert np.all(np.abs(alpha[starts] - DROPOUT_ANGLE) < 0.01)


def test_nan_and_full_turn_jumps_are_no_reading(tmp_path):
    spec = ChannelSpec("alpha", row=1, unit="rad", angle=True, sentinel=SENTINEL,
                       missing=("nan", "wrap"))
    raw = 0.36 + 0.05 * np.sin(np.linspace(0, 20, 200))
    raw[[3, 4]] = np.float32(SENTINEL)        # stored in single precision
    raw[10] = np.nan
    raw[20:25] += 2 * math.pi                 # a jump of a full turn
    raw[30:32] -= 2 * math.pi
    flagged = spec.no_reading(raw)
    assert np.flatnonzero(flagged).tolist() == [3, 4, 10, 20, 21, 22, 23, 24, 30, 31]
    assert not ChannelSpec("a", row=0).no_reading(raw).any()    # nothing declared
    assert ChannelSpec("d", row=0, unit="deg", angle=True, missing=("wrap",)).full_turn == 360
    # through the reader: the samples are gone, the rest is kept
    t = np.arange(200) / 100.0
    scipy.io.savemat(tmp_path / "run_stable.mat",
                     {"data": np.vstack([np.sin(t), raw]), "mu": np.array([[1.5]])})
    rig = RigDescription((ChannelSpec("h", row=0), spec), sample_rate=100.0, mu_variable="mu",
                         time_variable=None)
    rec = read_cbc_mat(tmp_path, rig)[0]
    assert rec.dropped == 10 and rec.t.size == 190 and np.all(np.abs(rec.channel("alpha")) < 1)
    np.testing.assert_array_equal(rec.t, t[~flagged])


def test_offset_and_scale_of_a_channel():
    spec = ChannelSpec("h", row=0, scale=0.18, offset=3.3)
    np.testing.assert_allclose(spec.to_physical(np.array([3.3, 4.3])), [0.0, 0.18])


def test_manifest_gives_branch_and_mu_of_mat_files(rig2, read2):
    assert read2.names == [f for f, *_ in FILES]          # manifest order
    assert [r.branch for r in read2] == [b for _, _, b, *_ in FILES]
    # the manifest's mu wins over Wind_sped (written 0.04 higher)
    np.testing.assert_array_equal(read2.mus, [mu for _, mu, *_ in FILES])
    assert (read2.mu_label, read2.mu_units, read2.planar) == ("airspeed", "m/s", ("h", "alpha"))
    # without the manifest, the stable files read, with Wind_sped as mu
    stable = [f for f, _, b, *_ in FILES if b == "stable"]
    rs = read_cbc_mat([rig2.folder / f for f in stable], rig2.folder / "rig.toml")
    np.testing.assert_allclose(rs.mus, [mu + 0.04 for f, mu, *_ in FILES if f in stable])


def test_manifest_mixes_mat_and_csv_files(rig2, read2, tmp_path):
    csv = write_interchange(read2.subset([0]), tmp_path / "csv")   # gaps survive the CSV
    d = _copy(rig2, tmp_path / "mixed", files=[FILES[1][0]])
    (d / "rec.csv").write_bytes((csv / f"{Path(FILES[0][0]).stem}.csv").read_bytes())
    (d / "manifest.csv").write_text(f"file,mu,branch\nrec.csv,20.3,stable\n"
                                    f"{FILES[1][0]},21.5,stable\n")
    rs = read_interchange(d, rig=d / "rig.toml")
    assert rs.names == ["rec.csv", FILES[1][0]] and rs.mu_label == "airspeed"
    np.testing.assert_array_equal(rs[0].t, read2[0].t)
    np.testing.assert_array_equal(rs[0].channel("alpha"), read2[0].channel("alpha"))


def test_data_beside_a_long_time_vector(rig2, read2, tmp_path):
    by_name = {r.name: r for r in read2}
    for name in LONG_TIME:
        v = scipy.io.loadmat(rig2.folder / name)
        assert v["data"].shape[1] == 10_000 and v["time"].size == 100_000
        rec = by_name[name]
        assert rec.dt == pytest.approx(1e-3)          # every 10th stamp of a 10 kHz vector
        assert rec.t.size + rec.dropped == 10_000 and rec.t[-1] < 10.0
    # time_mismatch = "sample_rate": the rig's 2 kHz from the first stamp
    d = _copy(rig2, tmp_path / "d", files=[LONG_TIME[0]], rig_text=RIG_TOML.replace(
        'time_mismatch = "decimate"', 'time_mismatch = "sample_rate"'))
    rec = load_recordings(d)[0]
    assert rec.dt == pytest.approx(5e-4) and rec.t[-1] < 5.0
    # decimate needs len(time) = k len(data)
    v = scipy.io.loadmat(d / LONG_TIME[0])
    scipy.io.savemat(d / LONG_TIME[0], {"data": v["data"], "time": v["time"][:, :15_000],
                                        "Wind_sped": v["Wind_sped"]})
    (d / "rig.toml").write_text(RIG_TOML)
    with pytest.raises(DataError, match=r"found 15000 \(time_mismatch = \"decimate\" needs "
                                        r"15000 = k x 10000; set time_mismatch = \"sample_rate\""):
        load_recordings(d)


def test_heave_offset_of_3_3_volts_reaches_the_frame(read2):
    h = np.concatenate([r.channel("h") for r in read2])
    assert np.mean(h) == pytest.approx(HEAVE_OFFSET_V * HEAVE_M_PER_V, rel=0.01)


def test_large_offset_and_drifting_mean_keep_the_frame():
    """Features do not change when a large common offset is added; drift is fine too."""
    kw = dict(duration=6.0, fs=200.0, noise=0.01, seed=1)
    sys_ = PlantedHopf(mu0=23.0, a2=3.4, T_s=np.array([0.0, 0.36]))
    rs = sys_.simulate((20.3, 22.0, 24.5), (20.6, 22.4), **kw)
    shift = np.array([HEAVE_OFFSET_V * HEAVE_M_PER_V, 0.0])
    moved = RecordingSet(tuple(
        Recording(r.t, {"h": r.channel("h") + shift[0], "alpha": r.channel("alpha")}, r.units,
                  r.mu, r.branch, r.name) for r in rs), rs.planar)
    f0, f1 = extract_harmonics(rs), extract_harmonics(moved)
    np.testing.assert_allclose(f1.frame.centre - f0.frame.centre, shift, atol=1e-12)
    np.testing.assert_allclose(f1.coeffs, f0.coeffs, atol=1e-6)
    np.testing.assert_allclose(f1.amplitude, f0.amplitude, rtol=1e-6)
    # a mean that drifts with amplitude by more than the smallest orbit's half-size
    drift = PlantedHopf(mu0=23.0, a2=3.4, T_L_mu=np.array([0.01, 0.05]), nonlinear=0.12,
                        T_s=np.array([0.594, 0.36]))
    rd = drift.simulate((20.3, 22.0, 24.5), (20.6, 22.4), **kw)
    means = np.array([r.planar(rd.planar).mean(axis=0) for r in rd])
    assert np.ptp(means[:, 1]) > 0.5 * np.ptp(rd[4].channel("alpha"))
    fd = extract_harmonics(rd)
    assert np.all(np.isfinite(fd.coeffs))
    truth = [float(drift.amplitude(r.mu, r.branch)) for r in rd]
    np.testing.assert_allclose(fd.amplitude, truth, rtol=0.03)


def test_features_of_gappy_records_match_the_clean_signal(rig2, read2):
    clean = extract_harmonics(rig2.clean)
    gappy = extract_harmonics(read2, frame=clean.frame)   # the same frame: comparable
    assert np.all(np.isfinite(gappy.coeffs)) and np.all(np.isfinite(gappy.coeffs_se))
    np.testing.assert_array_equal(gappy.n_segments, clean.n_segments)
    dev = np.abs(gappy.coeffs - clean.coeffs) / gappy.coeffs_se
    assert dev.max() < 4.0, dev.max()
    np.testing.assert_allclose(gappy.amplitude, clean.amplitude, rtol=2e-3)
    np.testing.assert_allclose(gappy.omega, clean.omega, rtol=1e-4)
    # the sentinel read as data would tear the orbits apart
    torn = RecordingSet(tuple(
        Recording(c.t, {"h": c.channel("h"), "alpha": np.where(rig2.dropouts[c.name], SENTINEL,
                                                               c.channel("alpha"))},
                  c.units, c.mu, c.branch, c.name) for c in rig2.clean), ("h", "alpha"))
    bad = extract_harmonics(torn, frame=clean.frame)
    assert np.max(np.abs(bad.coeffs - clean.coeffs) / gappy.coeffs_se) > 100


def test_trace_breaks_lines_at_gaps(read2):
    rec = read2[0]
    z = rec.trace(read2.planar)
    n_gaps = int(np.sum(np.diff(rec.t) > 1.5 * rec.dt))
    assert n_gaps > 10 and z.shape[0] == rec.t.size + n_gaps
    assert int(np.isnan(z[:, 0]).sum()) == n_gaps and np.nanmax(z[:, 1]) < 0.45
    assert rec.trace(read2.planar, max_points=1000).shape[0] <= 1000 + n_gaps


def test_rig_toml_beside_the_data_is_found(rig2, tmp_path):
    d = _copy(rig2, tmp_path / "d", files=[FILES[0][0]])
    assert load_recordings(d)[0].dropped > 0
    assert load_recordings(d / FILES[0][0]).extra["rig"] == "second rig"
    # an explicit description wins over rig.toml
    with pytest.raises(DataError, match=r"'data' of shape 5 x N expected; found \(4, 16000\)"):
        load_recordings(d, rig=RigDescription.flutter_cbc())


# --------------------------------------------------------------------------- end to end


def test_second_rig_fits_end_to_end_from_the_cli(rig2, tmp_path, capsys):
    """``bayeshopf fit DIR --rig rig.toml --fast`` runs to the end; the diagram is subcritical.

    The default model and inference (importance sampling, NUTS where its check fails).
    """
    from bayeshopf.cli.main import main
    from bayeshopf.fit_folder import load_fit

    out = tmp_path / "fit"
    code = main(["fit", str(rig2.folder), "--rig", str(rig2.folder / "rig.toml"),
                 "--out", str(out), "--fast", "--seed", "0"])
    err = capsys.readouterr().err
    assert code == 0, err
    for name, mask in rig2.dropouts.items():                 # the log says what was left out
        assert f"data: {name}: {int(mask.sum())} of {mask.size} samples" in err
    s = json.loads((out / "summary.json").read_text())
    assert s["criticality"] == "subcritical"
    assert s["mu_fold"]["ci90"][1] < s["mu0"]["ci90"][0]     # fold below the Hopf point
    assert s["mu0"]["ci90"][0] - 0.2 < rig2.truth.mu0 < s["mu0"]["ci90"][1] + 0.2
    assert abs(s["mu_fold"]["median"] - rig2.truth.mu_fold) < 0.3
    unstable = [r for r in s["recordings"] if r["branch"] == "unstable"]
    assert len(unstable) == 3 and all(r["predicted"]["median"] > 0 for r in unstable)
    fit = load_fit(out)
    assert fit.p_exists(21.0, "unstable") > 0.95                # the unstable branch is there
    assert (out / "figures" / "phase_portraits.png").stat().st_size > 10_000
    # time series: a uniform grid; the measured series is NaN exactly where the
    # dropouts were left out (the drawn line breaks), the prediction is everywhere
    rs2 = load_recordings(rig2.folder)
    bands = fit.posterior.time_series_bands(rs2)   # the saved fit, rebuilt
    assert sum(np.isnan(b.measured).any() for b in bands) >= 3
    for band, rec in zip(bands, rs2, strict=True):
        assert np.allclose(np.diff(band.t), band.t[1] - band.t[0])
        assert np.isfinite(band.median).all()
        gap = np.isnan(band.measured)
        if not rec.has_gaps:
            assert not gap.any()
            continue
        t = rec.t - rec.t[0]
        nearest = np.min(np.abs(t[None, :] - band.t[gap, None]), axis=1) if gap.any() else []
        assert np.all(np.asarray(nearest) > 0.5 * rec.dt)        # no sample there
        kept = np.min(np.abs(t[None, :] - band.t[~gap, None]), axis=1)
        assert np.all(kept <= 0.5 * rec.dt + 1e-12)                # a sample there
