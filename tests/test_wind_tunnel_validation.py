"""The wind-tunnel recordings on the collapsed core: leave-one-out, the criticality, the example.

Leave-one-out refits all 7 folds at default settings and again with the model
error away from the recordings at 0.1 (``fit_hybrid``, about 10 s a fold on 2
cores): those tests are marked ``slow`` and run with
``pytest -m slow``; the stored notebook 03 holds the outputs of the same study.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from notebook_runs import execute_fast, stored

from bayeshopf.validation import leave_one_out

REPO = Path(__file__).resolve().parent.parent
CBC_DIR = (REPO / ".." / "shared" / "data" / "flutter_cbc").resolve()


@pytest.fixture(scope="module")
def recordings(cbc_recordings):
    return cbc_recordings


@pytest.fixture(scope="module")
def loo(recordings):
    return leave_one_out(recordings, "subcritical", seed=0, progress=False)


@pytest.fixture(scope="module")
def loo_narrow(recordings):
    """The same folds with the model error away from the recordings at 0.1 in every draw."""
    from bayeshopf.inference.collapsed import CollapsedSettings

    return leave_one_out(recordings, "subcritical", seed=0, progress=False,
                         settings=CollapsedSettings(extrapolation_scale=0.1))


#: The legacy core's mean held-out band (m), docs/inference_core.md.
LEGACY_WIDTH = 0.0136


@pytest.mark.slow
def test_default_bands_hold_every_held_out_amplitude_at_four_times_the_legacy_width(loo):
    """Each refit's draws whose relative model error is above 2% take the scale 0.7 away from
    the recordings (stop 47): 7/7 inside at a mean width of 60.0 mm, 4.4 times the legacy
    core's (at 0.1 in every draw: 4/7 at 14.8 mm, below)."""
    assert loo.coverage("bayes") == 7, [(f.name, f.inside("bayes")) for f in loo.folds]
    width = loo.summary()["bayes"]["mean_band_width"]
    assert 3.5 * LEGACY_WIDTH < width < 5.5 * LEGACY_WIDTH, width
    # every refit is above the limit in part of its draws (rms scales 0.48-0.68)
    assert all(0.3 < f.extrapolation_scale < 0.7 for f in loo.folds), \
        [f.extrapolation_scale for f in loo.folds]


@pytest.mark.slow
def test_at_scale_0_1_held_out_orbits_at_the_branch_ends_are_not_covered(loo_narrow):
    """benchmarks/loo_collapsed.json (seed 0, the scale 0.1 in every draw): 4/7.

    The unstable 14.9 and 16.5 m/s recordings are missed (without one of them
    the fold and the Hopf point move), and so, since the control term (stop
    44), is the stable 17.3 m/s one, 1.7 mm above its band's upper end; the
    stable 14.9–16.5 m/s ones are inside (P(X ≤ 4) = 0.026 for calibrated 90%
    bands).
    """
    loo = loo_narrow
    inside = {f.name: f.inside("bayes") for f in loo.folds}
    assert all(v for k, v in inside.items() if "_stable_" in k and "17_3" not in k), inside
    assert not inside["CBC_unstable_v14_9.mat"] and not inside["CBC_unstable_v16_5.mat"], inside
    assert loo.coverage("bayes") >= 4, inside
    assert loo.summary()["bayes"]["mean_band_width"] < 1.2 * LEGACY_WIDTH
    # the plug-in band has no parameter uncertainty: narrower than the posterior's
    s = loo.summary()
    assert s["map"]["mean_band_width"] < s["bayes"]["mean_band_width"], s


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="6/7 needs bands 4.4x the legacy width at the default "
                   "scale; at 0.1, 4/7 (docs/limits.md)")
def test_held_out_coverage_reaches_six_of_seven_within_twice_the_legacy_width(loo, loo_narrow):
    assert any(x.coverage("bayes") >= 6
               and x.summary()["bayes"]["mean_band_width"] <= 2 * LEGACY_WIDTH
               for x in (loo, loo_narrow))


@pytest.mark.slow
def test_fold_and_hopf_intervals_of_every_fold(loo):
    """The fold stays below the lowest recording (14.9 m/s) and μ0 above the unstable ones."""
    for f in loo.folds:
        p = f.predictions["bayes"]
        assert p.mu_fold[2] <= 14.9 + 1e-9 and p.mu0[1] >= 16.5 - 1e-9, (f.name, p)
        assert p.mu_fold[1] <= p.mu_fold[0] <= p.mu_fold[2], (f.name, p)
    assert loo.summary()["bayes"]["mu_fold_sd"] < 0.5


@pytest.mark.slow
def test_loo_table_is_json_ready(loo):
    rows = json.loads(json.dumps(loo.table()))
    assert len(rows) == 7
    assert {"bayes", "map"} <= set(rows[0])
    assert all(np.isfinite(r["bayes"]["median"]) for r in rows)


