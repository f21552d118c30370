"""The command line: bad input gives one clear line, a non-zero exit and untouched inputs."""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bayeshopf.cli.main import main
from bayeshopf.data import RecordingSet, write_interchange
from bayeshopf.data.synthetic import demo_system


def digest(folder: Path) -> dict[str, str]:
    """Content hash and mtime of every file below ``folder``."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        + str(p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.fixture(scope="module")
def good_data(tmp_path_factory) -> Path:
    rs, _ = demo_system(seed=3, fast=True)
    return write_interchange(rs, tmp_path_factory.mktemp("data") / "demo")


def _rewrite_csv(folder: Path, transform) -> None:
    """Apply ``transform(header, table) -> (header, table)`` to the first recording's CSV."""
    manifest = (folder / "manifest.csv").read_text().splitlines()
    rows = [r for r in manifest if r and not r.startswith("#")]
    name = rows[1].split(",")[0]
    path = folder / name
    lines = path.read_text().splitlines()
    header, table = lines[0], np.loadtxt(lines[1:], delimiter=",")
    header, table = transform(header, table)
    np.savetxt(path, table, fmt="%.17g", delimiter=",", header=header, comments="")


def _missing_column(folder: Path) -> str:
    def drop(h, t):
        cols = h.split(",")
        return ",".join(cols[:2]), t[:, :2]

    _rewrite_csv(folder, drop)
    return "planar pair"


def _non_uniform_time(folder: Path) -> str:
    def jitter(h, t):
        t = t.copy()
        t[50:, 0] += 0.5 * (t[1, 0] - t[0, 0])
        return h, t

    _rewrite_csv(folder, jitter)
    return "uniform"


def _unknown_branch(folder: Path) -> str:
    m = folder / "manifest.csv"
    m.write_text(m.read_text().replace(",unstable", ",unstabel", 1))
    return "unstabel"


def _single_recording(folder: Path) -> str:
    m = folder / "manifest.csv"
    lines = m.read_text().splitlines()
    keep = [ln for ln in lines if ln.startswith("#") or ln.startswith("file,")]
    data = [ln for ln in lines if ln not in keep]
    m.write_text("\n".join(keep + data[:1]) + "\n")
    return "two or more distinct"


def _unreadable_file(folder: Path) -> str:
    m = folder / "manifest.csv"
    rows = [r for r in m.read_text().splitlines() if r and not r.startswith("#")]
    (folder / rows[1].split(",")[0]).write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00garbage\xff\xfe")
    return rows[1].split(",")[0]


