from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from bayeshopf.data import (
    Recording,
    RecordingSet,
    load_recordings,
    read_cbc_mat,
    read_interchange,
    write_interchange,
)
from bayeshopf.errors import DataError, OutputError

CBC_DIR = (Path(__file__).parents[1] / ".." / "shared" / "data" / "flutter_cbc").resolve()
needs_cbc = pytest.mark.skipif(
    not CBC_DIR.is_dir(), reason=f"flutter CBC recordings not found at {CBC_DIR}"
)


# --------------------------------------------------------------------------- helpers


def synthetic_set(n: int = 40) -> RecordingSet:
    t = 0.01 + np.arange(n) * 1e-3
    recs = []
    for i, (mu, branch) in enumerate([(1.0, "stable"), (1.5, "stable"), (1.25, "unstable")]):
        w = 2 * np.pi * (3.0 + i)
        chans = {
            "h": (0.1 + i) * np.sin(w * t) + 1e-17 * i,
            "alpha": np.cos(w * t) / 3.0,
            "u": np.random.default_rng(i).normal(size=n),
        }
        units = {"h": "m", "alpha": "rad", "u": ""}
        recs.append(Recording(t, chans, units, mu, branch, name=f"rec{i + 1}.csv"))
    return RecordingSet(tuple(recs), ("h", "alpha"), mu_label="airspeed", mu_units="m/s")


def write_manifest(folder: Path, rows: list[str], header: str = "file,mu,branch") -> None:
    folder.mkdir(parents=True, exist_ok=True)
    text = "# mu_label: airspeed\n# mu_units: m/s\n" + "\n".join([header, *rows]) + "\n"
    (folder / "manifest.csv").write_text(text)


def write_csv(folder: Path, name: str, header: str, table: np.ndarray) -> None:
    np.savetxt(folder / name, table, fmt="%.17g", delimiter=",", header=header, comments="")


def good_table(n: int = 20) -> np.ndarray:
    t = np.arange(n) * 0.01
    return np.column_stack([t, np.sin(t), np.cos(t)])


def good_folder(folder: Path, n_rec: int = 2) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for i in range(n_rec):
        write_csv(folder, f"rec{i + 1}.csv", "t,h [m],alpha [rad]", good_table())
        rows.append(f"rec{i + 1}.csv,{1.0 + i},stable")
    write_manifest(folder, rows)
    return folder


def snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    if not folder.exists():
        return {}
    return {
        str(p): (p.read_bytes(), p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def save_mat(path: Path, **variables: object) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    scipy.io.savemat(path, variables)


def good_mat_vars(n: int = 50) -> dict[str, object]:
    t = (1 + np.arange(n)) / 5000.0
    data = np.vstack([np.sin(50 * t), np.zeros(n), np.zeros(n), 0.7 + np.cos(50 * t), np.zeros(n)])
    return {"data": data, "time": t[None, :], "Wind_sped": np.array([[15.7]])}


# --------------------------------------------------------------------------- real CBC files


@pytest.fixture(scope="module")
def cbc() -> RecordingSet:
    if not CBC_DIR.is_dir():
        pytest.skip(f"flutter CBC recordings not found at {CBC_DIR}")
    return read_cbc_mat(CBC_DIR)


@needs_cbc
def test_cbc_recordings(cbc: RecordingSet) -> None:
    assert len(cbc) == 7
    stable = [r for r in cbc if r.branch == "stable"]
    unstable = [r for r in cbc if r.branch == "unstable"]
    assert cbc.is_unstable.tolist() == [False] * 4 + [True] * 3  # stable first
    np.testing.assert_allclose([r.mu for r in stable], [14.9, 15.6, 16.5, 17.3])
    np.testing.assert_allclose([r.mu for r in unstable], [14.9, 15.7, 16.5])
    assert cbc[5].name == "CBC_unstable_v15_6.mat"  # Wind_sped wins over the file name
    assert cbc.planar == ("h", "alpha")
    assert cbc.units == ("m", "rad")
    assert (cbc.mu_label, cbc.mu_units) == ("airspeed", "m/s")
    r0 = cbc[0]
    assert set(r0.channels) == {"h", "alpha", "cbc_target", "actuator", "mean_h"}
    assert dict(r0.units) == {
        "h": "m",
        "alpha": "rad",
        "cbc_target": "V",
        "actuator": "V",
        "mean_h": "m",
    }
    assert r0.t.size == 100_000 and r0.dt == pytest.approx(2e-4)
    assert Path(r0.source).is_absolute() and Path(r0.source).name == r0.name
    window = r0.t < r0.t[0] + 1.2
    assert 0.036 <= np.ptp(r0.channel("h")[window]) <= 0.040  # heave in metres
    alpha = r0.channel("alpha")
    assert 0.5 < np.median(alpha) < 0.9 and np.ptp(alpha) < 0.5  # radians, encoder offset


@needs_cbc
def test_load_recordings_detects_cbc(cbc: RecordingSet, tmp_path: Path) -> None:
    one = load_recordings(CBC_DIR / "CBC_stable_v14_9.mat", planar=("alpha", "h"))
    assert one.planar == ("alpha", "h") and len(one) == 1
    np.testing.assert_array_equal(one[0].channel("h"), cbc[0].channel("h"))


@needs_cbc
def test_cbc_read_without_time(tmp_path: Path) -> None:
    mat = scipy.io.loadmat(CBC_DIR / "CBC_unstable_v15_6.mat", variable_names=["data", "Wind_sped"])
    save_mat(
        tmp_path / "CBC_unstable_x.mat", data=mat["data"][:, :1000], Wind_sped=mat["Wind_sped"]
    )
    rs = read_cbc_mat([tmp_path / "CBC_unstable_x.mat"])
    assert rs[0].mu == pytest.approx(15.7) and rs[0].branch == "unstable"
    assert rs[0].t[0] == 0.0 and rs[0].dt == pytest.approx(2e-4)


def test_cbc_mu_from_file_name_and_sorting(tmp_path: Path) -> None:
    v = good_mat_vars()
    del v["Wind_sped"]
    save_mat(tmp_path / "CBC_unstable_v14_9.mat", **v)
    save_mat(tmp_path / "CBC_stable_v16_5.mat", **v)
    save_mat(tmp_path / "CBC_stable_v15_1.mat", **v)
    rs = load_recordings(tmp_path)
    assert rs.names == ["CBC_stable_v15_1.mat", "CBC_stable_v16_5.mat", "CBC_unstable_v14_9.mat"]
    np.testing.assert_allclose(rs.mus, [15.1, 16.5, 14.9])
    np.testing.assert_allclose(rs[0].channel("h"), 0.18 * v["data"][0])


@needs_cbc
def test_manifest_lists_cbc_mat_files(cbc: RecordingSet, tmp_path: Path) -> None:
    d = tmp_path / "m"
    d.mkdir()
    (d / "manifest.csv").write_text(
        "file,mu,branch\n"
        f"{CBC_DIR / 'CBC_unstable_v15_6.mat'},15.6,unstable\n"
        f"{CBC_DIR / 'CBC_stable_v14_9.mat'},14.9,stable\n"
    )
    rs = load_recordings(d)
    assert rs.names == ["CBC_unstable_v15_6.mat", "CBC_stable_v14_9.mat"]  # manifest order
    assert rs.mus.tolist() == [15.6, 14.9]  # the manifest's mu wins over Wind_sped (15.7)
    assert [r.branch for r in rs] == ["unstable", "stable"]
    assert (rs.planar, rs.mu_label, rs.mu_units) == (("h", "alpha"), "airspeed", "m/s")
    np.testing.assert_array_equal(rs[0].channel("h"), cbc[5].channel("h"))
    np.testing.assert_array_equal(rs[1].t, cbc[0].t)


def test_csv_with_gaps_of_whole_samples_is_read(tmp_path: Path) -> None:
    d = good_folder(tmp_path / "d")
    table = good_table(40)
    write_csv(d, "rec2.csv", "t,h [m],alpha [rad]", np.delete(table, [5, 6, 20], axis=0))
    rec = read_interchange(d)[1]
    assert rec.t.size == 37 and rec.has_gaps and rec.dt == pytest.approx(0.01)
    assert not read_interchange(d)[0].has_gaps


# --------------------------------------------------------------------------- interchange


def test_round_trip(tmp_path: Path) -> None:
    rs = synthetic_set()
    out = write_interchange(rs, tmp_path / "out")
    assert out == tmp_path / "out"
    back = read_interchange(out)
    assert (back.planar, back.mu_label, back.mu_units) == (rs.planar, rs.mu_label, rs.mu_units)
    assert back.names == rs.names
    for a, b in zip(rs, back, strict=True):
        assert (a.mu, a.branch) == (b.mu, b.branch)
        np.testing.assert_array_equal(a.t, b.t)  # %.17g round-trips exactly
        assert dict(a.units) == dict(b.units)
        for k in a.channels:
            np.testing.assert_array_equal(a.channels[k], b.channels[k])
        assert b.source == str((out / b.name).resolve())
    header = (out / "rec1.csv").read_text().splitlines()[0]
    assert header == "t,h [m],alpha [rad],u"
    manifest = (out / "manifest.csv").read_text().splitlines()
    assert manifest[:3] == ["# mu_label: airspeed", "# mu_units: m/s", "file,mu,branch"]
    # no temporary siblings are left behind
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_write_puts_planar_first_and_load_detects(tmp_path: Path) -> None:
    rs = synthetic_set()
    swapped = RecordingSet(rs.recordings, ("u", "alpha"))
    write_interchange(swapped, tmp_path / "w")
    back = load_recordings(tmp_path / "w")
    assert back.planar == ("u", "alpha") and (back.mu_label, back.mu_units) == ("mu", "")
    assert load_recordings(tmp_path / "w" / "manifest.csv", planar=("h", "u")).planar == ("h", "u")


def test_read_interchange_extras(tmp_path: Path) -> None:
    folder = tmp_path / "d"
    folder.mkdir()
    write_csv(folder, "a.csv", "t, alpha [deg] ,h,extra [V]", good_table(10)[:, [0, 1, 2, 1]])
    (folder / "manifest.csv").write_text("note,file,branch,mu\nfirst,a.csv, Unstable ,2.5\n")
    rs = read_interchange(folder)
    assert rs.planar == ("alpha", "h") and (rs.mu_label, rs.mu_units) == ("mu", "")
    r = rs[0]
    assert (r.mu, r.branch, r.name) == (2.5, "unstable", "a.csv")
    assert dict(r.units) == {"alpha": "deg", "h": "", "extra": "V"}
    assert read_interchange(folder, planar=("h", "extra")).planar == ("h", "extra")


def test_write_refuses_non_empty_folder(tmp_path: Path) -> None:
    rs = synthetic_set()
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "keep.txt").write_text("precious")
    with pytest.raises(OutputError, match="non-empty folder"):
        write_interchange(rs, folder)
    assert [p.name for p in folder.iterdir()] == ["keep.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    with pytest.raises(OutputError, match="found a file"):
        write_interchange(rs, folder / "keep.txt")
    write_interchange(rs, folder, overwrite=True)
    assert sorted(p.name for p in folder.iterdir()) == [
        "manifest.csv",
        "rec1.csv",
        "rec2.csv",
        "rec3.csv",
    ]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    (tmp_path / "empty").mkdir()
    write_interchange(rs, tmp_path / "empty")  # an existing empty folder is fine
    assert len(read_interchange(tmp_path / "empty")) == 3


def test_write_failure_leaves_nothing(tmp_path: Path) -> None:
    rs = synthetic_set()
    bad = RecordingSet(
        (rs[0], Recording(rs[1].t, {"h": rs[1].t, "alpha": rs[1].t}, {}, 1.0, "stable", "x")),
        ("h", "alpha"),
    )
    with pytest.raises(DataError, match="x: channels"):
        write_interchange(bad, tmp_path / "out")
    assert list(tmp_path.iterdir()) == []


def test_write_file_names_are_safe_and_unique(tmp_path: Path) -> None:
    rs = synthetic_set()
    recs = [
        Recording(r.t, r.channels, r.units, r.mu, r.branch, name=name)
        for r, name in zip(rs, ["run 1.mat", "run_1.mat", "manifest.csv"], strict=True)
    ]
    write_interchange(RecordingSet(tuple(recs), rs.planar), tmp_path / "o")
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == [
        "manifest.csv", "manifest_2.csv", "run_1.csv", "run_1_2.csv"]
    # the manifest's name column gives the names back
    assert read_interchange(tmp_path / "o").names == ["run 1.mat", "run_1.mat", "manifest.csv"]


# --------------------------------------------------------------------------- bad inputs

Case = Callable[[Path], tuple[Path, str, Callable[[Path], object]]]


def _manifest_rows(folder: Path, rows: list[str], header: str = "file,mu,branch") -> Path:
    good_folder(folder)
    write_manifest(folder, rows, header)
    return folder


def case_folder_missing(tmp: Path):
    return tmp / "nope", "nope", read_interchange


def case_manifest_missing(tmp: Path):
    d = good_folder(tmp / "d")
    (d / "manifest.csv").unlink()
    return d, "manifest.csv", read_interchange


def case_nothing_to_load(tmp: Path):
    d = good_folder(tmp / "d")
    (d / "manifest.csv").unlink()
    return d, "rec1.csv", load_recordings  # message lists what was found


def case_manifest_column(tmp: Path):
    return _manifest_rows(tmp / "d", ["rec1.csv,1.0"], "file,mu"), "manifest.csv", read_interchange


def case_manifest_mu(tmp: Path):
    d = _manifest_rows(tmp / "d", ["rec1.csv,1.0,stable", "rec2.csv,fast,stable"])
    return d, "manifest.csv row 2", read_interchange


def case_manifest_branch(tmp: Path):
    d = _manifest_rows(tmp / "d", ["rec1.csv,1.0,stable", "rec2.csv,2.0,stable", "rec3.csv,3,x"])
    return d, "manifest.csv row 3 (line 6): branch must be", read_interchange


def case_manifest_branch_label(tmp: Path):
    d = _manifest_rows(tmp / "d", ["rec1.csv,1.0,stable", "rec2.csv,2.0,stabel"])
    return d, "found 'stabel'", read_interchange


def case_recording_missing(tmp: Path):
    d = _manifest_rows(tmp / "d", ["rec1.csv,1.0,stable", "rec9.csv,2.0,stable"])
    return d, "rec9.csv", read_interchange


def case_csv_corrupt(tmp: Path):
    d = good_folder(tmp / "d")
    (d / "rec2.csv").write_text("t,h,alpha\n0,1,2\n0.1,oops,3\n0.2,1,2\n")
    return d, "rec2.csv", read_interchange


def case_csv_binary(tmp: Path):
    d = good_folder(tmp / "d")
    (d / "rec2.csv").write_bytes(b"\xff\xfe\x00garbage\x00\x81\n\x00\x00")
    return d, "rec2.csv", read_interchange


def case_csv_ragged(tmp: Path):
    d = good_folder(tmp / "d")
    (d / "rec1.csv").write_text("t,h,alpha\n0,1,2\n0.1,1\n0.2,1,2\n")
    return d, "rec1.csv", read_interchange


def case_csv_no_t(tmp: Path):
    d = good_folder(tmp / "d")
    write_csv(d, "rec2.csv", "time,h [m],alpha [rad]", good_table())
    return d, "rec2.csv: column 't' expected", read_interchange


def case_csv_no_planar(tmp: Path):
    d = good_folder(tmp / "d")
    return d, "rec1.csv: column 'theta' expected", lambda p: read_interchange(p, ("h", "theta"))


def case_csv_nan(tmp: Path):
    d = good_folder(tmp / "d")
    table = good_table()
    table[[4, 7], 2] = [np.nan, np.inf]
    write_csv(d, "rec2.csv", "t,h [m],alpha [rad]", table)
    # NaN is no reading (left out); an infinite value is refused
    expected = "rec2.csv: channel 'alpha' has 1 infinite sample(s), first at index 7"
    return d, expected, read_interchange


def case_csv_short(tmp: Path):
    d = good_folder(tmp / "d")
    write_csv(d, "rec2.csv", "t,h [m],alpha [rad]", good_table(2))
    return d, "rec2.csv: expected at least 3 samples; found 2", read_interchange


def case_csv_empty(tmp: Path):
    d = good_folder(tmp / "d")
    (d / "rec1.csv").write_text("t,h,alpha\n")
    return d, "rec1.csv: expected at least 3 samples; found 0", read_interchange


def case_csv_nonuniform(tmp: Path):
    d = good_folder(tmp / "d")
    table = good_table()
    table[10:, 0] += 0.003
    write_csv(d, "rec2.csv", "t,h [m],alpha [rad]", table)
    return d, "rec2.csv: t must be uniformly spaced; dt varies by", read_interchange


def case_csv_decreasing(tmp: Path):
    d = good_folder(tmp / "d")
    table = good_table()
    table[5, 0] = table[4, 0]
    write_csv(d, "rec1.csv", "t,h [m],alpha [rad]", table)
    return d, "rec1.csv: t must be strictly increasing", read_interchange


def case_channels_differ(tmp: Path):
    d = good_folder(tmp / "d")
    write_csv(
        d, "rec2.csv", "t,h [m],alpha [rad],x", np.column_stack([good_table(), good_table()[:, 1]])
    )
    return d, "rec2.csv: channels h, alpha expected (as in rec1.csv)", read_interchange


def case_mat_corrupt(tmp: Path):
    d = tmp / "m"
    save_mat(d / "CBC_stable_v15_0.mat", **good_mat_vars())
    (d / "CBC_stable_v16_0.mat").write_bytes(b"MATLAB 5.0 MAT-file" + bytes(range(256)) * 3)
    return d, "CBC_stable_v16_0.mat", read_cbc_mat


def case_mat_no_data(tmp: Path):
    d = tmp / "m"
    v = good_mat_vars()
    v["signals"] = v.pop("data")
    save_mat(d / "CBC_stable_v15_0.mat", **v)
    return d, "CBC_stable_v15_0.mat: variable 'data'", load_recordings


def case_mat_bad_shape(tmp: Path):
    d = tmp / "m"
    v = good_mat_vars()
    v["data"] = v["data"][:4]
    save_mat(d / "CBC_unstable_v15_0.mat", **v)
    return d, "CBC_unstable_v15_0.mat: 'data' of shape 5 x N expected; found (4, 50)", read_cbc_mat


def case_mat_no_branch(tmp: Path):
    d = tmp / "m"
    save_mat(d / "CBC_v15_0.mat", **good_mat_vars())
    return d, "CBC_v15_0.mat", read_cbc_mat


def case_mat_nan(tmp: Path):
    d = tmp / "m"
    v = good_mat_vars()
    v["data"][3, [4, 9]] = [np.nan, np.inf]  # NaN is no reading; inf is refused
    save_mat(d / "CBC_stable_v15_0.mat", **v)
    return d, "CBC_stable_v15_0.mat: channel 'alpha' has 1 infinite", read_cbc_mat


def case_mat_none(tmp: Path):
    d = good_folder(tmp / "d")
    (d / "manifest.csv").unlink()
    return d, "d: .mat files expected", read_cbc_mat


CASES = [v for k, v in sorted(globals().items()) if k.startswith("case_")]


@pytest.mark.parametrize("case", CASES, ids=[c.__name__[5:] for c in CASES])
def test_bad_input_raises_one_line_data_error(case: Case, tmp_path: Path) -> None:
    folder, expected, reader = case(tmp_path)
    before = snapshot(folder)
    if before:
        for p in folder.iterdir():
            os.chmod(p, 0o444)  # the reader must open everything read-only
    with pytest.raises(DataError) as err:
        reader(folder)
    msg = str(err.value)
    assert "\n" not in msg
    assert expected in msg
    assert snapshot(folder) == before


def test_nonuniform_message_reports_deviation(tmp_path: Path) -> None:
    d = good_folder(tmp_path / "d")
    table = good_table(11)
    table[5:, 0] += 0.0012  # one dt of 0.0112 against a mean of 0.01012
    write_csv(d, "rec2.csv", "t,h,alpha", table)
    with pytest.raises(DataError, match=r"rec2\.csv: .* dt varies by 10\.7% \(expected < 1%\)"):
        read_interchange(d)


@needs_cbc
def test_real_files_unchanged_after_read(cbc: RecordingSet) -> None:
    before = snapshot(CBC_DIR)
    read_cbc_mat([CBC_DIR / "CBC_stable_v14_9.mat"])
    with pytest.raises(DataError, match="README.md"):
        read_cbc_mat([CBC_DIR / "README.md"])
    assert snapshot(CBC_DIR) == before