def test_two_orbits_at_one_airspeed_without_any_model(recordings):
    """The model-free part of the criticality verdict, on the collapsed core's features."""
    from bayeshopf.diagnostics.comparison import coexisting_orbits
    from bayeshopf.features.harmonics import extract_harmonics

    pairs = {round(p["mu"], 1): p for p in coexisting_orbits(extract_harmonics(recordings))}
    assert sorted(pairs) == pytest.approx([14.9, 16.5])     # 15.6 and 15.7 m/s are not one μ
    assert set(pairs[16.5]["recordings"]) == {"CBC_stable_v16_5.mat", "CBC_unstable_v16_5.mat"}
    # K = 4 harmonics of the mean orbit (the legacy R(θ) features read 64.2 and 19.5 mm)
    assert pairs[16.5]["amplitudes"] == pytest.approx((0.0637, 0.0194), abs=2e-4)
    assert min(p["separation"] for p in pairs.values()) > 10


def test_a_supercritical_fit_of_the_rig_is_refused(recordings):
    """The rig's CBC recordings include unstable LCOs: only the subcritical normal form has them."""
    from bayeshopf.errors import FitError
    from bayeshopf.posterior import fit_hybrid

    with pytest.raises(FitError, match="3 unstable recording"):
        fit_hybrid(recordings, "supercritical", progress=False)


@pytest.mark.slow  # two fits at default settings
def test_criticality_from_the_data_is_subcritical(cbc_auto):
    """fit_auto: PSIS-LOO with the exact conditional density, and the coexisting orbits.

    Both rules agree on the rig: the ELPD alone prefers the subcritical model by
    5.1 standard errors (benchmarks/criticality.md, PSIS only), and the two orbits
    at 16.5 m/s decide for it whatever the ELPD.
    """
    post, ev = cbc_auto
    assert post.criticality == "subcritical" and ev["preferred"] == "subcritical"
    assert ev["decided_by"] == "coexisting orbits"
    assert ev["elpd_preferred"] == "subcritical" and ev["z"] > 2, ev["statement"]
    assert ev["branch_labels"] == "used by the subcritical model only"


@pytest.mark.slow  # the same calls as notebook 03 in its fast mode (below)
@pytest.mark.notebooks
def test_wind_tunnel_example_runs_in_fast_mode(tmp_path, recordings):
    env = {**os.environ, "BAYESHOPF_FAST": "1", "MPLBACKEND": "Agg"}
    proc = subprocess.run(
        [sys.executable, str(REPO / "examples" / "wind_tunnel.py"), str(CBC_DIR), str(tmp_path)],
        env=env, capture_output=True, text=True, timeout=1800,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "training amplitudes inside their 90% predictive bands" in proc.stdout
    summary = json.loads((tmp_path / "wind_tunnel.json").read_text())
    assert summary["criticality"] == "subcritical"
    assert set(summary["leave_one_out"]["summary"]) == {"bayes", "map"}
    assert len(summary["leave_one_out"]["folds"]) == 2
    for name in ("bifurcation.png", "frequency.png", "time_series.png", "leave_one_out.png",
                 "actuator.png", "pair_invariant.png"):
        assert (tmp_path / "figures" / name).read_bytes()[:4] == b"\x89PNG"


NOTEBOOK = REPO / "notebooks" / "03_wind_tunnel.ipynb"


@pytest.mark.slow  # its calls run by default on smaller problems: fit_hybrid (test_wind_tunnel,
# default settings), leave_one_out (test_validation, one fold of the demo set), fit_channel
# (test_channels, slow)
@pytest.mark.notebooks
def test_wind_tunnel_notebook_executes_in_fast_mode(tmp_path, monkeypatch, user_without_shared):
    """As a user without ../shared runs it: the recordings come from the (local) mirror."""
    served = user_without_shared[1]   # the kernel inherits the mirror's environment
    n0 = len(served)
    run = execute_fast(NOTEBOOK, tmp_path, monkeypatch)
    assert not run.errors
    assert "fast mode: True" in run.text and "segment spreads apart" in run.text
    assert "training amplitudes inside their 90% predictive bands" in run.text
    assert run.n_images >= 7
    assert len(served) - n0 == 7, served[n0:]   # the seven files came from the download


@pytest.mark.notebooks
def test_stored_wind_tunnel_notebook_has_outputs_of_a_full_run():
    run = stored(NOTEBOOK)
    assert all(c.get("execution_count") for c in run.code), "stored notebook not fully executed"
    assert not run.errors
    assert "fast mode: False" in run.text
    assert "import bayeshopf as bh" in run.code[0].source
    assert 'bh.fit(rs, settings, criticality="subcritical"' in "".join(c.source for c in run.code)
    assert run.n_images >= 7