CASES = {
    "missing column": _missing_column,
    "non-uniform time": _non_uniform_time,
    "unknown branch label": _unknown_branch,
    "single recording": _single_recording,
    "unreadable file": _unreadable_file,
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_one_line_error_inputs_untouched(case, good_data, tmp_path, capsys):
    data = tmp_path / "data"
    shutil.copytree(good_data, data)
    needle = CASES[case](data)
    before = digest(data)
    out = tmp_path / "out"
    code = main(["fit", str(data), "--out", str(out), "--fast", "--quiet", "--no-figures"])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    assert needle.lower() in err.lower(), err
    assert digest(data) == before
    assert not out.exists()


def test_missing_data_folder(tmp_path, capsys):
    code = main(["fit", str(tmp_path / "nope"), "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "nope" in err


def test_console_script_no_traceback(good_data, tmp_path):
    """The installed entry point, in a subprocess: exit code and stderr."""
    data = tmp_path / "data"
    shutil.copytree(good_data, data)
    _unknown_branch(data)
    exe = Path(sys.executable).with_name("bayeshopf")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "bayeshopf.cli.main"]
    r = subprocess.run(cmd + ["fit", str(data), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_help_everywhere(capsys):
    from bayeshopf.cli.main import build_parser

    commands = list(build_parser()._subparsers._group_actions[0].choices)
    assert {"demo", "fit", "predict", "download", "simulate", "discrepancy"} <= set(commands)
    for argv in [["--help"]] + [[c, "--help"] for c in commands]:
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 0
        out = capsys.readouterr().out
        assert "%%" not in out and "%(" not in out, (argv, out)
        assert "usage: bayeshopf" in out
        if argv[0] == "demo":
            assert "1% noise" in out and "90% intervals" in out


def test_version(capsys):
    import bayeshopf

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.strip() == f"bayeshopf {bayeshopf.__version__}"


@pytest.mark.parametrize("where", ["before", "after"])
def test_debug_before_or_after_the_subcommand(where, monkeypatch, capsys):
    from bayeshopf import fit_folder

    def broken(folder):
        raise RuntimeError("boom\nsecond line")

    monkeypatch.setattr(fit_folder, "load_fit", broken)
    argv = ["predict", "somewhere", "--mu", "16"]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err == ("bayeshopf predict: internal error: RuntimeError: boom "
                   "(rerun with --debug for details)")
    argv = ["--debug"] + argv if where == "before" else argv + ["--debug"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "RuntimeError: boom" in err


@pytest.mark.parametrize("argv, found", [
    (["fit", "--out", "OUT"], "found neither"),
    (["fit", "DATA", "--dataset", "flutter_cbc", "--out", "OUT"], "found both"),
])
def test_fit_needs_data_or_dataset(argv, found, tmp_path, capsys):
    argv = [str(tmp_path / a) if a in ("OUT", "DATA") else a for a in argv]
    assert main(argv + ["--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--dataset flutter_cbc" in err and found in err
    assert not (tmp_path / "OUT").exists()


def test_fit_dataset_downloads_from_the_mirror(user_without_shared, tmp_path, monkeypatch,
                                               capsys):
    """``fit --dataset flutter_cbc`` without ../shared: the rig's 7 recordings, downloaded."""
    from bayeshopf.cli import fit as cli
    from bayeshopf.errors import FitError

    url, served, data_dir = user_without_shared
    seen = {}

    def stop(rs, criticality, args, out, **kw):   # the fit itself is tested elsewhere
        seen.update(rs=rs, criticality=criticality, out=out)
        raise FitError("stopped by the test")

    monkeypatch.setattr(cli, "run_hybrid", stop)
    out = tmp_path / "rig-fit"
    assert main(["fit", "--dataset", "flutter_cbc", "--out", str(out), "--planar", "alpha",
                 "h"]) == 2
    assert "stopped by the test" in capsys.readouterr().err
    rs = seen["rs"]
    assert len(rs) == 7 and rs.planar == ("alpha", "h") and seen["criticality"] == "subcritical"
    assert len({p for p in served if p.endswith(".mat")}) == 7
    assert len(list((data_dir / "flutter_cbc").glob("CBC_*.mat"))) == 7


def test_download_command(user_without_shared, tmp_path, capsys):
    to = tmp_path / "here"
    assert main(["download", "flutter_cbc", "--to", str(to)]) == 0
    assert capsys.readouterr().out.strip() == str(to)
    assert len(list(to.glob("CBC_*.mat"))) == 7
    assert main(["download", "flutter_cbc"]) == 0
    assert capsys.readouterr().out.strip() == str(user_without_shared[2] / "flutter_cbc")


@pytest.fixture(scope="module")
def fitted(good_data, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fit") / "out"
    # the model without the discrepancy, whose programs compile faster (the default model
    # goes through the CLI in test_readme's demo and test_rig_description's second rig)
    assert main(["fit", str(good_data), "--out", str(out), "--fast", "--quiet", "--seed", "1",
                 "--inference", "svi", "--nuts-check", "--no-discrepancy", "--nn-width",
                 "16"]) == 0
    return out


def test_fit_writes_summary_posterior_figures(fitted, good_data):
    s = json.loads((fitted / "summary.json").read_text())
    assert s["criticality"] == "subcritical"
    for k in ("mu0", "a2", "mu_fold"):
        lo, hi = s[k]["ci90"]
        assert lo <= s[k]["median"] <= hi
    assert s["amplitude_units"] == "m"
    assert len(s["recordings"]) == 7
    for r in s["recordings"]:
        assert set(r) >= {"file", "mu", "branch", "amplitude", "predicted"}
        assert r["predicted"]["ci90"][0] <= r["predicted"]["median"] <= r["predicted"]["ci90"][1]
    assert s["core"] == "collapsed"
    # --inference svi --nuts-check: SVI's intervals against NUTS on the same model
    chk = s["nuts_check"]
    assert set(chk["sites"]) == {"mu0", "a2", "mu_fold"}
    for v in chk["sites"].values():
        gap = max(abs(a - b) for a, b in zip(v["reference"], v["other"], strict=True))
        assert v["end_gap_fraction"] == pytest.approx(
            gap / (v["reference"][1] - v["reference"][0]))
        assert v["agree"] == (v["end_gap_fraction"] <= 0.25)
    diag = s["diagnostics"]
    assert diag["posterior"]["method"] == "svi" and "elbo_plateau" in diag["posterior"]
    assert [e["name"] for e in s["orbit_error"]] == [r["file"] for r in s["recordings"]]
    assert all(set(r["orbit_error"]) == {"relative", "spread", "ok", "by_harmonic"}
               for r in s["recordings"])
    assert (fitted / "posterior.nc").stat().st_size > 1000
    pngs = sorted(p.name for p in (fitted / "figures").glob("*.png"))
    assert pngs == sorted(["bifurcation.png", "phase_portraits.png", "ppc.png", "frequency.png",
                           "time_series.png"])
    assert not [p for p in fitted.parent.iterdir() if p.name.startswith(".")]


def test_fit_refuses_non_empty_out_without_force(fitted, good_data, capsys):
    before = digest(fitted)
    code = main(["fit", str(good_data), "--out", str(fitted), "--fast", "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "not empty" in err and "--force" in err
    assert digest(fitted) == before


def test_predict_json_matches_summary(fitted, capsys):
    s = json.loads((fitted / "summary.json").read_text())
    rec = s["recordings"][0]
    assert main(["predict", str(fitted), "--mu", str(rec["mu"]), "--branch", rec["branch"],
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["schema_version"] == 1 and doc["command"] == "predict"
    assert doc["branch"] == rec["branch"] and doc["ci"] == 0.9
    (out,) = doc["predictions"]
    assert out["mu"] == rec["mu"] and out["exists"] is True
    lo, hi = out["amplitude"]["lo"], out["amplitude"]["hi"]
    assert lo <= out["amplitude"]["median"] <= hi and out["amplitude"]["ci"] == 0.9
    # the curve's band at a training μ is the one in the summary
    assert out["amplitude"]["median"] == pytest.approx(rec["curve"]["median"], rel=1e-6)
    # the collapsed core models the frequency too: its band at a training μ holds a median
    # within 5% of that recording's measured frequency
    assert s["core"] == "collapsed"
    freq = out["frequency"]
    assert freq["lo"] <= freq["median"] <= freq["hi"], freq
    assert freq["median"] == pytest.approx(abs(rec["frequency_hz"]), rel=0.05), (freq, rec)


def test_predict_several_mu_table_csv_json(fitted, capsys):
    import csv
    import io

    s = json.loads((fitted / "summary.json").read_text())
    mu0 = s["mu0"]["median"]
    lo_mu = min(r["mu"] for r in s["recordings"] if r["branch"] == "stable")
    start, step = round(lo_mu, 2), 0.25
    spec = f"{start}:{start + 1}:{step}"                           # 5 values, STOP included
    mus = [start + step * k for k in range(5)]
    assert main(["predict", str(fitted), "--mu", spec, "--csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert [float(r["mu"]) for r in rows] == pytest.approx(mus)
    amp = [[float(r[f"amplitude_{k} [m]"]) for k in ("lo", "median", "hi")] for r in rows]
    assert all(lo <= m <= hi for lo, m, hi in amp)
    assert all(r["ci"] == "0.9" and float(r["p_exists"]) > 0.5 for r in rows)
    # each row is the single-μ prediction
    assert main(["predict", str(fitted), "--mu", str(mus[2]), "--json"]) == 0
    one = json.loads(capsys.readouterr().out)["predictions"][0]
    assert one["amplitude"]["median"] == pytest.approx(amp[2][1], rel=1e-12)
    # --ci: a narrower interval inside the 90% one; the same keys, the level in "ci"
    assert main(["predict", str(fitted), "--mu", str(mus[0]), str(mus[1]), "--ci", "0.5",
                 "--json"]) == 0
    many = json.loads(capsys.readouterr().out)["predictions"]
    assert [m["mu"] for m in many] == pytest.approx(mus[:2])
    for m, a in zip(many, amp, strict=False):
        lo, hi = m["amplitude"]["lo"], m["amplitude"]["hi"]
        assert a[0] < lo <= m["amplitude"]["median"] <= hi < a[2]
        assert m["amplitude"]["ci"] == m["frequency"]["ci"] == 0.5
    # the table: a header and one line per μ; beyond the Hopf point the unstable branch is "—"
    mu_u = next(r["mu"] for r in s["recordings"] if r["branch"] == "unstable")
    assert main(["predict", str(fitted), "--mu", str(mu_u), str(mu0 + 5), "--branch",
                 "unstable"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 4 and "90% interval" in lines[1]
    assert "—" not in lines[2] and "—" in lines[3]


def test_fit_ci_level_reaches_summary_and_table(fitted, good_data, tmp_path, monkeypatch,
                                                capsys):
    """``fit --ci 0.8``: the saved and printed intervals at 80% (the fit itself reused)."""
    from bayeshopf import fit_folder, posterior

    post = fit_folder.load_fit(fitted).posterior
    monkeypatch.setattr(posterior, "fit_hybrid", lambda rs, crit, **kw: post)
    out = tmp_path / "ci80"
    assert main(["fit", str(good_data), "--out", str(out), "--quiet", "--no-figures",
                 "--ci", "0.8"]) == 0
    s = json.loads((out / "summary.json").read_text())
    ref = json.loads((fitted / "summary.json").read_text())
    assert s["ci"] == 0.8 and "ci80" in s["mu0"] and "ci90" not in s["mu0"]
    lo80, hi80 = s["mu0"]["ci80"]
    lo90, hi90 = ref["mu0"]["ci90"]
    assert lo90 < lo80 < hi80 < hi90
    printed = capsys.readouterr().out
    assert "80% interval" in printed and "predicted (80%)" in printed
    assert "inside their 80% predictive intervals" in printed
    # without the discrepancy a fixed extra model error away from the recordings, 0.1
    assert not post.spec.has_discrepancy and post.extrapolation_scale == 0.1
    assert s["diagnostics"]["fit"]["extrapolation_scale"] == {
        "scale": 0.1, "chosen_by": "model without the discrepancy"}
    assert ("bands of new measurements away from the recordings: model-error scale 0.1 "
            "(the model without the discrepancy)") in printed
    assert main(["fit", str(good_data), "--out", str(tmp_path / "o"), "--ci", "90"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--ci 90" in err


@pytest.mark.parametrize("args, needle", [
    (["--mu", "15:14:0.5"], "--mu 15:14:0.5"),
    (["--mu", "a"], "--mu a"),
    (["--mu", "15", "--ci", "1.5"], "--ci 1.5"),
    (["--mu", "15", "--json", "--csv"], "both"),
])
def test_predict_bad_arguments_one_line(args, needle, fitted, capsys):
    assert main(["predict", str(fitted)] + args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err


def test_predict_unstable_beyond_hopf_is_clear_error(fitted, capsys):
    assert main(["predict", str(fitted), "--mu", "40", "--branch", "unstable"]) == 2
    err = capsys.readouterr().err.strip()
    assert "does not exist" in err and len(err.splitlines()) == 1


def test_predict_missing_fit_folder(tmp_path, capsys):
    assert main(["predict", str(tmp_path), "--mu", "17"]) == 2
    assert "summary.json" in capsys.readouterr().err


def test_removed_and_misused_options_are_one_line_errors(good_data, tmp_path, capsys):
    with pytest.raises(SystemExit):           # --speed went with the legacy core: Ω is built in
        main(["fit", str(good_data), "--out", str(tmp_path / "o"), "--speed"])
    assert "unrecognized arguments: --speed" in capsys.readouterr().err
    code = main(["fit", str(good_data), "--out", str(tmp_path / "o"), "--nuts-check", "--quiet",
                 "--inference", "nuts"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "needs --inference importance (the default) or svi" in err
    with pytest.raises(SystemExit):           # the discrepancy is the default: --no-discrepancy
        main(["fit", str(good_data), "--out", str(tmp_path / "o"), "--discrepancy"])
    assert "unrecognized arguments: --discrepancy" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_exact_loo_needs_criticality_auto(good_data, tmp_path, capsys):
    code = main(["fit", str(good_data), "--out", str(tmp_path / "o"), "--exact-loo", "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "--criticality auto" in err and "got --criticality sub" in err
    assert not (tmp_path / "o").exists()


def test_predict_on_a_fit_of_the_removed_core_is_a_one_line_error(tmp_path, capsys):
    old = tmp_path / "old_fit"
    old.mkdir()
    (old / "summary.json").write_text("{}")
    (old / "model.json").write_text('{"criticality": "subcritical"}')   # no "core"
    (old / "posterior.nc").write_bytes(b"")
    assert main(["predict", str(old), "--mu", "16"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "legacy inference core" in err and "model.json" in err


@pytest.mark.parametrize("flag", [[], ["--no-control"]])
def test_no_control_reaches_the_fit(flag, tmp_path, monkeypatch, capsys):
    """The built-in rig names its actuator as the control channel; ``--no-control``
    fits without the term."""
    import bayeshopf.posterior
    from bayeshopf.errors import FitError

    CBC_DIR = (Path(__file__).parents[1] / ".." / "shared" / "data" / "flutter_cbc").resolve()
    if not CBC_DIR.is_dir():
        pytest.skip(f"flutter CBC recordings not found at {CBC_DIR}")
    seen = {}

    def stop(rs, criticality, **kw):   # the fit itself is tested elsewhere
        seen.update(rs=rs, **kw)
        raise FitError("stopped by the test")

    monkeypatch.setattr(bayeshopf.posterior, "fit_hybrid", stop)
    assert main(["fit", str(CBC_DIR), "--out", str(tmp_path / "o"), *flag]) == 2
    err = capsys.readouterr().err
    assert "stopped by the test" in err
    assert seen["rs"].control == "actuator"
    assert seen["settings"].control is (not flag)
    assert ("the control channel 'actuator' as a measured input" in err) is (not flag)


def test_control_channel_named_on_the_command_line(tmp_path, monkeypatch, capsys):
    """``--control`` names the control channel of an interchange folder (a CSV column);
    a channel that is not there is a one-line error; it excludes ``--no-control``."""
    from dataclasses import replace

    import bayeshopf.posterior
    from bayeshopf.data.recording import RecordingSet
    from bayeshopf.errors import FitError

    rs, _ = demo_system(seed=3, fast=True)
    recs = tuple(replace(r, channels={**r.channels, "u": np.cos(15.0 * r.t)},
                         units={**r.units, "u": "V"}) for r in rs)
    folder = write_interchange(RecordingSet(recs, rs.planar, rs.mu_label, rs.mu_units),
                               tmp_path / "held")
    seen = {}

    def stop(rs, criticality, **kw):   # the fit itself is tested elsewhere
        seen.update(rs=rs, **kw)
        raise FitError("stopped by the test")

    monkeypatch.setattr(bayeshopf.posterior, "fit_hybrid", stop)
    assert main(["fit", str(folder), "--out", str(tmp_path / "a"), "--control", "u"]) == 2
    assert "stopped by the test" in capsys.readouterr().err
    assert seen["rs"].control == "u" and seen["settings"].control is True
    assert main(["fit", str(folder), "--out", str(tmp_path / "b"), "--control", "v"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("bayeshopf fit: error: --control: ") \
        and "control channel 'v' expected; found channels" in err, err
    with pytest.raises(SystemExit):
        main(["fit", str(folder), "--out", str(tmp_path / "c"), "--control", "u",
              "--no-control"])


@pytest.mark.parametrize("n_inside, figures", [(3, True), (7, False)])
def test_fit_leave_one_out_reaches_summary_diagnostics_and_table(fitted, good_data, tmp_path,
                                                                 monkeypatch, capsys, n_inside,
                                                                 figures):
    """``fit --leave-one-out``: the refits get the fit's recordings (so that each refit's frame
    is built without the recording it predicts), criticality, settings and seed; their
    check joins ``diagnostics`` and warns when the coverage is improbable (the
    fit itself and the refits are replaced here; both are tested in test_validation)."""
    from bayeshopf import fit_folder, posterior, validation

    post = fit_folder.load_fit(fitted).posterior
    monkeypatch.setattr(posterior, "fit_hybrid", lambda rs, crit, **kw: post)
    seen = {}

    def refits(data, criticality, **kw):
        seen.update(data=data, criticality=criticality, **kw)
        features = post.features
        names, folds = features.names, []
        for i, name in enumerate(names):
            a = float(features.amplitude[i])
            lo, hi = (0.9 * a, 1.1 * a) if i < n_inside else (1.2 * a, 1.4 * a)
            p = validation.HeldOut(median=0.5 * (lo + hi), lo=lo, hi=hi, p_exists=1.0,
                                   mu_fold=(15.0, 14.9, 15.1), mu0=(18.0, 17.9, 18.1))
            folds.append(validation.HeldOutFold(
                name=name, mu=float(features.mu[i]), branch="stable", measured=a,
                measured_sd=0.0, predictions={"bayes": p},
                fit=post if kw["keep_fits"] else None))
        return validation.LeaveOneOut(folds=tuple(folds), methods=("bayes",))

    monkeypatch.setattr(validation, "leave_one_out", refits)
    out = tmp_path / "loo"
    assert main(["fit", str(good_data), "--out", str(out), "--quiet", "--seed", "1",
                 "--leave-one-out", *([] if figures else ["--no-figures"])]) == 0
    assert seen["keep_fits"] is figures      # the folds' fits only for the figure
    assert (out / "figures" / "leave_one_out.png").is_file() is figures
    assert isinstance(seen["data"], RecordingSet) and seen["criticality"] == "subcritical"
    assert [r.mu for r in seen["data"]] == post.features.mu.tolist()
    assert seen["seed"] == 1 and seen["methods"] == ("bayes",)
    assert seen["settings"].inference == "importance" and seen["settings"].control is True
    s = json.loads((out / "summary.json").read_text())
    n = len(s["recordings"])
    loo = s["leave_one_out"]
    assert [r["file"] for r in loo["folds"]] == [r["file"] for r in s["recordings"]]
    assert loo["check"]["inside_ci90"] == n_inside == loo["summary"]["coverage"]
    from scipy.stats import binom

    flagged = bool(binom.cdf(n_inside, n, 0.9) < 0.05)     # 3/7: P = 0.003; 7/7: 1
    assert flagged is (n_inside == 3)
    chk = s["diagnostics"]["leave_one_out"]
    assert chk["ok"] is (not flagged) and "warning" not in chk
    lines = [w for w in s["diagnostics"]["warnings"] if w.startswith("leave-one-out:")]
    assert len(lines) == int(flagged)
    printed = capsys.readouterr().out.split("leave-one-out (each recording")[1]
    assert printed.count("  OUTSIDE") == n - n_inside
    assert f"{n_inside}/{n} held-out amplitudes inside their bands" in printed
    assert (f"warning: leave-one-out: {n_inside}/{n} held-out" in printed) is flagged


def test_extrapolation_scale_reaches_the_fit_and_is_checked(tmp_path, monkeypatch, capsys):
    """``--extrapolation-scale`` sets the prior scale of the model error away from the
    recordings; a value that is not positive is a one-line error before any fit."""
    import bayeshopf.posterior
    from bayeshopf.errors import FitError

    seen = {}

    def stop(rs, criticality, **kw):   # the fit itself is tested elsewhere
        seen.update(kw)
        raise FitError("stopped by the test")

    monkeypatch.setattr(bayeshopf.posterior, "fit_hybrid", stop)
    assert main(["demo", "--fast", "--out", str(tmp_path / "a"), "--no-figures",
                 "--extrapolation-scale", "0.25"]) == 2
    assert "stopped by the test" in capsys.readouterr().err
    assert seen["settings"].extrapolation_scale == 0.25
    seen.clear()
    assert main(["demo", "--fast", "--out", str(tmp_path / "b"), "--no-figures"]) == 2
    capsys.readouterr()
    assert seen["settings"].extrapolation_scale is None      # none with the discrepancy
    assert seen["settings"].discrepancy is True and seen["settings"].nn_width is None
    assert seen["settings"].inference == "importance"
    seen.clear()
    assert main(["demo", "--fast", "--out", str(tmp_path / "d"), "--no-figures",
                 "--no-discrepancy", "--nn-width", "16", "--inference", "nuts"]) == 2
    capsys.readouterr()
    assert seen["settings"].discrepancy is False and seen["settings"].nn_width == 16
    assert seen["settings"].inference == "nuts"
    for bad in ("0", "-1", "nan"):
        seen.clear()
        assert main(["demo", "--fast", "--out", str(tmp_path / "c"), "--no-figures",
                     "--extrapolation-scale", bad]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "--extrapolation-scale" in err, err
        assert "a positive number expected" in err and not seen


def test_mu_discrepancy_reaches_the_fit_and_is_checked(tmp_path, monkeypatch, capsys):
    """``--mu-discrepancy`` sets κ of the discrepancy in μ (2 by default) and
    ``--mu-discrepancy-floor`` its floor φ (0.05); with ``--no-discrepancy``,
    negative or not finite each is a one-line error before any fit."""
    import bayeshopf.posterior
    from bayeshopf.errors import FitError

    seen = {}

    def stop(rs, criticality, **kw):   # the fit itself is tested elsewhere
        seen.update(kw)
        raise FitError("stopped by the test")

    monkeypatch.setattr(bayeshopf.posterior, "fit_hybrid", stop)
    base = ["demo", "--fast", "--no-figures"]
    assert main([*base, "--out", str(tmp_path / "a"), "--mu-discrepancy", "0.5",
                 "--mu-discrepancy-floor", "0"]) == 2
    capsys.readouterr()
    assert seen["settings"].mu_discrepancy == 0.5
    assert seen["settings"].mu_discrepancy_floor == 0.0
    seen.clear()
    assert main([*base, "--out", str(tmp_path / "b")]) == 2
    capsys.readouterr()
    assert seen["settings"].mu_discrepancy == 2.0
    assert seen["settings"].mu_discrepancy_floor == 0.05
    for flag in ("--mu-discrepancy", "--mu-discrepancy-floor"):
        for args, why in (([*base, flag, "-1"], "a finite number ≥ 0 expected"),
                          ([*base, flag, "inf"], "a finite number ≥ 0 expected"),
                          ([*base, "--no-discrepancy", flag, "1"],
                           "which --no-discrepancy removes")):
            seen.clear()
            assert main([*args, "--out", str(tmp_path / "c")]) == 2
            err = capsys.readouterr().err.strip()
            assert len(err.splitlines()) == 1 and err.split()[3] == flag, err
            assert why in err and not seen


def test_nn_width_reaches_the_fit_and_is_checked(tmp_path, monkeypatch, capsys):
    """``--nn-width inf`` fits the network at infinite width, a number its hidden units;
    anything else is a one-line error before any fit."""
    import bayeshopf.posterior
    from bayeshopf.errors import FitError

    seen = {}

    def stop(rs, criticality, **kw):   # the fit itself is tested elsewhere
        seen.update(kw)
        raise FitError("stopped by the test")

    monkeypatch.setattr(bayeshopf.posterior, "fit_hybrid", stop)
    for value, want in (("inf", None), ("64", 64)):
        seen.clear()
        assert main(["demo", "--fast", "--out", str(tmp_path / value), "--no-figures",
                     "--nn-width", value]) == 2
        assert "stopped by the test" in capsys.readouterr().err
        assert seen["settings"].nn_width == want
    for bad in ("0", "-4", "wide", "2.5"):
        seen.clear()
        assert main(["demo", "--fast", "--out", str(tmp_path / "c"), "--no-figures",
                     "--nn-width", bad]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and f"--nn-width {bad}" in err, err
        assert not seen
