from __future__ import annotations

import json

import numpy as np
import pytest

from bayeshopf.data.recording import RecordingSet
from bayeshopf.data.synthetic import (
    DEMO_STABLE_MU,
    DEMO_UNSTABLE_MU,
    PlantedHopf,
    demo_system,
    hopf_recordings,
)
from bayeshopf.errors import DataError
from bayeshopf.features import extract_harmonics


@pytest.fixture(scope="module")
def demo() -> tuple[RecordingSet, PlantedHopf]:
    return demo_system(seed=0)


def test_planted_truth() -> None:
    truth = PlantedHopf()
    assert (truth.mu0, truth.a2) == (18.0, 3.4)
    assert truth.criticality == "subcritical"
    assert truth.mu_fold == pytest.approx(18.0 - 3.4**2 / 4) and round(truth.mu_fold, 2) == 15.11
    assert truth.mu_ref == 18.0
    mu = 16.5
    disc = np.sqrt(3.4**2 + 4 * (mu - 18.0))
    assert float(truth.radius(mu, "stable")) == pytest.approx(np.sqrt((3.4 + disc) / 2))
    assert float(truth.radius(mu, "unstable")) == pytest.approx(np.sqrt((3.4 - disc) / 2))
    r = float(truth.radius(mu, "stable"))
    assert float(truth.frequency_hz(mu)) == pytest.approx(2.5 * (1 + truth.omega_r2 * r**2))
    assert np.isnan(truth.amplitude(19.0, "unstable")) and np.isnan(truth.amplitude(15.0))
    amp = truth.amplitude(np.array([16.0, 17.0, 19.0]))
    assert amp.shape == (3,) and np.all(np.diff(amp) > 0)
    # the peak-to-peak of the orbit's heave, on the same phases (amplitude drops the
    # constant terms; a skewed map and both branches)
    skew = PlantedHopf(T_L=np.array([[0.004, -0.003], [0.02, 0.05]]), nonlinear=0.3)
    for branch, mus in (("stable", [15.2, 16.0, 19.0, 21.0]), ("unstable", [15.2, 17.9])):
        z1 = skew.orbit(np.array(mus), branch, 4096)[..., 0]
        np.testing.assert_allclose(skew.amplitude(np.array(mus), branch), np.ptp(z1, axis=-1),
                                   rtol=1e-12)
    # flutter-rig scales: heave a few cm, pitch ~0.1 rad
    z = truth.orbit(19.5)
    assert 0.02 < np.ptp(z[:, 0]) < 0.06 and 0.1 < np.ptp(z[:, 1]) < 0.3
    json.dumps(truth.to_dict())
    sup = PlantedHopf(a2=-1.0)
    assert sup.criticality == "supercritical" and sup.mu_fold is None


def test_shapes_units_and_labels(demo: tuple[RecordingSet, PlantedHopf]) -> None:
    rs, _ = demo
    assert len(rs) == len(DEMO_STABLE_MU) + len(DEMO_UNSTABLE_MU) == 7
    assert rs.planar == ("h", "alpha") and rs.units == ("m", "rad")
    assert (rs.mu_label, rs.mu_units) == ("airspeed", "m/s")
    np.testing.assert_allclose(rs.mus, DEMO_STABLE_MU + DEMO_UNSTABLE_MU)
    np.testing.assert_array_equal(rs.is_unstable, [False] * 4 + [True] * 3)
    assert len(set(rs.names)) == 7
    for r in rs:
        assert r.t.shape == (1600,) and r.dt == pytest.approx(1 / 200) and r.t[0] == 0.0
        assert set(r.channels) == {"h", "alpha"} and dict(r.units) == {"h": "m", "alpha": "rad"}
        assert r.channels["h"].shape == r.t.shape and np.all(np.isfinite(r.channels["h"]))
    fast, _ = demo_system(fast=True)
    assert fast[0].t.shape == (400,) and fast[0].dt == pytest.approx(1 / 100)
    assert fast.names == rs.names


def test_deterministic_from_seed(demo: tuple[RecordingSet, PlantedHopf]) -> None:
    rs, _ = demo
    again, _ = demo_system(seed=0)
    other, _ = demo_system(seed=1)
    for a, b, c in zip(rs, again, other, strict=True):
        for ch in ("h", "alpha"):
            np.testing.assert_array_equal(a.channels[ch], b.channels[ch])
            assert not np.allclose(a.channels[ch], c.channels[ch])
    # a recording does not change when others are added after it
    fewer = PlantedHopf().simulate(DEMO_STABLE_MU, DEMO_UNSTABLE_MU[:1], seed=0)
    for a, b in zip(fewer, rs, strict=False):
        np.testing.assert_array_equal(a.channels["h"], b.channels["h"])


