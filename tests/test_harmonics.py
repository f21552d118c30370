"""Harmonic features against planted signals with known coefficients and noise."""

import numpy as np
import pytest

from bayeshopf.data.recording import Recording, RecordingSet
from bayeshopf.errors import DataError
from bayeshopf.features.frame import PlanarFrame
from bayeshopf.features.harmonics import (
    align,
    extract_harmonics,
    reconstruct,
    shift_origin,
    time_design,
)

OMEGA = 2 * np.pi * 2.5
# true coefficients [a0, a1, a2, b1, b2] of each channel, phase-aligned (b of z1's fundamental 0)
TRUE = np.array([[0.1, 1.0, 0.05, 0.0, 0.03], [-0.2, 0.4, 0.02, 0.8, -0.04]])
IDENTITY = PlanarFrame(np.zeros(2), np.eye(2), ("x", "y"))


def _record(mu, t, noise, rng, t0=0.37):
    z = time_design(t + t0, OMEGA, 2) @ TRUE.T   # delayed: the aligner must undo t0
    z = z + noise * rng.standard_normal(z.shape)
    return Recording(t, {"x": z[:, 0], "y": z[:, 1]}, {}, mu, "stable", name=f"r{mu}")


def _set(duration, fs, noise, seed=0, n=2):
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration * fs)) / fs
    return RecordingSet(tuple(_record(1.0 + i, t, noise, rng) for i in range(n)), ("x", "y"))


def test_shift_origin_matches_a_time_shift():
    rng = np.random.default_rng(1)
    c = rng.standard_normal((2, 9))
    phi = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    shifted = shift_origin(c, np.array(0.7))
    np.testing.assert_allclose(reconstruct(shifted, phi), reconstruct(c, phi + 0.7), atol=1e-12)
    a = align(c)
    assert abs(a[0, 5]) < 1e-12 and a[0, 1] > 0


def test_recovers_planted_coefficients_with_honest_standard_errors():
    f = extract_harmonics(_set(20.0, 500.0, 0.02), n_harmonics=2, frame=IDENTITY)
    assert f.n_segments.min() >= 9
    np.testing.assert_allclose(f.frequency_hz, 2.5, rtol=1e-5)
    z = (f.coeffs - TRUE[None]) / f.coeffs_se
    z = np.delete(z.reshape(2, -1), 3, axis=1)    # z1's b1 is 0 by construction
    assert np.max(np.abs(z)) < 4.5
    # the white-noise standard error of a coefficient: σ √(2/n) (σ/√n for a0)
    n = 20.0 * 500.0
    expected = 0.02 * np.sqrt(2 / n)
    ratio = np.median(f.coeffs_se[:, :, 1:]) / expected
    assert 0.7 < ratio < 1.6


def test_frequency_standard_error_matches_its_spread_over_noise_realisations():
    """The frequency is fitted on the whole record: its error falls as T^(-3/2), so the
    segments' spread (each of T/n) overstates it unless scaled by n^(3/2), not √n."""
    f = extract_harmonics(_set(20.0, 500.0, 0.05, seed=3, n=60), n_harmonics=2, frame=IDENTITY)
    assert f.n_segments.min() >= 9
    spread = np.std(f.omega, ddof=1)          # 60 realisations of the same orbit
    ratio = np.median(f.omega_se) / spread
    assert 0.75 < ratio < 1.35, (np.median(f.omega_se), spread)


def test_control_fundamental_is_on_the_features_time_origin():
    """A control channel u(t) = A cos(ω(t + t0) + ψ), with z1's crest at t = −t0: after the
    alignment its fundamental is A(cos ψ, −sin ψ); without a control channel it is None."""
    rng = np.random.default_rng(4)
    t = np.arange(int(12.0 * 400.0)) / 400.0
    recs, truth = [], []
    for i, (amp, psi) in enumerate(((0.3, 0.4), (0.05, -2.0), (0.2, 2.9))):
        t0 = rng.uniform(0, 0.4)
        r = _record(1.0 + i, t, 0.01, rng, t0=t0)
        u = amp * np.cos(OMEGA * (t + t0) + psi) + 0.01 * rng.standard_normal(t.size)
        recs.append(Recording(t, {**r.channels, "u": u}, {}, r.mu, "stable", name=r.name))
        truth.append([amp * np.cos(psi), -amp * np.sin(psi)])
    rs = RecordingSet(tuple(recs), ("x", "y"), control="u")
    f = extract_harmonics(rs, n_harmonics=2, frame=IDENTITY)
    np.testing.assert_allclose(f.control, truth, atol=2e-3)
    assert f.subset([2, 0]).control.tolist() == f.control[[2, 0]].tolist()
    assert extract_harmonics(RecordingSet(tuple(recs), ("x", "y")), n_harmonics=2).control is None
    with pytest.raises(DataError, match="control channel 'x' expected apart from the planar"):
        RecordingSet(tuple(recs), ("x", "y"), control="x")
    with pytest.raises(DataError, match="r1.0: control channel 'v' expected"):
        RecordingSet(tuple(recs), ("x", "y"), control="v")


