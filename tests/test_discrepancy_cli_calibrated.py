"""``bayeshopf discrepancy`` with the simulator's uncertain parameters calibrated first.

The recordings come from a copy of flutter3dof whose parameters were changed
with ``System.with_params`` (k_h +4%, c0 +3%, c_alpha −5%; 2 stable + 2 unstable
LCOs, 4 s records, 1.5% noise, sensor offsets); the command is told only the
nominal simulator. Independent reference: the Hopf point and fold of the
changed copy, continued here. Default run: the command once (calibration by
default; terms screened only), that ``--no-calibration`` reaches the analysis,
and a refusal. Slow: a planted term on top of the changed parameters (the
three fit stages, the terms fitted in full; 3 + 3 recordings).
"""

from __future__ import annotations

import contextlib
import functools
import io
import json

import jax
import numpy as np
import pytest

jax.config.update("jax_enable_x64", True)

import bayeshopf.discrepancy as bd  # noqa: E402
from bayeshopf.cli.main import main  # noqa: E402
from bayeshopf.data import write_interchange  # noqa: E402
from bayeshopf.data.recording import Recording, RecordingSet  # noqa: E402
from bayeshopf.discrepancy import calibration, simulate_with_effect  # noqa: E402
from bayeshopf.discrepancy.calibration import CalibrationError  # noqa: E402
from bayeshopf.discrepancy.effects import truth_points  # noqa: E402
from bayeshopf.errors import BayesHopfError  # noqa: E402
from bayeshopf.simulators import get_system, simulate_recordings  # noqa: E402
from bayeshopf.simulators.continuation import bifurcation_diagram  # noqa: E402

PLAN = [(15.5, "stable"), (17.0, "stable"), (15.5, "unstable"), (17.0, "unstable")]
PLAN_SLOW = [(15.5, "stable"), (16.25, "stable"), (17.0, "stable"),
             (15.5, "unstable"), (16.25, "unstable"), (17.0, "unstable")]
KW = dict(duration_s=4.0, noise=0.015, offsets={"h": 0.001, "alpha": -0.004}, seed=11)
PERTURB = {"k_h": 1.04, "c0": 1.03, "c_alpha": 0.95}


def _truth():
    flutter = get_system("flutter3dof")
    return flutter, flutter.with_params(**{k: flutter.params[k] * v
                                           for k, v in PERTURB.items()})


@pytest.fixture(scope="module")
def perturbed(tmp_path_factory):
    """The recordings (as an interchange folder), the changed copy and its diagram."""
    _, truth = _truth()
    diagram = bifurcation_diagram(truth)
    rs = simulate_recordings(truth, [m for m, _ in PLAN], [b for _, b in PLAN],
                             diagram=diagram, **KW)
    folder = write_interchange(rs, tmp_path_factory.mktemp("perturbed") / "data")
    return folder, truth, diagram


@pytest.fixture(scope="module")
def cli_run(perturbed, tmp_path_factory):
    """``bayeshopf discrepancy`` on the recordings: (report.json, stdout, output folder).

    The command runs as a user runs it, except that the library's terms are
    only screened (``calibrate(refine=0)``: the linear model at the calibration,
    no full fit of the best terms, which would take longer than this test may).
    """
    folder, _, _ = perturbed
    out = tmp_path_factory.mktemp("cli") / "out"
    buf = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(buf):
        mp.setattr(calibration, "calibrate", functools.partial(calibration.calibrate, refine=0))
        rc = main(["discrepancy", str(folder), "--simulator", "flutter3dof", "--out", str(out),
                   "--no-hybrid", "--quiet"])
    assert rc == 0
    return json.loads((out / "report.json").read_text()), buf.getvalue(), out


def test_cli_calibrates_the_parameters_that_are_off(cli_run, perturbed):
    d, _, _ = cli_run
    _, truth, _ = perturbed
    v = d["verdict"]
    assert v["kind"] == "parameters off", v
    assert set(PERTURB) <= set(v["parameters"]), v
    assert "k_alpha" not in v["parameters"]
    table = {p["name"]: p for p in d["parameters"]["table"]}
    assert d["parameters"]["model"] == "calibrated"
    assert len(table) == 11
    for name in PERTURB:               # 3-5% shifts, each recovered to within 0.5%
        assert table[name]["off"]
        assert abs(table[name]["median"] / truth.params[name] - 1) < 0.005, table[name]
    # the calibration itself, whole
    cal = d["calibration"]
    assert cal["verdict"]["kind"] == v["kind"]
    assert [p["name"] for p in cal["calibration"]["parameters"]] == list(table)
    assert {m["name"] for m in d["models"][:2]} == {"none", "parameters"}
    assert d["models"][1]["probability"] == max(m["probability"] for m in d["models"])


