"""One reader for every format; the control channel through a manifest; names and reprs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

import bayeshopf.data.io as data_io
from bayeshopf.data import (
    Recording,
    RecordingSet,
    read_interchange,
    read_recordings,
    write_interchange,
)
from bayeshopf.data.datasets import FLUTTER_CBC_ENV
from bayeshopf.errors import DataError

CBC_DIR = (Path(__file__).parents[1] / ".." / "shared" / "data" / "flutter_cbc").resolve()
DATA_PKG = Path(data_io.__file__).parent


def save_mat(path: Path, mu: float) -> None:
    n = 200
    t = (1 + np.arange(n)) / 5000.0
    data = np.vstack([np.sin(50 * t), np.zeros(n), 0.1 * np.cos(50 * t), 0.7 + np.cos(50 * t),
                      np.zeros(n)])
    scipy.io.savemat(path, {"data": data, "time": t[None, :], "Wind_sped": np.array([[mu]])})


def mat_manifest(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    save_mat(folder / "CBC_a.mat", 15.0)
    save_mat(folder / "CBC_b.mat", 16.0)
    (folder / "manifest.csv").write_text("file,mu,branch\nCBC_a.mat,15.0,stable\n"
                                         "CBC_b.mat,16.0,unstable\n")
    return folder


def three(names: tuple[str, ...] = ("rec1", "rec2", "rec3")) -> RecordingSet:
    t = np.arange(50) * 1e-3
    recs = [Recording(t, {"h": np.sin(30 * t + i), "alpha": np.cos(30 * t), "u": 0 * t},
                      {"h": "m", "alpha": "rad"}, 14.0 + i, "stable" if i else "unstable", n)
            for i, n in enumerate(names)]
    return RecordingSet(tuple(recs), ("h", "alpha"), "airspeed", "m/s", control="u")


def test_the_rig_descriptions_control_survives_a_manifest(tmp_path: Path) -> None:
    folder = mat_manifest(tmp_path / "d")
    (folder / "rig.toml").write_text((DATA_PKG / "flutter_cbc.toml").read_text())
    assert read_recordings(folder).control == "actuator"
    assert read_interchange(folder).control == "actuator"  # the built-in description's
    # a planar pair that takes the control channel leaves no control
    assert read_recordings(folder, planar=("h", "actuator")).control is None


def test_names_round_trip_without_gaining_csv(tmp_path: Path) -> None:
    rs = three()
    back = read_interchange(write_interchange(rs, tmp_path / "o"))
    assert back.names == ["rec1", "rec2", "rec3"]
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == [
        "manifest.csv", "rec1.csv", "rec2.csv", "rec3.csv"]
    odd = three(("a,b", 'say "hi"', "rec3.csv"))
    assert read_interchange(write_interchange(odd, tmp_path / "p")).names == list(odd.names)


def test_repr_is_short_and_counts_are_singular_when_one() -> None:
    rs = three()
    text = repr(rs)
    assert text == ("RecordingSet(3 recordings: 2 stable, 1 unstable; airspeed 14 to 16 m/s; "
                    "planar (h, alpha), control u; channels h [m], alpha [rad], u)")
    assert "array" not in repr(rs[0]) and len(repr(rs[0])) < 200
    one = rs.subset([0])
    assert one.size_text == "1 recording" and "1 recording:" in repr(one)


def test_read_recordings_reads_every_format(tmp_path: Path, monkeypatch) -> None:
    rs = three()
    write_interchange(rs, tmp_path / "csv")
    assert read_recordings(tmp_path / "csv").names == rs.names
    assert read_recordings(tmp_path / "csv" / "manifest.csv").names == rs.names
    mats = tmp_path / "mats"
    mats.mkdir()
    save_mat(mats / "CBC_stable_v15_0.mat", 15.0)
    save_mat(mats / "CBC_unstable_v16_0.mat", 16.0)
    assert read_recordings(mats).names == ["CBC_stable_v15_0.mat", "CBC_unstable_v16_0.mat"]
    assert len(read_recordings(mats / "CBC_stable_v15_0.mat")) == 1
    assert read_recordings(rs, planar=("h", "u")).control is None
    with pytest.raises(DataError, match="data set name"):
        read_recordings(3.5)
    if CBC_DIR.is_dir():
        monkeypatch.setenv(FLUTTER_CBC_ENV, str(CBC_DIR))
        assert len(read_recordings("flutter_cbc")) == 7


def test_no_data_module_is_over_600_lines_and_io_reexports() -> None:
    sizes = {p.name: len(p.read_text().splitlines()) for p in DATA_PKG.glob("*.py")}
    assert max(sizes.values()) <= 600, sizes
    for name in ("load_recordings", "read_cbc_mat", "read_interchange", "write_interchange",
                 "dropped_report", "read_recordings"):
        assert callable(getattr(data_io, name))
