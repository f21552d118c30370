"""The CBC controller's convergence, as a rig description names it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from bayeshopf.data import (
    Convergence,
    RigDescription,
    converged_only,
    load_recordings,
    read_cbc_mat,
    unconverged,
)
from bayeshopf.data.convergence import ConvergenceSpec
from bayeshopf.data.screening import convergence_report
from bayeshopf.errors import DataError

CBC_DIR = (Path(__file__).parents[1] / ".." / "shared" / "data" / "flutter_cbc").resolve()

RIG = """
name = "conv rig"
mu_variable = "Wind_sped"
planar = ["h", "alpha"]
control = "u"

[convergence]
success = "success"
error = "error1"
tolerance = "error_tol"

[channels.h]
row = 0
unit = "m"

[channels.alpha]
row = 1
unit = "rad"

[channels.u]
row = 2
unit = "V"
"""


def save(folder: Path, name: str, mu: float, **extra: float) -> None:
    n = 400
    t = (1 + np.arange(n)) / 2000.0
    data = np.vstack([np.sin(40 * t), np.cos(40 * t), 0.1 * np.sin(40 * t)])
    scipy.io.savemat(folder / name, {"data": data, "time": t[None, :],
                                     "Wind_sped": np.array([[mu]]),
                                     **{k: np.array([[v]]) for k, v in extra.items()}})


def test_unconverged_recordings_are_marked_and_left_out(tmp_path: Path) -> None:
    (tmp_path / "rig.toml").write_text(RIG)
    save(tmp_path, "stable_a.mat", 14.0, error1=0.001, error_tol=0.01, success=1)
    save(tmp_path, "unstable_b.mat", 14.5, error1=-0.33, error_tol=0.01, success=1)
    save(tmp_path, "unstable_c.mat", 15.0, error1=0.002, error_tol=0.01, success=0)
    save(tmp_path, "unstable_d.mat", 15.5)  # convergence not recorded
    rs = load_recordings(tmp_path)
    conv = {r.name: r.convergence for r in rs}
    assert conv["stable_a.mat"] == Convergence(success=True, error=0.001, tolerance=0.01)
    assert conv["unstable_b.mat"] == Convergence(success=True, error=-0.33, tolerance=0.01)
    assert conv["unstable_d.mat"] is None
    assert [rs[i].name for i in unconverged(rs)] == ["unstable_b.mat", "unstable_c.mat"]
    report = convergence_report(rs)
    assert report[0] == ("unstable_b.mat: the controller did not converge (error -0.33 against "
                         "tolerance 0.01, success 1); not an orbit of the uncontrolled system")
    kept = converged_only(rs)
    assert kept.names == ["stable_a.mat", "unstable_d.mat"] and kept.control == "u"


def test_only_the_listed_branches_must_converge(tmp_path: Path) -> None:
    text = RIG.replace('tolerance = "error_tol"', 'tolerance = 0.05\nbranches = ["unstable"]')
    (tmp_path / "rig.toml").write_text(text)
    save(tmp_path, "stable_a.mat", 14.0, error1=0.08)
    save(tmp_path, "unstable_b.mat", 14.5, error1=0.04)
    rs = load_recordings(tmp_path)
    assert rs[0].convergence == Convergence(error=0.08, tolerance=0.05, required=False)
    assert not rs[0].convergence.converged and unconverged(rs) == ()


@pytest.mark.parametrize(("table", "expected"), [
    ({"error": "error1"}, "[convergence]: 'error' and 'tolerance' expected together"),
    ({"tolerance": 0.1}, "[convergence]: 'success' or 'error'"),
    ({"success": "ok", "branches": ["up"]}, "[convergence]: 'branches' must list"),
    ({"success": "ok", "limit": 1}, "[convergence]: keys among branches, error, success, "
                                    "tolerance expected; found 'limit'"),
])
def test_bad_convergence_table_is_one_line(table: dict, expected: str) -> None:
    d = {"channels": {"h": {"row": 0}, "alpha": {"row": 1}}, "convergence": table}
    with pytest.raises(DataError) as err:
        RigDescription.from_dict(d, source="rig.toml")
    assert str(err.value).startswith("rig.toml: ") and expected in str(err.value), err.value


def test_convergence_round_trips_through_a_rig_file() -> None:
    rig = RigDescription.flutter_cbc()
    assert rig.convergence == ConvergenceSpec(success="success", error="error1",
                                              tolerance="error_tol", branches=("unstable",))
    assert RigDescription.from_dict(rig.to_dict()) == rig


@pytest.mark.skipif(not CBC_DIR.is_dir(), reason=f"flutter CBC recordings not found at {CBC_DIR}")
def test_the_authors_files_carry_their_convergence() -> None:
    rs = read_cbc_mat(CBC_DIR)
    for r in rs:
        raw = scipy.io.loadmat(CBC_DIR / r.name, variable_names=["error1", "error_tol", "success"])
        assert r.convergence == Convergence(
            success=bool(raw["success"].item()), error=float(raw["error1"].item()),
            tolerance=float(raw["error_tol"].item()), required=r.branch == "unstable")
    # every controller-held (unstable) recording converged: none is left out
    assert unconverged(rs) == () and converged_only(rs) is rs
