"""What the commands print: one JSON schema, "no branch" the same everywhere, repeated --mu."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest

from bayeshopf.cli.main import main

INTERVAL_KEYS = {"median", "lo", "hi", "ci"}


@pytest.fixture(scope="module")
def fit_dir(fast_demo_fit, tmp_path_factory):
    from bayeshopf.fit_folder import save_hybrid

    return save_hybrid(fast_demo_fit[0], tmp_path_factory.mktemp("cli_output") / "fit")


@pytest.fixture(scope="module")
def saved(fit_dir):
    from bayeshopf.fit_folder import load_fit

    return load_fit(fit_dir)


def _intervals(obj):
    """Every value under a key that names an interval in the schema."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            if k == "units":
                continue
            if k in ("amplitude", "frequency", "predicted") or k in ("mu0", "a2", "mu_fold"):
                yield v
            yield from _intervals(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _intervals(v)


def _check_schema(doc: dict, command: str, ci: float) -> None:
    assert doc["schema_version"] == 1 and doc["command"] == command and doc["ci"] == ci
    assert set(doc["units"]) == {"mu", "amplitude", "frequency"}
    found = list(_intervals(doc))
    assert found
    for iv in found:
        assert iv is None or (set(iv) == INTERVAL_KEYS and iv["ci"] == ci
                              and iv["lo"] <= iv["median"] <= iv["hi"]), iv


def _rare_mu(saved, branch: str) -> float:
    """A μ where ``branch`` exists in some posterior draws, but fewer than half."""
    s = saved.summary     # the branches end at the fold and the Hopf point, per draw
    grid = np.concatenate([np.linspace(*s[k]["ci90"], 41) for k in ("mu_fold", "mu0")])
    for mu in grid:
        p = saved.p_exists(float(mu), branch)
        if 0 < p < 0.5:
            return float(mu)
    pytest.skip(f"no μ with 0 < P(exists) < 0.5 on the {branch} branch of this fit")


def test_predict_repeated_mu_adds_values_in_order(fit_dir, saved, capsys):
    mus = [r["mu"] for r in saved.summary["recordings"] if r["branch"] == "stable"][:3]
    argv = ["predict", str(fit_dir), "--json", "--mu", str(mus[0]), "--mu", str(mus[1]),
            str(mus[2])]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    _check_schema(doc, "predict", 0.9)
    assert [p["mu"] for p in doc["predictions"]] == mus
    for p in doc["predictions"]:     # each entry is the fit's own prediction at that μ
        ref = saved.predict(p["mu"], "stable", ci=0.9)
        assert (p["amplitude"]["median"], p["amplitude"]["lo"], p["amplitude"]["hi"]) == \
            pytest.approx((ref.median, ref.lo, ref.hi), rel=1e-12)
        assert p["p_exists"] == pytest.approx(saved.p_exists(p["mu"], "stable"))


@pytest.mark.parametrize("branch", ["stable", "unstable"])
def test_no_branch_is_the_same_in_table_csv_json_and_sentence(fit_dir, saved, branch,
                                                              capsys):
    """Where the branch exists in fewer than half the draws: '—', empty cells, null; with
    --min-p-exists 0 the values of the draws that have it."""
    rare = _rare_mu(saved, branch)
    common = next(r["mu"] for r in saved.summary["recordings"] if r["branch"] == branch)
    mus = [str(common), str(rare)]
    base = ["predict", str(fit_dir), "--branch", branch, "--mu", *mus]

    assert main(base + ["--json"]) == 0
    have, rare_p = json.loads(capsys.readouterr().out)["predictions"]
    assert have["exists"] and have["amplitude"] is not None
    assert rare_p["exists"] is False and 0 < rare_p["p_exists"] < 0.5
    assert rare_p["amplitude"] is None and rare_p["frequency"] is None

    assert main(base + ["--csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    cells = [[v for k, v in r.items() if k.startswith(("amplitude", "frequency"))] for r in rows]
    assert all(c != "" for c in cells[0]) and all(c == "" for c in cells[1])

    assert main(base) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert "—" not in lines[2] and "—" in lines[3]
    assert len(lines[3].split()) == 4          # mu, P(exists), — for amplitude and frequency

    assert main(["predict", str(fit_dir), "--branch", branch, "--mu", str(rare)]) == 0
    sentence = capsys.readouterr().out
    assert "amplitude —" in sentence and "--min-p-exists" in sentence

    assert main(base + ["--json", "--min-p-exists", "0"]) == 0
    rare_all = json.loads(capsys.readouterr().out)["predictions"][1]
    assert rare_all["exists"] and rare_all["amplitude"] is not None


def test_predict_branch_nowhere_and_bad_share_are_one_line_errors(fit_dir, saved, capsys):
    far = saved.summary["mu0"]["median"] + 20
    assert main(["predict", str(fit_dir), "--branch", "unstable", "--mu", str(far),
                 "--json"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "does not exist" in err and "--mu" in err
    assert main(["predict", str(fit_dir), "--mu", "16", "--min-p-exists", "1.5"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--min-p-exists 1.5" in err


def test_the_table_shows_the_width_of_every_interval(fit_dir, saved, capsys):
    mu = next(r["mu"] for r in saved.summary["recordings"] if r["branch"] == "stable")
    assert main(["predict", str(fit_dir), "--mu", str(mu)]) == 0
    amp, freq = capsys.readouterr().out.strip().splitlines()
    ref = saved.predict(mu, "stable"), saved.frequency(mu, "stable")
    for line, iv in zip((amp, freq), ref, strict=True):
        lo, hi = (float(x) for x in line.split("[")[1].split("]")[0].split(","))
        assert lo < hi and (hi - lo) == pytest.approx(iv.hi - iv.lo, rel=0.1), (line, iv)


def test_next_json_has_the_schema(fit_dir, capsys):
    assert main(["next", str(fit_dir), "--target", "hopf", "--n", "2", "--json",
                 "--no-figure"]) == 0
    doc = json.loads(capsys.readouterr().out)
    _check_schema(doc, "next", 0.9)
    assert doc["target"] == "hopf" and len(doc["recommended"]) == 2
    assert [c["rank"] for c in doc["recommended"]] == [1, 2]
    assert all((c["amplitude"] is None) == bool(c["skipped"]) for c in doc["candidates"])


def test_fit_json_has_the_schema_and_the_summary_numbers(fast_demo_fit, tmp_path,
                                                         monkeypatch, capsys):
    from bayeshopf import posterior
    from bayeshopf.data import write_interchange

    fit, rs, _ = fast_demo_fit
    data = write_interchange(rs, tmp_path / "data")
    monkeypatch.setattr(posterior, "fit_hybrid", lambda rs, crit, **kw: fit)
    out = tmp_path / "out"
    assert main(["fit", str(data), "--out", str(out), "--quiet", "--no-figures", "--json",
                 "--ci", "0.8"]) == 0
    doc = json.loads(capsys.readouterr().out)
    _check_schema(doc, "fit", 0.8)
    s = json.loads((out / "summary.json").read_text())
    for k in ("mu0", "mu_fold"):
        p = doc["parameters"][k]
        assert (p["median"], p["lo"], p["hi"]) == (s[k]["median"], *s[k]["ci80"])
    assert [r["file"] for r in doc["recordings"]] == [r["file"] for r in s["recordings"]]
    assert doc["checks"]["n_recordings"] == len(s["recordings"])
