r"""Time-Fourier coefficients of each channel over a common phase origin.

The data side of the collapsed model (:mod:`bayeshopf.model.collapsed`). Each
recording is put in the common affine :class:`~bayeshopf.features.frame.PlanarFrame`
``w = L⁻¹(z − c)`` (no polar form, so an orbit need not encircle anything), cut
into segments of a few periods, and each segment's channels are fitted by least
squares with ``K`` harmonics of the record's frequency ω,

.. math::  w_c(t) \approx a_{c,0} + \sum_{k=1}^{K} a_{c,k}\cos k\omega t
           + b_{c,k}\sin k\omega t .

The time origin of every segment is then moved to the crest of the first
channel's fundamental (``b_{1,1} = 0``, ``a_{1,1} > 0``), which rotates the
harmonic ``k`` of both channels by ``k`` times the same phase. In normal-form
coordinates the LCO is the circle ``r(cos ωt, sin ωt)`` traversed at constant
speed (the rotational symmetry of the Hopf normal form), so these coefficients
are the map applied to a uniformly sampled circle, and they are linear in the
map's linear coefficients.

Each datum is the mean over segments; its measurement error is the standard
error of that mean (the spread over segments divided by √n), and never less
than the least-squares standard error of the whole record. A record of fewer
than :data:`MIN_SEGMENTS_FOR_SPREAD` segments has no usable spread: its error
is taken from the residual's spectrum beside each harmonic
(:func:`spectral_se`), which counts coloured noise where it moves the
coefficients, with the Student-t's variance of a scale estimated from a few
periodogram bins; a record too short for bins of its own (a few periods)
takes the spectrum of all such records pooled, and the white-noise
least-squares error where even those are too few.

**Control** (control-based continuation). When the recordings name a control
channel (the actuator command, :class:`~bayeshopf.data.RecordingSet`'s
``control``), its fundamental ``(u_a, u_b)`` is fitted on the same segments at
the same ω and moved to the same time origin, so it is in phase with the
orbit's coefficients: the measured input of the model's control term.

**Records with gaps.** A reader leaves out samples at which a sensor had no
reading (:class:`~bayeshopf.data.rig.ChannelSpec`), so ``t`` may skip whole
sample intervals. The least-squares fits use the samples that are there, at
their own times, and need no uniform sampling; the periodogram that starts the
frequency search puts the samples back on their uniform grid with zeros in the
gaps; segments are cut by time, so each covers the same span as without gaps.
The frame's centre and scale come from the samples that are there: gaps at one
phase move them a little, which only changes the frame (a common affine map).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from bayeshopf.data.recording import GAP_FACTOR, RecordingSet
from bayeshopf.errors import DataError
from bayeshopf.features.frame import PlanarFrame

#: Default harmonics per channel. The rig's second harmonic is about 4% of the
#: fundamental in pitch; above the fourth they sit at the noise floor.
DEFAULT_HARMONICS = 4
#: Default segment length in periods.
DEFAULT_SEGMENT_PERIODS = 5.0
#: Fewest segments from which a spread (and so a standard error) is taken.
MIN_SEGMENTS_FOR_SPREAD = 4
#: Fewest periodogram bins beside each harmonic from which its noise level is taken.
MIN_SPECTRAL_BINS = 4


def n_coefficients(n_harmonics: int) -> int:
    """``2K + 1`` coefficients per channel: ``[a_0, a_1..a_K, b_1..b_K]``."""
    return 2 * n_harmonics + 1


def coefficient_names(n_harmonics: int) -> list[str]:
    """Names ``a0, a1..aK, b1..bK`` of a channel's ``2K + 1`` Fourier coefficients, in order."""
    k = range(1, n_harmonics + 1)
    return ["a0", *(f"a{h}" for h in k), *(f"b{h}" for h in k)]


def time_design(t, omega: float, n_harmonics: int) -> np.ndarray:
    """Columns ``[1, cos ωt, …, cos Kωt, sin ωt, …, sin Kωt]``, shape ``(n_t, 2K+1)``."""
    kt = np.asarray(t)[:, None] * omega * np.arange(1, n_harmonics + 1)
    return np.concatenate([np.ones((kt.shape[0], 1)), np.cos(kt), np.sin(kt)], axis=1)


def phase_design(phi, n_harmonics: int) -> np.ndarray:
    """The same columns at phases φ (``time_design(φ, 1, K)``)."""
    return time_design(np.asarray(phi), 1.0, n_harmonics)