def test_cli_reports_the_fit_nominal_and_calibrated(cli_run, perturbed):
    d, _, _ = cli_run
    _, _, diagram = perturbed
    fit = d["fit"]
    assert set(fit) == {"before", "calibrated"}           # no term named: no third stage
    assert d["final_model"] == {"stage": "calibrated", "label": "calibrated"}
    fb, fc = fit["before"], fit["calibrated"]
    for c in ("h", "alpha"):          # nominal: ~50% off; calibrated: within the 1.5% noise
        assert fc["amplitude_error"][c] < 0.01 < fb["amplitude_error"][c]
        assert fc["rms_orbit_error"][c] < 0.1 * fb["rms_orbit_error"][c]
    assert fc["chi2"] < 1e-3 * fb["chi2"]
    assert fc["dof"] < fb["dof"] == d["calibration"]["nominal"]["dof"]
    # Hopf point and fold of the calibrated simulator against those of the changed copy
    hopf, fold = float(diagram.hopf.mu), min(float(f.mu) for f in diagram.folds)
    assert abs(fc["hopf"] - hopf) < 0.05 * abs(fb["hopf"] - hopf)
    assert abs(fc["fold"] - fold) < 0.05 * abs(fb["fold"] - fold)
    # the mismatch: nominal, located per recording, and what remains
    m = d["mismatch"]
    assert m["significant"] and len(m["by_recording"]) == len(PLAN)
    assert m["after"]["model"] == "calibrated" and not m["after"]["significant"]
    assert len(m["after"]["by_recording"]) == len(PLAN)
    assert not any(r["significant"] for r in m["after"]["by_recording"])
    assert "within the recordings' noise" in m["after"]["sentence"]


def test_cli_writes_and_prints_the_calibrated_report(cli_run):
    d, printed, out = cli_run
    lines = printed.splitlines()
    assert lines[0] == d["verdict"]["sentence"]
    assert any(ln.startswith("k_h ") and ln.rstrip().endswith("yes") for ln in lines)
    assert not any(ln.startswith("k_alpha ") and ln.rstrip().endswith("yes") for ln in lines)
    assert any(ln.startswith("parameters calibrated") for ln in lines)
    amp = next(ln for ln in lines if ln.startswith("amplitude error h"))
    assert len(amp.split()[3:]) == 2                        # nominal, calibrated
    assert d["mismatch"]["after"]["sentence"] in lines
    md = (out / "report.md").read_text()
    assert md.startswith("# Discrepancy analysis: flutter3dof")
    assert "## Uncertain parameters (calibrated)" in md
    assert "| k_h | N/m |" in md and "## Fit: nominal, calibrated" in md
    assert "| Hopf point |" in md and "## What remains (calibrated)" in md
    for f in ("bifurcation_diagram.png", "orbit_residuals.png"):
        assert (out / "figures" / f).stat().st_size > 10_000


def test_cli_reports_bayes_factors_apart_from_the_prior_odds(cli_run):
    d, _, out = cli_run
    v = d["verdict"]
    bf, cp = v["bayes_factors"], d["calibration"]["class_probabilities"]
    assert sum(bf["prior"].values()) == pytest.approx(1.0)
    # prior odds times Bayes factor give the posterior odds of the stated probabilities
    checked = 0
    for c in cp:
        for o in ("none", "parameters off"):
            if c != o and min(cp[c], cp[o]) > 1e-200:
                odds = bf["log_bayes_factor"][c][o] + np.log(bf["prior"][c] / bf["prior"][o])
                assert odds == pytest.approx(np.log(cp[c] / cp[o]), abs=1e-6)
                checked += 1
    assert checked >= 1
    # the verdict's own model's probability, beside its class's
    model = next(m for m in d["models"] if m["name"] == v["model"])
    assert v["model_probability"] == pytest.approx(model["probability"])
    assert v["model_probability"] <= v["probability"] + 1e-12
    band = v["prior_sensitivity"]
    assert band and set(band[0]["scales"]) == {"0.5", "2.0"}
    md = (out / "report.md").read_text()
    assert "## Bayes factors (apart from the prior odds)" in md
    assert "over prior scales ×0.5–×2" in md


