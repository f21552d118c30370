"""A further channel regressed on the normal-form state of a collapsed-core fit (planted)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from bayeshopf.data.recording import RecordingSet
from bayeshopf.data.synthetic import demo_system
from bayeshopf.errors import FitError
from bayeshopf.inference.channels import fit_channel

#: The planted third channel: y = 2 h − 0.5 α (a function of the state on the LCO).
C_H, C_ALPHA = 2.0, -0.5


def _with_force(rs: RecordingSet, seed: int = 0) -> RecordingSet:
    rng = np.random.default_rng(seed)
    h, a = rs.planar
    recs = []
    for r in rs.recordings:
        y = C_H * r.channels[h] + C_ALPHA * r.channels[a]
        y = y + 0.02 * np.std(y) * rng.standard_normal(y.size)
        recs.append(replace(r, channels={**r.channels, "force": y},
                            units={**r.units, "force": "N"}))
    return RecordingSet(tuple(recs), rs.planar, rs.mu_label, rs.mu_units, rs.extra)


@pytest.fixture(scope="module")
def planted():
    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.posterior import fit_hybrid

    rs, truth = demo_system(seed=3, fast=True)
    rs = _with_force(rs)
    post = fit_hybrid(rs, "subcritical", seed=0, settings=CollapsedSettings.fast(),
                      progress=False)
    return rs, truth, post, fit_channel(post, rs, "force", n_draws=40, seed=0)


def _true_amplitude(truth, mu, branch):
    orbit = truth.orbit(mu, branch)
    y = C_H * orbit[:, 0] + C_ALPHA * orbit[:, 1]
    return float(y.max() - y.min())


@pytest.mark.slow  # a fit, and a statistical check at three μ
@pytest.mark.parametrize(("mu", "branch"), [(17.0, "stable"), (16.0, "unstable"), (19.0, "stable")])
def test_channel_amplitude_at_unseen_mu_is_inside_its_band(planted, mu, branch):
    _, truth, post, ch = planted
    amp = ch.amplitude(post, [mu], branch, predictive=True)[:, 0]
    lo, hi = np.nanquantile(amp, [0.05, 0.95])
    true = _true_amplitude(truth, mu, branch)
    assert lo <= true <= hi, (lo, true, hi)
    assert hi - lo < 0.05 * true  # informative, not merely wide


@pytest.mark.slow  # a fit
def test_channel_waveform_matches_the_planted_function(planted):
    """Along the predicted orbit the channel's median waveform equals 2h − 0.5α of that orbit."""
    rs, truth, post, ch = planted
    wave = np.median(ch.waveform(post, 18.1, "stable"), axis=0)
    true = _true_amplitude(truth, 18.1, "stable")
    assert abs((wave.max() - wave.min()) - true) < 0.05 * true
    # the mean level is that of the recording at 18.1 (offsets included)
    rec = next(r for r in rs if r.mu == 18.1 and r.branch == "stable")
    assert abs(wave.mean() - rec.channels["force"].mean()) < 0.05 * true
    assert ch.measured_amplitude.shape == (len(rs),)
    # each measured amplitude is the planted function's on its recording, within 5%
    for r, a in zip(rs, ch.measured_amplitude, strict=True):
        assert a == pytest.approx(_true_amplitude(truth, r.mu, r.branch), rel=0.05), r.name
    # the measured samples sit on the orbit: their phases run over the whole circle
    phi, _ = ch.phases[0]
    assert np.ptp(phi) > 0.9 * 2 * np.pi


@pytest.mark.slow  # a fit
def test_recordings_must_be_those_of_the_fit(planted):
    rs, _, post, _ = planted
    with pytest.raises(FitError, match="not those of the fit"):
        fit_channel(post, rs.subset([0, 1, 2]), "force")


def test_bad_channel_requests_say_what_was_expected():
    """Checked before the fit is used: no fit needed."""
    rs = _with_force(demo_system(seed=3, fast=True)[0])
    stand_in = SimpleNamespace(features=SimpleNamespace(names=tuple(rs.names)))
    with pytest.raises(FitError, match="planar pair"):
        fit_channel(stand_in, rs, rs.planar[0])
    with pytest.raises(FitError, match="no channel 'torque'"):
        fit_channel(stand_in, rs, "torque")