def test_single_segment_record_has_a_standard_error():
    # 2 s at 2.5 Hz: five periods, one segment, no spread to measure
    f = extract_harmonics(_set(2.0, 1000.0, 0.02), n_harmonics=2, frame=IDENTITY,
                          segment_periods=5.0)
    assert (f.n_segments == 1).all()
    assert (f.coeffs_se > 0).all() and (f.segment_rms == 0).all()
    z = np.abs(f.coeffs - TRUE[None]) / f.coeffs_se
    assert np.delete(z.reshape(2, -1), 3, axis=1).max() < 4.5


def test_less_than_one_period_is_refused():
    with pytest.raises(DataError, match="at least one period"):
        extract_harmonics(_set(0.3, 1000.0, 0.0), n_harmonics=2, frame=IDENTITY)


def _short_records(seed: int, duration: float, rho: float, fs: float = 1000.0):
    """Eight orbits of a smooth two-channel map of a circle, with AR(1) noise (not white).

    Written here, apart from the feature code: ``x_n = ρ x_{n−1} + √(1−ρ²) e_n``
    scaled to 1% of each channel's half peak-to-peak. Returns the noisy and the
    noiseless recording sets.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1 / fs)
    noisy, clean = [], []
    for i, r in enumerate(np.linspace(0.6, 1.4, 8)):
        ph = 2 * np.pi * (3.0 + 0.1 * r) * t + rng.uniform(0, 2 * np.pi)
        u1, u2 = r * np.cos(ph), r * np.sin(ph)
        chans = {"h": 0.02 * u1 + 0.004 * u2 + 0.003 * u1 * u2,
                 "alpha": 0.1 * u2 - 0.02 * u1 + 0.01 * u1**2 * u2}
        noise = {}
        for name, x in chans.items():
            e = rng.standard_normal(t.size)
            ar = np.empty_like(e)
            ar[0] = e[0]
            for n in range(1, e.size):
                ar[n] = rho * ar[n - 1] + np.sqrt(1 - rho**2) * e[n]
            noise[name] = x + 0.005 * np.ptp(x) * ar
        kw = dict(t=t, units={"h": "m", "alpha": "rad"}, mu=16 + 0.1 * i, branch="stable",
                  name=f"r{i}")
        noisy.append(Recording(channels=noise, **kw))
        clean.append(Recording(channels=chans, **kw))
    return (RecordingSet(tuple(noisy), planar=("h", "alpha")),
            RecordingSet(tuple(clean), planar=("h", "alpha")))


@pytest.mark.parametrize("duration", [2.0, 4.0])
def test_short_records_with_coloured_noise_have_calibrated_standard_errors(duration):
    # 2 s and 4 s at about 3 Hz: one or two segments, no spread to take an error from;
    # AR(1) noise with a 20 ms memory puts far more power near the fundamental than
    # white noise of the same variance (the white-noise error was several times too small)
    z = []
    for seed in range(300, 306):
        rs, clean = _short_records(seed, duration, rho=0.95)
        f = extract_harmonics(rs)
        f0 = extract_harmonics(clean, frame=f.frame)
        assert np.all(f.n_segments < 4)
        K = f.n_harmonics
        z.append(((f.coeffs - f0.coeffs) / f.coeffs_se)[:, :, [1, K + 1]].ravel())
    z = np.concatenate(z)
    z = z[z != 0]          # the first channel's crest sine is zero by the alignment
    # 90 standardised errors: their sd is within 0.7–1.4 if the errors are calibrated
    assert 0.7 < np.std(z) < 1.4
    assert np.mean(np.abs(z) > 1.645) < 0.2