def test_diagram_title_names_terms_then_parameters_and_wraps():
    from bayeshopf.plotting.discrepancy import diagram_title

    params = ["k_h", "k_alpha", "c_h", "c_alpha", "c3", "k_alpha2", "k_alpha3", "c0", "c1"]
    title = diagram_title({"kind": "term missing", "parameters": params,
                           "terms": ["h_quadratic_damping", "alpha_cubic_damping"]}, width=56)
    lines = title.splitlines()
    assert lines[0] == "term missing: quadratic damping in heave + cubic damping"
    assert lines[1] == "in pitch"
    assert lines[2].startswith("9 parameters off: k_h, k_alpha")
    assert len(lines) == 4 and max(map(len, lines)) <= 56
    assert diagram_title({"kind": "none", "terms": [], "parameters": []}) == "none"


@pytest.mark.parametrize(("flag", "expected"), [([], None), (["--no-calibration"], False)])
def test_no_calibration_flag_reaches_the_analysis(perturbed, tmp_path, monkeypatch, flag,
                                                  expected):
    """``--no-calibration`` asks for the single-term analysis (``calibrate=False``; its
    report is checked in test_discrepancy.py::test_cli_simulate_effect_then_discrepancy)."""
    folder, _, _ = perturbed
    calls = []

    class Stop(BayesHopfError):
        pass

    def record(*args, **kwargs):
        calls.append(kwargs["calibrate"])
        raise Stop("stopped before the analysis")

    monkeypatch.setattr(bd, "analyse", record)
    assert main(["discrepancy", str(folder), "--simulator", "flutter3dof", "--out",
                 str(tmp_path / "out"), "--no-hybrid", "--quiet", *flag]) == 2
    assert calls == [expected]


def test_calibration_needs_uncertain_parameters():
    t = np.arange(100) / 100.0
    rec = Recording(t=t, channels={"z1": np.sin(6 * t), "z2": np.cos(6 * t)},
                    units={"z1": "", "z2": ""}, mu=0.5, branch="stable", name="r0")
    with pytest.raises(CalibrationError, match="declares none"):
        bd.analyse(RecordingSet((rec,), ("z1", "z2")), "vanderpol", calibrate=True,
                   hybrid=False)


@pytest.mark.slow
def test_parameters_off_and_a_term_missing_give_three_stages():
    """Changed parameters and cubic heave damping: nominal, calibrated, calibrated + term."""
    _, truth = _truth()
    truth = truth.replace(default_plan=tuple(PLAN_SLOW))  # the planting sizes the term on it
    rs, _ = simulate_with_effect(truth, "h_cubic_damping", 20.0, [m for m, _ in PLAN_SLOW],
                                 [b for _, b in PLAN_SLOW], **KW)
    rep = bd.analyse(rs, "flutter3dof", hybrid=False)
    d = rep.to_json()
    assert d["verdict"]["kind"] == "term missing", d["verdict"]
    assert d["verdict"]["terms"][0] == "h_cubic_damping"
    fit = d["fit"]
    assert set(fit) == {"before", "calibrated", "after"}
    assert d["final_model"]["label"] == "calibrated + h_cubic_damping"
    lo, hi = fit["after"]["coefficient_ci90"]
    assert lo < fit["after"]["coefficient"] < hi
    assert abs(fit["after"]["coefficient"] / 20.0 - 1) < 0.05, (lo, hi)
    for c in ("h", "alpha"):
        assert fit["after"]["amplitude_error"][c] < fit["calibrated"]["amplitude_error"][c] \
            < fit["before"]["amplitude_error"][c]
    pts = truth_points(truth, "h_cubic_damping", 20.0)
    true_fold = pts["fold"][0]                             # the lowest
    assert abs(fit["after"]["fold"] - true_fold) < 0.2 * abs(fit["calibrated"]["fold"]
                                                              - true_fold)
    assert not d["mismatch"]["after"]["significant"]
    assert "## Fit: nominal, calibrated, calibrated + h_cubic_damping" in rep.to_markdown()


def test_the_verdicts_heading_gives_the_named_models_probability_where_it_is_smaller():
    """The class's probability is shared by every model of the class: where the verdict
    names a term, the heading also gives that model's own (what the reliability study
    scores, since a verdict counts right only when it names the planted term)."""
    from bayeshopf.discrepancy.render import verdict_probability

    term = {"probability": 0.99996, "model_probability": 0.5383}
    assert verdict_probability(term) == "probability 1.00; 0.54 for the model named"
    same = {"probability": 0.9419, "model_probability": 0.9419}      # parameters off
    assert verdict_probability(same) == "probability 0.94"
    assert verdict_probability({"probability": 0.97}) == "probability 0.97"   # older reports