def test_noise_level_and_clean_orbit() -> None:
    truth = PlantedHopf()
    clean = truth.simulate((16.7,), (16.5,), noise=0.0, seed=4)
    noisy = truth.simulate((16.7,), (16.5,), noise=0.02, seed=4)
    for c, n in zip(clean, noisy, strict=True):
        z = c.planar(("h", "alpha"))
        # the clean record lies on the planted orbit: same extent and same centre
        orbit = truth.orbit(c.mu, c.branch, 4096)
        np.testing.assert_allclose(np.ptp(z, axis=0), np.ptp(orbit, axis=0), rtol=2e-3)
        np.testing.assert_allclose(
            0.5 * (z.max(0) + z.min(0)), 0.5 * (orbit.max(0) + orbit.min(0)), atol=1e-4
        )
        # same phases, so the difference is the noise: std = 2 % of the channel amplitude
        sd = np.std(n.planar(("h", "alpha")) - z, axis=0)
        np.testing.assert_allclose(sd / (0.5 * np.ptp(orbit, axis=0)), 0.02, rtol=0.1)


@pytest.mark.parametrize("fast", [False, True])
def test_features_measure_planted_amplitudes(fast: bool) -> None:
    rs, truth = demo_system(seed=2, fast=fast)
    f = extract_harmonics(rs)
    planted = np.array([float(truth.amplitude(r.mu, r.branch)) for r in rs])
    np.testing.assert_allclose(f.amplitude, planted, rtol=0.02)
    freq = np.array([float(truth.frequency_hz(r.mu, r.branch)) for r in rs])
    np.testing.assert_allclose(np.abs(f.frequency_hz), freq, rtol=0.01)
    # the stable branch grows with μ, the unstable one shrinks towards μ0
    assert np.all(np.diff(f.amplitude[~f.unstable]) > 0)
    assert np.all(np.diff(f.amplitude[f.unstable]) < 0)


def test_supercritical_set() -> None:
    rs = hopf_recordings(criticality="supercritical", duration=4.0, fs=100.0, seed=1)
    assert len(rs) == 4 and not rs.is_unstable.any() and np.all(rs.mus > 18.0)
    truth = PlantedHopf(a2=-3.4)
    f = extract_harmonics(rs)
    planted = truth.amplitude(rs.mus)
    np.testing.assert_allclose(f.amplitude, planted, rtol=0.02)


def test_hopf_recordings_matches_planted_system() -> None:
    kw = dict(mu0=20.0, a2=2.0, omega=10.0, T_s=(0.0, 0.0), nonlinear=0.0)
    rs = hopf_recordings(stable_mu=(19.5, 21.0), unstable_mu=(19.5,), noise=0.0, **kw)
    direct = PlantedHopf(**kw).simulate((19.5, 21.0), (19.5,), noise=0.0)
    for a, b in zip(rs, direct, strict=True):
        np.testing.assert_array_equal(a.channels["alpha"], b.channels["alpha"])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(unstable_mu=(16.0, 19.0)), r"unstable_mu: .*\(15\.11, 18\).*got \[19\.0\]"),
        (dict(unstable_mu=(14.0,)), r"unstable_mu: .*got \[14\.0\] \(no unstable LCO there\)"),
        (dict(stable_mu=(15.0,)), r"stable_mu: .*\[15\.11, inf\).*got \[15\.0\]"),
        (dict(criticality="supercritical", unstable_mu=(18.5,)), r"no unstable LCOs; got"),
        (dict(criticality="supercritical", stable_mu=(17.0,)), r"stable_mu: .*\(18, inf\)"),
        (dict(a2=-1.0), r"subcritical system needs a2 > 0; got a2 = -1"),
        (dict(criticality="supercritical", a2=1.0), r"supercritical system needs a2 < 0"),
        (dict(criticality="critical"), r"criticality must be .*; got 'critical'"),
        (dict(a2=0.0, criticality="supercritical"), r"a2 < 0; got a2 = 0"),
        (dict(T_L=[[1.0, 2.0], [2.0, 4.0]]), r"T_L must be nonsingular"),
        (dict(T_L=[1.0, 2.0]), r"T_L must have shape \(2, 2\); got shape \(2,\)"),
        (dict(T_s=(0.0, np.nan)), r"T_s must be finite"),
        (dict(noise=-0.1), r"noise must be >= 0; got -0.1"),
        (dict(fs=4.0), r"fs must exceed twice .*; got fs = 4 Hz"),
        (dict(duration=0.0), r"duration must be > 0; got 0"),
        (dict(nonlinear=0.5), r"nonlinear: \|ε\|·r must be < 0.3"),
        (dict(stable_mu=(), unstable_mu=()), r"at least one μ"),
        (dict(stable_mu=("fast",)), r"stable_mu must be a sequence of numbers"),
        (dict(seed=-1), r"seed must be a non-negative integer; got -1"),
        (dict(seed=1.5), r"seed must be a non-negative integer; got 1.5"),
    ],
)
def test_bad_arguments_raise_clear_errors(kwargs: dict, match: str) -> None:
    with pytest.raises(DataError, match=match) as err:
        hopf_recordings(**kwargs)
    assert "\n" not in str(err.value)
    assert isinstance(err.value, ValueError)


def test_bad_branch_name() -> None:
    with pytest.raises(DataError, match="branch must be 'stable' or 'unstable'; got 'up'"):
        PlantedHopf().radius(16.0, "up")
