"""Missing samples: NaN, empty cells and sentinels are "no reading" everywhere."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from bayeshopf.data import Recording, RecordingSet, read_cbc_mat, read_interchange
from bayeshopf.features.harmonics import extract_harmonics

N = 2000
DT = 1e-3  # s
F = 5.0  # Hz


def table(i: int) -> np.ndarray:
    t = np.arange(N) * DT
    w = 2 * np.pi * (F + 0.2 * i)
    return np.column_stack([t, (0.01 + 0.002 * i) * np.sin(w * t), 0.05 * np.cos(w * t)])


def write_folder(folder: Path, texts: list[str], meta: str = "") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for i, text in enumerate(texts):
        (folder / f"run{i}.csv").write_text(text)
        rows.append(f"run{i}.csv,{14.0 + i},{'stable' if i % 2 == 0 else 'unstable'}")
    (folder / "manifest.csv").write_text(meta + "file,mu,branch\n" + "\n".join(rows) + "\n")
    return folder


def csv_text(tab: np.ndarray, holes: dict[int, str] | None = None) -> str:
    """CSV text of ``tab``; ``holes`` maps a row to what its h cell holds instead."""
    lines = ["t,h [m],alpha [rad]"]
    for k, (t, h, a) in enumerate(tab):
        cell = (holes or {}).get(k, f"{h:.17g}")
        lines.append(f"{t:.17g},{cell},{a:.17g}")
    return "\n".join(lines) + "\n"


def test_empty_cell_and_nan_are_left_out_and_features_skip_them(tmp_path: Path) -> None:
    tabs = [table(i) for i in range(3)]
    holes = {10: "", 500: "nan", 501: "NaN", 1400: ""}
    gappy = write_folder(tmp_path / "gappy", [csv_text(tabs[0], holes),
                                               *(csv_text(t) for t in tabs[1:])])
    clean = write_folder(tmp_path / "clean", [csv_text(t) for t in tabs])
    rs = read_interchange(gappy)
    r = rs[0]
    assert r.dropped == len(holes) and r.t.size == N - len(holes)
    keep = np.setdiff1d(np.arange(N), list(holes))
    np.testing.assert_array_equal(r.t, tabs[0][keep, 0])
    np.testing.assert_array_equal(r.channels["h"], tabs[0][keep, 1])
    assert r.has_gaps and r.dt == pytest.approx(DT)
    # the least-squares features need no filling: a record with 4 of 2000 samples
    # missing gives the orbit of the full record
    f_gap = extract_harmonics(rs)
    f_full = extract_harmonics(read_interchange(clean))
    assert np.all(np.isfinite(f_gap.coeffs))
    np.testing.assert_allclose(f_gap.omega, 2 * np.pi * (F + 0.2 * np.arange(3)), rtol=1e-6)
    np.testing.assert_allclose(f_gap.amplitude, f_full.amplitude, rtol=1e-6)


def test_manifest_sentinel_is_no_reading(tmp_path: Path) -> None:
    tabs = [table(i) for i in range(2)]
    folder = write_folder(tmp_path / "d", [csv_text(tabs[0], {7: "-9999"}), csv_text(tabs[1])],
                          meta="# missing: -9999\n")
    rs = read_interchange(folder)
    assert [r.dropped for r in rs] == [1, 0]
    assert not np.any(rs[0].channels["h"] == -9999)


def test_recording_built_from_arrays_leaves_nan_out() -> None:
    tab = table(0)
    h = tab[:, 1].copy()
    h[[3, 4]] = np.nan
    r = Recording(tab[:, 0], {"h": h, "alpha": tab[:, 2]}, {"h": "m"}, 14.0, "stable", "r")
    assert r.dropped == 2 and r.t.size == N - 2
    assert np.all(np.isfinite(r.channels["h"]))
    assert RecordingSet((r,), ("h", "alpha"))[0].dropped == 2


def test_nan_in_a_mat_file_is_no_reading_without_declaring_it(tmp_path: Path) -> None:
    n = 500
    t = (1 + np.arange(n)) / 5000.0
    data = np.vstack([np.sin(50 * t), np.zeros(n), np.zeros(n), 0.7 + np.cos(50 * t), np.zeros(n)])
    data[3, 9] = np.nan
    scipy.io.savemat(tmp_path / "CBC_stable_v15_0.mat",
                     {"data": data, "time": t[None, :], "Wind_sped": np.array([[15.0]])})
    r = read_cbc_mat(tmp_path)[0]
    assert r.dropped == 1 and r.t.size == n - 1
    assert 9 not in np.flatnonzero(np.isin(t, r.t))
