r"""Orbit features per channel in the time domain: frequency and Fourier coefficients.

For a recording with observed channels :math:`y_c(t)` and frequency
:math:`f`, the orbit of each channel is

.. math::  y_c(t) = C_{c,0}
           + \sum_{k=1}^{K} \big(C_{c,k}\,e^{ik\omega t} + \text{c.c.}\big),
           \qquad \omega = 2\pi f,

and the phase is fixed by turning time so that the first harmonic of the first
planar channel is real and positive, :math:`C'_{c,k} = C_{c,k}\,e^{-ik\arg C_{z_1,1}}`.
The feature vector of one orbit is :math:`f`, the real and imaginary parts of
:math:`C'_{c,k}` for :math:`k = 1..K` (less the imaginary part of
:math:`C'_{z_1,1}`, zero by construction) and the means :math:`C_{c,0}`.

**Measured.** :math:`f` is the peak of the periodogram of :math:`z_1`, refined
by a least-squares fit of its fundamental to the whole record (the core's
:func:`~bayeshopf.features.harmonics.fundamental_frequency`), then by the
drift of the first harmonic's phase across segments (below). The
record is cut into segments of ``segment_periods`` periods; in each segment the
coefficients are fitted by linear least squares at that :math:`f` and turned
to the common phase. The feature is the mean over segments and its standard
error the spread over segments divided by :math:`\sqrt{n_{seg}}`. The standard
error of :math:`f` comes from the drift of the first-harmonic phase across
segments (a straight-line fit of the unwrapped phase against time).

**Simulated.** The same coefficients from the samples of a periodic orbit
(:func:`numpy.fft.rfft` over one period) and :math:`f = 1/T`.

The means :math:`C_{c,0}` include each sensor's unknown offset;
:mod:`bayeshopf.discrepancy.select` removes it with one nuisance offset per
channel shared by all recordings.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayeshopf.data.recording import RecordingSet
from bayeshopf.errors import DataError
from bayeshopf.features.harmonics import fundamental_frequency

__all__ = ["FeatureLayout", "MeasuredFeatures", "measure", "orbit_coefficients", "simulated"]

#: Harmonics per channel.
DEFAULT_K = 5
#: Segment length in periods.
DEFAULT_SEGMENT_PERIODS = 2.0


@dataclass(frozen=True)
class FeatureLayout:
    """Names and kinds of the entries of one recording's feature vector.

    Attributes:
        channels: Observed channels, the first is the phase reference.
        K: Harmonics per channel.
        labels: One label per entry: ``"f"``, ``"h:Re3"``, ``"alpha:mean"``...
        kind: ``"f"``, ``"harm"`` or ``"mean"`` per entry.
        channel: Channel of each entry (``""`` for f).
        harmonic: Harmonic of each entry (0 for f and means).
    """

    channels: tuple[str, ...]
    K: int
    labels: tuple[str, ...]
    kind: tuple[str, ...]
    channel: tuple[str, ...]
    harmonic: tuple[int, ...]

    @classmethod
    def make(cls, channels, K: int) -> FeatureLayout:
        """The layout for ``channels`` (reference first) and ``K`` harmonics."""
        labels, kind, chan, harm = ["f"], ["f"], [""], [0]
        for j, c in enumerate(channels):
            for k in range(1, K + 1):
                for part in ("Re", "Im"):
                    if j == 0 and k == 1 and part == "Im":
                        continue
                    labels.append(f"{c}:{part}{k}")
                    kind.append("harm")
                    chan.append(c)
                    harm.append(k)
        for c in channels:
            labels.append(f"{c}:mean")
            kind.append("mean")
            chan.append(c)
            harm.append(0)
        return cls(tuple(channels), K, tuple(labels), tuple(kind), tuple(chan), tuple(harm))

    @property
    def size(self) -> int:
        """Entries per recording."""
        return len(self.labels)

    def pack(self, f, C: np.ndarray) -> np.ndarray:
        """Feature vector from ``f`` and phase-fixed coefficients ``C`` of shape ``(n_ch, K+1)``.

        With a leading batch axis (``f`` of shape ``(B,)``, ``C`` of ``(B, n_ch, K+1)``)
        the vectors are the rows of a ``(B, size)`` array.
        """
        C = np.asarray(C)
        f = np.asarray(f, dtype=np.float64)
        n_ch, K = len(self.channels), self.K
        cols = [f[..., None]]
        for j in range(n_ch):
            re, im = C[..., j, 1:].real, C[..., j, 1:].imag                # (..., K)
            pairs = np.stack([re, im], axis=-1).reshape(*re.shape[:-1], 2 * K)
            cols.append(np.delete(pairs, 1, axis=-1) if j == 0 else pairs)  # C[0, 1] is real
        cols.append(C[..., :, 0].real)
        return np.concatenate(cols, axis=-1).astype(np.float64)


def _fix_phase(C: np.ndarray) -> np.ndarray:
    """Turn ``C`` (..., n_ch, K+1) so that ``C[..., 0, 1]`` is real and positive."""
    k = np.arange(C.shape[-1])
    return C * np.exp(-1j * k * np.angle(C[..., 0, 1])[..., None])[..., None, :]


def orbit_coefficients(samples: np.ndarray, K: int) -> np.ndarray:
    """Phase-fixed :math:`C_{c,k}` of samples over one period, shape ``(n_ch, K+1)``.

    Args:
        samples: Shape ``(n_points, n_ch)``, uniform in time over one period;
            or ``(B, n_points, n_ch)`` for ``B`` orbits (then ``(B, n_ch, K+1)``).
        K: Harmonics.
    """
    C = np.fft.rfft(samples, axis=-2)[..., : K + 1, :] / samples.shape[-2]
    return _fix_phase(np.swapaxes(C, -1, -2))


def simulated(layout: FeatureLayout, samples: np.ndarray, period) -> np.ndarray:
    """The feature vector of a simulated orbit (samples of the observed channels).

    With a leading batch axis (``samples`` ``(B, n_points, n_ch)``, ``period``
    ``(B,)``), one vector per row.
    """
    return layout.pack(1.0 / np.asarray(period, dtype=np.float64),
                       orbit_coefficients(samples, layout.K))


def _design(t: np.ndarray, f: float, K: int) -> np.ndarray:
    wt = 2 * np.pi * f * t
    cols = [np.ones_like(t)]
    for k in range(1, K + 1):
        cols += [np.cos(k * wt), np.sin(k * wt)]
    return np.stack(cols, axis=1)


def _coeffs(t, Y, f, K) -> np.ndarray:
    """Least-squares ``C`` (n_ch, K+1) of ``Y`` (n_t, n_ch) at frequency ``f``."""
    A = _design(t, f, K)
    sol, *_ = np.linalg.lstsq(A, Y, rcond=None)
    C = np.empty((Y.shape[1], K + 1), dtype=complex)
    C[:, 0] = sol[0]
    for k in range(1, K + 1):
        C[:, k] = 0.5 * (sol[2 * k - 1] - 1j * sol[2 * k])
    return C


@dataclass(frozen=True)
class MeasuredFeatures:
    """Features of every recording of a set.

    Attributes:
        layout: The entries of one feature vector.
        names: Recording names.
        mu: μ per recording.
        branch: Branch per recording.
        y: Features, shape ``(R, layout.size)``.
        se: Their standard errors, same shape.
        n_segments: Segments per recording.
        amplitude: Measured half peak-to-peak per channel, shape ``(R, n_ch)``.
    """

    layout: FeatureLayout
    names: tuple[str, ...]
    mu: np.ndarray
    branch: tuple[str, ...]
    y: np.ndarray
    se: np.ndarray
    n_segments: np.ndarray
    amplitude: np.ndarray


def _channels(rs: RecordingSet, channels) -> tuple[str, ...]:
    chans = tuple(channels)
    for r in rs:
        missing = [c for c in chans if c not in r.channels]
        if missing:
            raise DataError(f"{r.name}: channel(s) {', '.join(missing)} expected (the simulator's "
                            f"observed states); found {', '.join(r.channels)}")
    return chans


def measure(rs: RecordingSet, channels, *, K: int = DEFAULT_K,
            segment_periods: float = DEFAULT_SEGMENT_PERIODS) -> MeasuredFeatures:
    """Features of every recording (module docstring).

    Args:
        rs: The recordings.
        channels: The channels to use, phase reference first (the simulator's
            observed states, planar first channel first).
        K: Harmonics per channel.
        segment_periods: Segment length in periods.

    Raises:
        DataError: If a channel is missing, or a record is shorter than two segments.
    """
    chans = _channels(rs, channels)
    layout = FeatureLayout.make(chans, K)
    ys, ses, nseg, amps = [], [], [], []
    for r in rs:
        t = np.asarray(r.t) - r.t[0]
        Y = np.stack([np.asarray(r.channels[c]) for c in chans], axis=1)
        f = fundamental_frequency(t, Y[:, :1], r.name) / (2 * np.pi)
        n_per = int(round(segment_periods / (f * r.dt)))
        m = t.size // max(n_per, 1)
        if m < 2:
            raise DataError(f"{r.name}: a record of at least {2 * segment_periods:g} periods "
                            f"expected; found {t[-1] * f:.3g}")
        Cs, ph, tc = [], [], []
        for j in range(m):
            sl = slice(j * n_per, (j + 1) * n_per)
            C = _coeffs(t[sl], Y[sl], f, K)
            ph.append(np.angle(C[0, 1]))
            tc.append(t[sl].mean())
            Cs.append(_fix_phase(C))
        ph_u, tc = np.unwrap(np.asarray(ph)), np.asarray(tc)
        A = np.stack([np.ones_like(tc), tc], axis=1)
        sol, *_ = np.linalg.lstsq(A, ph_u, rcond=None)
        resid = ph_u - A @ sol
        cov = np.linalg.inv(A.T @ A) * (resid @ resid) / max(m - 2, 1)
        f_hat = f + sol[1] / (2 * np.pi)
        f_se = np.sqrt(cov[1, 1]) / (2 * np.pi)
        V = np.stack([layout.pack(f_hat, C) for C in Cs])
        y = V.mean(axis=0)
        se = V.std(axis=0, ddof=1) / np.sqrt(m)
        y[0], se[0] = f_hat, f_se
        ys.append(y)
        ses.append(se)
        nseg.append(m)
        Cm = np.mean(np.stack(Cs), axis=0)
        amps.append([np.ptp(np.real(np.fft.irfft(
            np.concatenate([Cm[j], np.zeros(64 - K - 1)]) * 128, 128))) / 2
            for j in range(len(chans))])
    return MeasuredFeatures(layout=layout, names=tuple(r.name for r in rs),
                            mu=np.array([r.mu for r in rs]),
                            branch=tuple(r.branch for r in rs), y=np.array(ys), se=np.array(ses),
                            n_segments=np.array(nseg), amplitude=np.array(amps))
