"""Units in column headers and rig descriptions: converted with pint, or refused in one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from bayeshopf.data import (
    ChannelSpec,
    Recording,
    RecordingSet,
    RigDescription,
    read_cbc_mat,
    read_interchange,
)
from bayeshopf.data.units import harmonise
from bayeshopf.errors import DataError

N = 400
DT = 1e-3  # s


def signal(i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time (s), heave (m) and pitch (rad) of recording ``i``."""
    t = np.arange(N) * DT
    w = 2 * np.pi * (3.0 + 0.5 * i)
    return t, (0.01 + 0.002 * i) * np.sin(w * t), 0.05 * np.cos(w * t)


def write(folder: Path, files: dict[str, tuple[str, np.ndarray]]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for i, (name, (header, table)) in enumerate(files.items()):
        np.savetxt(folder / name, table, fmt="%.17g", delimiter=",", header=header, comments="")
        rows.append(f"{name},{14.0 + i},stable")
    (folder / "manifest.csv").write_text("file,mu,branch\n" + "\n".join(rows) + "\n")
    return folder


def test_header_units_are_converted_to_the_first_recordings(tmp_path: Path) -> None:
    t0, h0, a0 = signal(0)
    t1, h1, a1 = signal(1)
    folder = write(tmp_path / "d", {
        "run01.csv": ("t,h [m],alpha [rad]", np.column_stack([t0, h0, a0])),
        # the same kind of recording in ms, mm and degrees
        "run02.csv": ("t [ms],h [mm],alpha [deg]",
                      np.column_stack([1e3 * t1, 1e3 * h1, np.degrees(a1)])),
    })
    rs = read_interchange(folder)
    r = rs[1]
    assert dict(r.units) == {"h": "m", "alpha": "rad"}
    np.testing.assert_allclose(r.t, t1, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(r.channels["h"], h1, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(r.channels["alpha"], a1, rtol=1e-12, atol=1e-15)
    assert r.dt == pytest.approx(DT, rel=1e-9)
    # the first recording is left untouched, bit for bit
    np.testing.assert_array_equal(rs[0].channels["h"], h0)


def test_the_rig_descriptions_unit_wins(tmp_path: Path) -> None:
    t0, h0, a0 = signal(0)
    folder = write(tmp_path / "d", {
        "run01.csv": ("t,h [mm],alpha [rad]", np.column_stack([t0, 1e3 * h0, a0])),
        "run02.csv": ("t,h [cm],alpha [rad]", np.column_stack([t0, 1e2 * h0, a0])),
    })
    rig = RigDescription((ChannelSpec("h", row=0, unit="m"), ChannelSpec("alpha", row=1,
                                                                         unit="rad")))
    rs = read_interchange(folder, rig=rig)
    for r in rs:
        assert r.units["h"] == "m"
        np.testing.assert_allclose(r.channels["h"], h0, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize(("header", "expected"), [
    ("t,h [s],alpha [rad]",
     "run02.csv: column 'h': a unit convertible to 'm' (as in run01.csv) expected ([length]); "
     "found 's' ([time])"),
    ("t,h [furlongz],alpha [rad]", "run02.csv: column 'h': a unit pint knows expected"),
    ("t [mm],h [m],alpha [rad]", "run02.csv: column 't': a unit convertible to 's'"),
])
def test_wrong_units_are_refused_in_one_line(tmp_path: Path, header: str, expected: str) -> None:
    t0, h0, a0 = signal(0)
    table = np.column_stack([t0, h0, a0])
    folder = write(tmp_path / "d", {"run01.csv": ("t,h [m],alpha [rad]", table),
                                    "run02.csv": (header, table)})
    with pytest.raises(DataError) as err:
        read_interchange(folder)
    msg = str(err.value)
    assert "\n" not in msg and expected in msg, msg


def test_recording_set_refuses_unconverted_units() -> None:
    t, h, a = signal(0)
    r1 = Recording(t, {"h": h, "alpha": a}, {"h": "m", "alpha": "rad"}, 14.0, "stable", "a")
    r2 = Recording(t, {"h": 1e3 * h, "alpha": a}, {"h": "mm", "alpha": "rad"}, 15.0, "stable",
                   "b")
    with pytest.raises(DataError, match=r"b: channel 'h' in 'm' expected \(as in a\); found 'mm'"):
        RecordingSet((r1, r2), ("h", "alpha"))
    rs = RecordingSet(harmonise([r1, r2]), ("h", "alpha"))
    np.testing.assert_allclose(rs[1].channels["h"], h, rtol=1e-12, atol=1e-15)


def test_a_time_column_in_the_wrong_unit_is_caught_by_the_sample_rate(tmp_path: Path) -> None:
    t0, h0, a0 = signal(0)
    folder = write(tmp_path / "d", {
        "run01.csv": ("t,h [m],alpha [rad]", np.column_stack([t0, h0, a0])),
        "run02.csv": ("t,h [m],alpha [rad]", np.column_stack([t0, h0, a0])),
        "run03.csv": ("t,h [m],alpha [rad]", np.column_stack([1e3 * t0, h0, a0])),  # ms, unlabelled
    })
    with pytest.raises(DataError) as err:
        read_interchange(folder)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("run03.csv: a sample rate within a factor 100"), msg
    assert "found 1 Hz" in msg and "t [ms]" in msg


def test_the_rig_descriptions_time_unit(tmp_path: Path) -> None:
    n = 300
    t_ms = (1 + np.arange(n)) * 0.2  # 5 kHz in milliseconds
    data = np.vstack([np.sin(0.05 * t_ms), np.cos(0.05 * t_ms)])
    scipy.io.savemat(tmp_path / "run_stable.mat", {"data": data, "time": t_ms[None, :],
                                                   "mu": np.array([[3.0]])})
    chans = (ChannelSpec("h", row=0, unit="mm"), ChannelSpec("alpha", row=1, unit="deg"))
    r = read_cbc_mat(tmp_path, RigDescription(chans, mu_variable="mu", time_unit="ms"))[0]
    np.testing.assert_allclose(r.t, t_ms / 1e3, rtol=1e-12)
    assert r.dt == pytest.approx(2e-4) and dict(r.units) == {"h": "mm", "alpha": "deg"}
    bad = RigDescription(chans, mu_variable="mu", time_unit="V")
    with pytest.raises(DataError, match=r"run_stable\.mat: column 't': a unit convertible to 's'"):
        read_cbc_mat(tmp_path, bad)
