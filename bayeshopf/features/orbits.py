"""From recordings to per-orbit Fourier features (the data side of loss Ξ_U).

Each recording is put in the common :class:`PlanarFrame`, cut into segments of a
few periods, and each segment's ``R(θ)`` is projected on ``n_h`` harmonics. The
mean over segments is the orbit's feature vector; the spread over segments is
its measurement uncertainty. Using all of each record (not the paper's first
1.2 s) averages the noise, and the segment spread exposes what the paper's
features hide: the CBC-held unstable orbits drift during a record.

The amplitude used everywhere in bayeshopf is the peak-to-peak of z1 over the
orbit, in z1's physical unit. For a measurement the orbit is the Fourier
reconstruction of its mean coefficients; for the model it is the mapped
normal-form orbit. The paper's diagrams use heave peak-to-peak.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayeshopf.data.recording import RecordingSet
from bayeshopf.errors import DataError
from bayeshopf.features import fourier
from bayeshopf.features.frame import PlanarFrame

#: Default number of harmonics of R(θ). In the whitened frame the orbits are
#: close to circles and their R(θ) is smooth: on the wind-tunnel data, harmonics
#: above 8 are below 0.3 % of a0 and at the noise floor.
DEFAULT_N_HARMONICS = 8
#: Default segment length, in periods, for the per-segment features.
DEFAULT_SEGMENT_PERIODS = 5.0
#: Angular bins that a recording must visit to count as encircling the centre.
_N_ANGLE_BINS = 16


@dataclass(frozen=True)
class OrbitFeatures:
    """Fourier features of every recording of a set, in a common frame.

    Attributes:
        mu: μ of each recording, shape ``(n_rec,)``.
        unstable: Branch mask, shape ``(n_rec,)`` (True for unstable).
        coeffs: Mean coefficients over segments, shape ``(n_rec, 2 n_h + 1)``.
        coeffs_sd: Spread (standard deviation) of the coefficients over
            segments, same shape; zero where a record has a single segment.
        n_segments: Segments per recording, shape ``(n_rec,)``.
        amplitude: Measured peak-to-peak of z1, shape ``(n_rec,)``.
        amplitude_sd: Spread of the per-segment amplitudes, shape ``(n_rec,)``.
        frequency_hz: Mean oscillation frequency (signed: positive for
            counter-clockwise in the frame), shape ``(n_rec,)``.
        frame: The common planar frame.
        n_h: Number of harmonics.
        names: Recording names.
    """

    mu: np.ndarray
    unstable: np.ndarray
    coeffs: np.ndarray
    coeffs_sd: np.ndarray
    n_segments: np.ndarray
    amplitude: np.ndarray
    amplitude_sd: np.ndarray
    frequency_hz: np.ndarray
    frame: PlanarFrame
    n_h: int
    names: tuple[str, ...]

    @property
    def n_recordings(self) -> int:
        """Number of recordings."""
        return int(self.mu.size)

    def subset(self, indices) -> OrbitFeatures:
        """Features of the recordings at ``indices`` (frame kept)."""
        idx = np.asarray(indices)
        return OrbitFeatures(
            self.mu[idx],
            self.unstable[idx],
            self.coeffs[idx],
            self.coeffs_sd[idx],
            self.n_segments[idx],
            self.amplitude[idx],
            self.amplitude_sd[idx],
            self.frequency_hz[idx],
            self.frame,
            self.n_h,
            tuple(self.names[i] for i in idx),
        )


def amplitude_of_curve(z1) -> np.ndarray:
    """Peak-to-peak of z1 along a curve (last axis runs along the orbit)."""
    return np.max(z1, axis=-1) - np.min(z1, axis=-1)


def amplitude_from_coeffs(coeffs, frame: PlanarFrame, n_points: int = 512) -> np.ndarray:
    """Peak-to-peak of z1 of the orbit whose frame-R(θ) has these coefficients."""
    z = frame.from_frame(fourier.curve(np.asarray(coeffs), n_points))
    return amplitude_of_curve(z[..., 0])


def _winding(theta: np.ndarray) -> tuple[float, np.ndarray]:
    unwrapped = np.unwrap(theta)
    turns = (unwrapped[-1] - unwrapped[0]) / (2 * np.pi)
    bins = np.floor((theta + np.pi) / (2 * np.pi) * _N_ANGLE_BINS).astype(int) % _N_ANGLE_BINS
    return float(turns), np.bincount(bins, minlength=_N_ANGLE_BINS)


def _encircles(w: np.ndarray) -> bool:
    """Whether points ``w`` (in the frame) wind round the origin twice, visiting every sector."""
    turns, visits = _winding(fourier.polar(w)[1])
    return abs(turns) >= 2 and bool(np.all(visits > 0))


def extract_features(
    rs: RecordingSet,
    *,
    n_h: int = DEFAULT_N_HARMONICS,
    segment_periods: float = DEFAULT_SEGMENT_PERIODS,
    frame: PlanarFrame | None = None,
) -> OrbitFeatures:
    """Fourier features of every recording (the measured ``Φ(R_i)`` of eq. XiU).

    Args:
        rs: The recordings; their planar pair (z1, z2) is used.
        n_h: Number of harmonics of R(θ).
        segment_periods: Length of a segment in periods of the oscillation.
        frame: Planar frame to use; by default built from ``rs``
            (:meth:`PlanarFrame.from_orbits`, centred on the mean of the orbit
            means, or on the point deepest inside every orbit when some orbit
            does not encircle that mean). Pass a fit's frame to featurise new
            recordings consistently.

    Returns:
        The :class:`OrbitFeatures` of the set.

    Raises:
        DataError: If an orbit does not encircle the common centre (it then has
            no polar representation R(θ)), or a record is shorter than one
            period or than ``2 n_h + 1`` samples.
    """
    if n_h < 1:
        raise DataError(f"n_h must be a positive integer; got {n_h}")
    orbits = [r.planar(rs.planar) for r in rs]
    if frame is None:
        frame = PlanarFrame.from_orbits(orbits, rs.planar, rs.units)
        if not all(_encircles(frame.to_frame(z)) for z in orbits):
            # the orbit centres drift more than the smallest orbits are wide:
            # take the point deepest inside every orbit (frame module docstring)
            frame = PlanarFrame.from_orbits(orbits, rs.planar, rs.units, centre="deepest")
    n_c = fourier.n_coefficients(n_h)
    out = {k: [] for k in ("c", "sd", "nseg", "amp", "amp_sd", "f")}
    for rec, z in zip(rs, orbits, strict=True):
        w = frame.to_frame(z)
        R, theta = fourier.polar(w)
        turns, visits = _winding(theta)
        if abs(turns) < 2 or np.any(visits == 0):
            raise DataError(
                f"{rec.name}: the orbit in ({rs.planar[0]}, {rs.planar[1]}) must encircle the "
                f"common centre {np.round(frame.centre, 6).tolist()} at least twice; found "
                f"{abs(turns):.2f} turns and {int(np.sum(visits == 0))} of {_N_ANGLE_BINS} "
                "angular sectors never visited (is this recording an oscillation, and is its "
                "offset much larger than its amplitude?)"
            )
        freq = turns / rec.duration
        seg_len = max(int(round(segment_periods / abs(freq) / rec.dt)), n_c * 4)
        n_seg = max(1, rec.t.size // seg_len)
        seg_coeffs = np.array(
            [
                fourier.project(
                    theta[i * seg_len : (i + 1) * seg_len], R[i * seg_len : (i + 1) * seg_len], n_h
                )
                for i in range(n_seg)
            ]
        )
        seg_amp = amplitude_from_coeffs(seg_coeffs, frame)
        mean = seg_coeffs.mean(axis=0)
        out["c"].append(mean)
        out["sd"].append(seg_coeffs.std(axis=0, ddof=1) if n_seg > 1 else np.zeros(n_c))
        out["nseg"].append(n_seg)
        out["amp"].append(float(amplitude_from_coeffs(mean, frame)))
        out["amp_sd"].append(float(seg_amp.std(ddof=1)) if n_seg > 1 else 0.0)
        out["f"].append(freq)
    return OrbitFeatures(
        mu=rs.mus,
        unstable=rs.is_unstable,
        coeffs=np.array(out["c"]),
        coeffs_sd=np.array(out["sd"]),
        n_segments=np.array(out["nseg"]),
        amplitude=np.array(out["amp"]),
        amplitude_sd=np.array(out["amp_sd"]),
        frequency_hz=np.array(out["f"]),
        frame=frame,
        n_h=n_h,
        names=tuple(rs.names),
    )
