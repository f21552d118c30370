"""A further channel regressed on the normal-form state, against a planted channel."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from bayeshopf.data.recording import RecordingSet
from bayeshopf.data.synthetic import demo_system
from bayeshopf.errors import FitError
from bayeshopf.inference.channels import fit_channel
from bayeshopf.pipeline import FitSettings, fit

#: The planted third channel: y = 2 h − 0.5 α (a function of the state on the LCO).
C_H, C_ALPHA = 2.0, -0.5


@pytest.fixture(scope="module")
def planted():
    rs, truth = demo_system(seed=3, fast=True)
    rng = np.random.default_rng(0)
    h, a = rs.planar
    recs = []
    for r in rs.recordings:
        y = C_H * r.channels[h] + C_ALPHA * r.channels[a]
        y = y + 0.02 * np.std(y) * rng.standard_normal(y.size)
        recs.append(replace(r, channels={**r.channels, "force": y},
                            units={**r.units, "force": "N"}))
    rs = RecordingSet(tuple(recs), rs.planar, rs.mu_label, rs.mu_units, rs.extra)
    result = fit(rs, "subcritical", seed=0, settings=FitSettings.fast(), progress=False)
    return rs, truth, result, fit_channel(result, rs, "force", n_draws=40, seed=0)


def _true_amplitude(truth, mu, branch):
    orbit = truth.orbit(mu, branch)
    y = C_H * orbit[:, 0] + C_ALPHA * orbit[:, 1]
    return float(y.max() - y.min())


@pytest.mark.slow  # legacy core fit
@pytest.mark.parametrize(("mu", "branch"), [(17.0, "stable"), (16.0, "unstable"), (19.0, "stable")])
def test_channel_amplitude_at_unseen_mu_is_inside_its_band(planted, mu, branch):
    _, truth, result, ch = planted
    amp = ch.amplitude(result, [mu], branch, predictive=True)[:, 0]
    lo, hi = np.nanquantile(amp, [0.05, 0.95])
    true = _true_amplitude(truth, mu, branch)
    assert lo <= true <= hi, (lo, true, hi)
    assert hi - lo < 0.05 * true  # informative, not merely wide


@pytest.mark.slow  # legacy core fit
def test_channel_waveform_matches_the_planted_function(planted):
    """Along the predicted orbit the channel's median waveform equals 2h − 0.5α of that orbit."""
    rs, truth, result, ch = planted
    wave = np.median(ch.waveform(result, 18.1, "stable"), axis=0)
    true = _true_amplitude(truth, 18.1, "stable")
    assert abs((wave.max() - wave.min()) - true) < 0.05 * true
    # the mean level is that of the recording at 18.1 (offsets included)
    rec = next(r for r in rs if r.mu == 18.1 and r.branch == "stable")
    assert abs(wave.mean() - rec.channels["force"].mean()) < 0.05 * true
    assert ch.measured_amplitude.shape == (len(rs),)


@pytest.mark.slow  # legacy core fit
def test_bad_channel_requests_say_what_was_expected(planted):
    rs, _, result, _ = planted
    with pytest.raises(FitError, match="planar pair"):
        fit_channel(result, rs, rs.planar[0])
    with pytest.raises(FitError, match="no channel 'torque'"):
        fit_channel(result, rs, "torque")