def shift_origin(coeffs: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """Coefficients of ``w(t + phase/ω)``: harmonic ``k`` rotated by ``k·phase``.

    Args:
        coeffs: Shape ``(..., n_channels, 2K+1)``.
        phase: Shape ``(...)``, radians of the fundamental.
    """
    K = (coeffs.shape[-1] - 1) // 2
    a, b = coeffs[..., 1 : K + 1], coeffs[..., K + 1 :]
    kp = np.asarray(phase)[..., None, None] * np.arange(1, K + 1)
    c, s = np.cos(kp), np.sin(kp)
    # x = Re Σ (a_k − i b_k) e^{ik ωt}; t → t + φ/ω multiplies by e^{ikφ}
    return np.concatenate([coeffs[..., :1], a * c + b * s, b * c - a * s], axis=-1)


def align_phase(coeffs: np.ndarray) -> np.ndarray:
    """The phase that moves the time origin to the crest of channel 0's fundamental."""
    K = (coeffs.shape[-1] - 1) // 2
    return np.arctan2(coeffs[..., 0, K + 1], coeffs[..., 0, 1])


def align(coeffs: np.ndarray) -> np.ndarray:
    """Move the time origin to the crest of channel 0's fundamental (``b_{0,1} = 0``)."""
    return shift_origin(coeffs, align_phase(coeffs))


def reconstruct(coeffs, phi) -> np.ndarray:
    """Orbit points at phases φ from coefficients ``(..., n_ch, 2K+1)``.

    Returns:
        Shape ``(..., n_phi, n_ch)``.
    """
    K = (np.shape(coeffs)[-1] - 1) // 2
    return phase_design(phi, K) @ np.swapaxes(np.asarray(coeffs), -1, -2)


def _grid_index(t: np.ndarray) -> tuple[np.ndarray, float]:
    """Index of each sample on the uniform grid of ``t`` and the grid's spacing.

    Without gaps (no spacing above :data:`~bayeshopf.data.recording.GAP_FACTOR`
    times the median) the indices are ``0..n−1`` and the spacing the mean one.
    """
    steps = np.diff(t)
    median = float(np.median(steps))
    if float(steps.max()) <= GAP_FACTOR * median:
        return np.arange(t.size), float((t[-1] - t[0]) / (t.size - 1))
    return np.rint((t - t[0]) / median).astype(np.int64), median


def fundamental_frequency(t: np.ndarray, w: np.ndarray, where: str) -> float:
    """Fundamental angular frequency: the periodogram's peak, refined by least squares.

    The peak of the channels' summed Hann-windowed periodogram, refined by
    SciPy's bounded scalar minimiser to within one bin of it: the frequency
    whose fit of a mean and one sinusoid per channel leaves the least residual.
    Samples of a record with gaps go back on their uniform grid, zero in the gaps.

    Args:
        t: Sample times, shape ``(n,)``.
        w: Samples, shape ``(n, n_channels)``.
        where: The record's name, for the error.

    Returns:
        ω in radians per unit of ``t``.

    Raises:
        DataError: When the periodogram has no peak above zero frequency.
    """
    x = w - w.mean(axis=0)
    idx, dt = _grid_index(t)
    n = int(idx[-1]) + 1
    if n != t.size:
        grid = np.zeros((n, x.shape[1]))
        grid[idx] = x
    else:
        grid = x
    spec = np.sum(np.abs(np.fft.rfft(grid * np.hanning(n)[:, None], axis=0)) ** 2, axis=1)
    spec[0] = 0.0
    k = int(np.argmax(spec))
    if k < 1 or spec[k] <= 0:
        raise DataError(f"{where}: an oscillation expected; found no spectral peak")
    f0 = k / (n * dt)
    df = 1.0 / (n * dt)

    tt = t - t[0]
    xx = float(np.sum(x * x))

    def residual(f):
        # least-squares residual of [1, cos, sin] by the normal equations (3 × 3):
        # ‖x‖² − cᵀG⁻¹c with G = AᵀA, c = Aᵀx, without forming A (a record has 10⁵ samples)
        wt = 2 * np.pi * f * tt
        cs = np.stack([np.cos(wt), np.sin(wt)])
        G = np.empty((3, 3))
        G[0, 0] = tt.size
        G[0, 1:] = G[1:, 0] = cs.sum(axis=1)
        G[1:, 1:] = cs @ cs.T
        c = np.concatenate([x.sum(axis=0)[None], cs @ x])
        return xx - float(np.sum(c * np.linalg.solve(G, c)))

    res = minimize_scalar(residual, bounds=(max(f0 - df, 0.5 * f0), f0 + df), method="bounded",
                          options={"xatol": 1e-6 * f0})
    return 2 * np.pi * float(res.x)


def noise_bins(resid: np.ndarray, idx: np.ndarray, dt: float, omega: float,
               n_harmonics: int) -> list[np.ndarray]:
    """The residual's periodogram beside each harmonic (the bins :func:`spectral_se` averages).

    Args:
        resid: Residuals of the whole record's fit, ``(n_t, n_ch)``.
        idx: Each sample's index on the uniform grid (gaps skipped).
        dt: The grid's spacing (s).
        omega: The fundamental angular frequency (rad/s).
        n_harmonics: K.

    Returns:
        For ``k = 0..K``, the one-sided spectral density (units²/Hz) in the
        bins within half a harmonic spacing of ``kω/2π`` and outside the Hann
        window's main lobe about it, ``(n_bins_k, n_ch)``.
    """
    from scipy.signal import periodogram

    n_grid = int(idx[-1]) + 1
    grid = np.zeros((n_grid, resid.shape[1]))
    grid[idx] = resid
    f, p = periodogram(grid, fs=1.0 / dt, window="hann", detrend=False, axis=0)
    p = p * (n_grid / idx.size)          # zeros in the gaps carry no power
    f0 = omega / (2 * np.pi)
    lobe = 2.0 / (n_grid * dt)           # the Hann window's main lobe, half width
    out = []
    for k in range(n_harmonics + 1):
        d = np.abs(f - k * f0)
        out.append(p[(d <= 0.5 * f0) & (d >= lobe) & (f > 0)])
    return out


def spectral_se(bins: list[np.ndarray], duration: float) -> np.ndarray | None:
    r"""Standard errors of the coefficients from the noise's spectrum beside each harmonic.

    Least squares over a record of duration ``T`` estimates a harmonic's
    coefficients with variance ``S(f_k)/T`` (``a_k``, ``b_k``) and ``S(0)/(2T)``
    (``a_0``) when the noise is stationary with one-sided spectral density
    ``S`` near the harmonic's frequency ``f_k = kω/2π`` (Brockwell & Davis,
    *Time Series: Theory and Methods*, §10.3); white noise of variance σ² gives
    the familiar ``2σ²/N``. ``S(f_k)`` is the mean of the residual's Hann
    periodogram over the bins beside ``f_k`` (:func:`noise_bins`). Coloured
    noise, such as a sensor's low-frequency wander or turbulence, is thereby
    counted at the frequencies where it moves the coefficients, which the
    white-noise error of the least squares misses and a spread over two or
    three segments estimates with one or two degrees of freedom. A level
    averaged over ``n`` bins is itself an estimate with about ``n`` degrees of
    freedom: the variance is multiplied by ``n/(n − 2)``, the variance of the
    Student-t that the estimated scale implies, so that a short record's error
    enters the Gaussian likelihood with the right second moment.

    Args:
        bins: :func:`noise_bins`' bins for ``k = 0..K`` (a record's own, or
            several records' pooled).
        duration: The record's duration with samples (s).

    Returns:
        ``(n_ch, 2K+1)`` standard errors, or ``None`` when some harmonic has
        fewer than :data:`MIN_SPECTRAL_BINS` bins.
    """
    level = []
    for b in bins:
        n = b.shape[0]
        if n < MIN_SPECTRAL_BINS:
            return None
        level.append(b.mean(axis=0) * n / (n - 2))
    level = np.array(level).T            # (n_ch, K+1)
    var = np.concatenate([level[:, :1] / 2, level[:, 1:], level[:, 1:]], axis=1) / duration
    return np.sqrt(var)


def _short_record_se(short: list[dict], n_harmonics: int) -> None:
    """Fill ``se`` of the records with too few segments for a spread (in place).

    Each takes its own spectrum beside the harmonics (:func:`spectral_se`);
    one whose own has too few bins (a record of a few periods) takes the bins
    of every such record pooled (the same sensors; the frame is common), and
    without enough of those the white-noise least-squares error. The crest's
    sine of the first channel is zero by the alignment, whatever the noise,
    and keeps the least-squares error.
    """
    pooled = [np.concatenate([r["bins"][k] for r in short]) for k in range(n_harmonics + 1)]
    for r in short:
        se = spectral_se(r["bins"], r["duration"])
        if se is None:
            se = spectral_se(pooled, r["duration"])
        if se is None:
            se = r["se_ls"].copy()
        se[0, n_harmonics + 1] = r["se_ls"][0, n_harmonics + 1]
        r["se"][...] = se


@dataclass(frozen=True)
class HarmonicFeatures:
    """Phase-aligned time-Fourier coefficients of every recording (immutable).

    Attributes:
        mu: μ of each recording, ``(n_rec,)``.
        unstable: Branch mask, ``(n_rec,)``.
        coeffs: Mean aligned coefficients in the frame, ``(n_rec, 2, 2K+1)``.
        coeffs_se: Their standard errors, same shape.
        segment_rms: RMS distance of the segments' orbits from the mean orbit
            (frame units), ``(n_rec,)``; 0 for a single segment.
        n_segments: Segments per recording.
        omega: Angular frequency (rad/s) per recording.
        omega_se: Its standard error: the spread of the ``n`` segments' own
            frequencies over ``n^{3/2}`` (ω is fitted on the whole record, whose
            error falls as its length to the power −3/2), or 0 for one segment.
        amplitude: Peak-to-peak of z1 of the mean orbit (z1's unit).
        amplitude_sd: Spread of the segments' amplitudes.
        frame: The common planar frame.
        n_harmonics: K.
        names: Recording names.
        control: The control channel's fundamental ``(u_a, u_b)`` on the same
            time origin (its unit), ``(n_rec, 2)``; ``None`` without a control
            channel.
    """

    mu: np.ndarray
    unstable: np.ndarray
    coeffs: np.ndarray
    coeffs_se: np.ndarray
    segment_rms: np.ndarray
    n_segments: np.ndarray
    omega: np.ndarray
    omega_se: np.ndarray
    amplitude: np.ndarray
    amplitude_sd: np.ndarray
    frame: PlanarFrame
    n_harmonics: int
    names: tuple[str, ...]
    control: np.ndarray | None = None

    @property
    def n_recordings(self) -> int:
        """Number of recordings."""
        return int(self.mu.size)

    @property
    def frequency_hz(self) -> np.ndarray:
        """``ω/2π`` per recording."""
        return self.omega / (2 * np.pi)

    def subset(self, indices) -> HarmonicFeatures:
        """Features of the recordings at ``indices`` (frame kept)."""
        idx = np.asarray(indices)
        arrays = {k: getattr(self, k)[idx] for k in (
            "mu", "unstable", "coeffs", "coeffs_se", "segment_rms", "n_segments", "omega",
            "omega_se", "amplitude", "amplitude_sd")}
        return HarmonicFeatures(**arrays, frame=self.frame, n_harmonics=self.n_harmonics,
                                names=tuple(self.names[i] for i in idx),
                                control=None if self.control is None else self.control[idx])

    def orbit(self, n_phi: int = 128) -> np.ndarray:
        """Mean orbits in the frame at uniform phases, ``(n_rec, n_phi, 2)``."""
        return reconstruct(self.coeffs, np.linspace(0, 2 * np.pi, n_phi, endpoint=False))


def _amplitude(coeffs, frame: PlanarFrame, n_phi: int = 256) -> np.ndarray:
    w = reconstruct(coeffs, np.linspace(0, 2 * np.pi, n_phi, endpoint=False))
    z1 = frame.from_frame(w)[..., 0]
    return z1.max(axis=-1) - z1.min(axis=-1)


def extract_harmonics(
    rs: RecordingSet,
    *,
    n_harmonics: int = DEFAULT_HARMONICS,
    segment_periods: float = DEFAULT_SEGMENT_PERIODS,
    frame: PlanarFrame | None = None,
) -> HarmonicFeatures:
    """Phase-aligned harmonic coefficients of every recording (module docstring).

    Args:
        rs: The recordings; their planar pair (z1, z2) is used.
        n_harmonics: Harmonics K per channel.
        segment_periods: Segment length in periods.
        frame: Frame to use (a fit's, for new recordings); by default the one
            :meth:`PlanarFrame.from_orbits` builds from ``rs``.

    Returns:
        The :class:`HarmonicFeatures`.

    Raises:
        DataError: If a record holds less than one period or fewer samples than
            ``4(2K+1)``.
    """
    if n_harmonics < 1:
        raise DataError(f"n_harmonics must be a positive integer; got {n_harmonics}")
    orbits = [r.planar(rs.planar) for r in rs]
    if frame is None:
        frame = PlanarFrame.from_orbits(orbits, rs.planar, rs.units)
    n_c = n_coefficients(n_harmonics)
    out = {k: [] for k in ("c", "se", "rms", "nseg", "om", "om_se", "amp", "amp_sd", "u")}
    phi = np.linspace(0, 2 * np.pi, 128, endpoint=False)
    short = []      # records too short for a spread over segments
    for rec, z in zip(rs, orbits, strict=True):
        w = frame.to_frame(z)
        t = rec.t - rec.t[0]
        if t.size < 4 * n_c:
            raise DataError(f"{rec.name}: at least {4 * n_c} samples expected for "
                            f"{n_harmonics} harmonics; found {t.size}")
        omega = fundamental_frequency(t, w, rec.name)
        if omega * rec.duration < 2 * np.pi:
            raise DataError(f"{rec.name}: at least one period expected; found "
                            f"{omega * rec.duration / (2 * np.pi):.2f} periods")
        idx, dt = _grid_index(t)          # 0..n-1 without gaps
        n_grid = int(idx[-1]) + 1
        seg_len = max(int(round(segment_periods * 2 * np.pi / omega / dt)), 4 * n_c)
        n_seg = max(1, n_grid // seg_len)
        # segments by grid index (by time); a segment left with too few samples is skipped
        cuts = np.searchsorted(idx, np.arange(n_seg + 1) * seg_len)
        cuts[-1] = t.size
        slices = [slice(a, b) for a, b in zip(cuts[:-1], cuts[1:], strict=True)
                  if b - a >= 4 * n_c]
        if not slices:
            slices = [slice(0, t.size)]
        n_seg = len(slices)
        u = None if rs.control is None else rec.channel(rs.control)[:, None]
        seg, seg_u, seg_om = [], [], []
        for sl in slices:
            A = time_design(t[sl], omega, n_harmonics)
            y = w[sl] if u is None else np.concatenate([w[sl], u[sl]], axis=1)
            c = np.linalg.lstsq(A, y, rcond=None)[0].T
            seg.append(c[:2])
            if u is not None:
                seg_u.append(c[2:])
            if n_seg > 1:  # the segment's own frequency, for the frequency's spread
                seg_om.append(fundamental_frequency(t[sl], w[sl], rec.name))
        seg = np.array(seg)
        origin = align_phase(seg)
        seg = shift_origin(seg, origin)
        if u is not None:
            cu = shift_origin(np.array(seg_u), origin).mean(axis=0)[0]
            out["u"].append([cu[1], cu[n_harmonics + 1]])
        mean = seg.mean(axis=0)
        # least-squares standard error of the whole record (white-noise floor)
        A = time_design(t, omega, n_harmonics)
        # by the normal equations: the Fourier columns over many periods are near-orthogonal
        # (the same numbers as lstsq to 1e-16 on the rig; the 7 records take 0.75 s, not 0.84)
        G_inv = np.linalg.inv(A.T @ A)
        whole = G_inv @ (A.T @ w)
        resid = w - A @ whole
        dof = max(t.size - n_c, 1)
        se_ls = np.sqrt(np.outer(np.sum(resid**2, axis=0) / dof, np.diag(G_inv)))
        if n_seg >= MIN_SEGMENTS_FOR_SPREAD:
            se = np.maximum(seg.std(axis=0, ddof=1) / np.sqrt(n_seg), se_ls)
        else:       # too few segments for a spread: the noise beside each harmonic
            se = np.empty_like(se_ls)
            short.append({"se": se, "se_ls": se_ls, "duration": idx.size * dt,
                          "bins": noise_bins(resid, idx, dt, omega, n_harmonics)})
        orbit_mean = reconstruct(mean, phi)
        dev = reconstruct(seg, phi) - orbit_mean
        out["c"].append(mean)
        out["se"].append(se)
        out["rms"].append(float(np.sqrt(np.mean(np.sum(dev**2, axis=-1)))) if n_seg > 1 else 0.0)
        out["nseg"].append(n_seg)
        out["om"].append(omega)
        # the record's frequency is fitted on all n segments together: its error is the
        # segments' spread over n^(3/2) (a frequency's variance falls as T^-3), not over √n
        out["om_se"].append(float(np.std(seg_om, ddof=1) / n_seg**1.5) if n_seg > 1 else 0.0)
        out["amp"].append(float(_amplitude(mean, frame)))
        out["amp_sd"].append(float(_amplitude(seg, frame).std(ddof=1)) if n_seg > 1 else 0.0)
    if short:
        _short_record_se(short, n_harmonics)
    return HarmonicFeatures(
        mu=rs.mus, unstable=rs.is_unstable, coeffs=np.array(out["c"]),
        coeffs_se=np.array(out["se"]), segment_rms=np.array(out["rms"]),
        n_segments=np.array(out["nseg"]), omega=np.array(out["om"]),
        omega_se=np.array(out["om_se"]), amplitude=np.array(out["amp"]),
        amplitude_sd=np.array(out["amp_sd"]), frame=frame, n_harmonics=n_harmonics,
        names=tuple(rs.names), control=None if rs.control is None else np.array(out["u"]),
    )
