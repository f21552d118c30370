r"""The ground truth of a simulated experiment, and the paper's Section 4 experiments.

A fit of simulated recordings is checked against the simulator's own answers:
the Hopf point :math:`\mu_0` (Jacobian eigenvalues), the fold of cycles
:math:`\mu_{SN}` and the amplitude of every periodic orbit (shooting and
continuation, :mod:`bayeshopf.simulators.continuation`). The model's normal form
:math:`\dot r = (\mu-\mu_0) r + a_2 r^3 - r^5` has its fold at
:math:`\mu_{SN} = \mu_0 - a_2^2/4`, so the true :math:`a_2` of a subcritical
system is

.. math::  a_2 = 2\sqrt{\mu_0 - \mu_{SN}}

(the paper reports 3.65 for the 3-DOF aerofoil). For a supercritical system
the scale of :math:`a_2` is set by the learnt map and has no true value;
:math:`\mu_0` is the check.

**The true bifurcation diagram.** The continuation gives the peak-to-peak
:math:`A_k` of the observed channel at points :math:`\mu_k` along each branch.
Near the Hopf point :math:`\mu_0 - \mu \propto A^2` and near a fold
:math:`\mu - \mu_{SN} \propto (A - A_{SN})^2`, so :math:`\mu` is a smooth
function of :math:`A` along a branch while :math:`A(\mu)` has square-root ends.
:func:`amplitude_truth` therefore interpolates :math:`\mu(A)` on each branch by
a cubic spline (with the Hopf point :math:`(\mu_0, 0)` added) and inverts it
on a dense grid; inside a branch it is checked against Newton-corrected
orbits (:func:`~bayeshopf.simulators.orbit_at`).

**The experiments** (:func:`flutter_experiment`, :func:`vanderpol_experiment`)
are the paper's Section 4 data sets made blind and realistic: noisy recordings
(1 % relative RMS noise, sensor offsets drawn from the seed) of the μ plans
:data:`FLUTTER_PLAN` and :data:`VANDERPOL_PLAN`, with held-out orbits
(:data:`FLUTTER_HELD_OUT`, :data:`VANDERPOL_HELD_OUT`) to check predictions.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from bayeshopf._x64 import ensure_x64
from bayeshopf.data.recording import RecordingSet
from bayeshopf.diagnostics.summaries import interval
from bayeshopf.simulators.base import SimulationError
from bayeshopf.simulators.continuation import BifurcationDiagram, bifurcation_diagram
from bayeshopf.simulators.recordings import simulate_recordings
from bayeshopf.simulators.registry import get_system

__all__ = [
    "FLUTTER_HELD_OUT",
    "FLUTTER_PLAN",
    "VANDERPOL_HELD_OUT",
    "VANDERPOL_PAPER_PLAN",
    "VANDERPOL_PLAN",
    "SimulatedTruth",
    "amplitude_truth",
    "flutter_experiment",
    "held_out_check",
    "held_out_recordings",
    "vanderpol_experiment",
]

#: Training plan of the 3-DOF aerofoil (m/s): 4 stable and 4 unstable LCOs
#: spread over the bistable range (fold 14.94, Hopf 18.27 m/s), the outer ones
#: within 0.1–0.3 m/s of the fold and the Hopf point, as a CBC experiment can
#: measure them. (A plan whose unstable orbits stop well short of the Hopf
#: point, such as the simulator's ``default_plan``, leaves μ0 and the fold to an
#: extrapolation.)
FLUTTER_PLAN: tuple[tuple[float, str], ...] = (
    (15.0, "stable"), (15.8, "stable"), (16.6, "stable"), (17.4, "stable"),
    (15.1, "unstable"), (16.2, "unstable"), (17.2, "unstable"), (18.0, "unstable"),
)
#: Held-out orbits of the 3-DOF aerofoil, between and beyond the training μ.
FLUTTER_HELD_OUT: tuple[tuple[float, str], ...] = (
    (15.4, "stable"), (16.2, "stable"), (17.0, "stable"), (18.0, "stable"),
    (15.6, "unstable"), (16.7, "unstable"), (17.6, "unstable"),
)
#: Training plan of the Van der Pol oscillator: 10 stable LCOs, μ = 0.05 … 0.5.
#: Beyond μ ≈ 0.5 the cycle turns relaxation-like (sharp corners at the
#: extremes of z1), which the map's small network follows only in part (the
#: misfit goes into the scatter σ_k of the high harmonics).
#: :data:`VANDERPOL_PAPER_PLAN` is the paper's range.
VANDERPOL_PLAN: tuple[tuple[float, str], ...] = tuple(
    (round(0.05 * k, 2), "stable") for k in range(1, 11)
)
#: The paper's range, μ = 0.1 … 1.0 (10 stable LCOs).
VANDERPOL_PAPER_PLAN: tuple[tuple[float, str], ...] = tuple(
    (round(0.1 * k, 1), "stable") for k in range(1, 11)
)
#: Held-out orbits of the Van der Pol oscillator (between the training μ).
VANDERPOL_HELD_OUT: tuple[tuple[float, str], ...] = (
    (0.075, "stable"), (0.175, "stable"), (0.275, "stable"), (0.375, "stable"),
    (0.475, "stable"),
)

#: Sensor offsets of the 3-DOF experiment: standard deviations per channel
#: (1 mm of heave, 0.005 rad of pitch), drawn once per seed.
FLUTTER_OFFSET_SD = {"h": 1e-3, "alpha": 5e-3}
#: Sensor offsets of the Van der Pol experiment (1 % of the smallest orbit).
VANDERPOL_OFFSET_SD = {"z1": 0.02, "z2": 0.02}

AmplitudeTruth = Callable[[np.ndarray, str], np.ndarray]


def _branch_amplitude(mu: np.ndarray, amp: np.ndarray, n_dense: int = 4001):
    """``(μ_dense, A_dense)`` of one branch, sorted by μ, from a spline of μ(A)."""
    order = np.argsort(amp)
    a, m = amp[order], mu[order]
    keep = np.concatenate([[True], np.diff(a) > 1e-12 * max(float(a.max()), 1e-300)])
    a, m = a[keep], m[keep]
    if a.size < 4:
        raise SimulationError("a branch needs at least 4 continuation points to interpolate")
    spline = CubicSpline(a, m)
    A = np.linspace(a[0], a[-1], n_dense)
    M = spline(A)
    # the spline may overshoot the end of the branch by round-off at a fold
    M = np.clip(M, m.min(), m.max())
    idx = np.argsort(M, kind="stable")
    return M[idx], A[idx]


def amplitude_truth(diagram: BifurcationDiagram, channel: str | None = None) -> AmplitudeTruth:
    r"""The true ``truth(mu, branch) -> amplitude`` of a continued bifurcation diagram.

    The peak-to-peak of ``channel`` along each branch is interpolated as
    :math:`\mu(A)` by a cubic spline and inverted (module docstring), so the
    square-root ends at the Hopf point and at folds are exact to spline
    accuracy. The callable is what
    :func:`~bayeshopf.plotting.diagram.plot_bifurcation` takes as ``truth``.

    Args:
        diagram: Output of :func:`~bayeshopf.simulators.bifurcation_diagram`.
        channel: Observed channel whose peak-to-peak is the amplitude (default:
            the first of the system's planar pair, as in bayeshopf's fits).

    Returns:
        ``truth(mu, branch)``: amplitudes of the shape of ``mu``; ``nan`` where
        the branch has no orbit (outside the continued range).

    Raises:
        SimulationError: For an unobserved channel.
    """
    ensure_x64()
    system = diagram.system
    channel = channel or system.planar[0]
    if channel not in system.observed:
        raise SimulationError(
            f"channel must be one of the observed states {', '.join(system.observed)}; "
            f"got {channel!r}"
        )
    tables: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for b in diagram.branches:
        if b.kind in tables:  # the first branch of each kind, as diagram.branch(kind)
            continue
        mu, amp = np.asarray(b.mu, float), np.asarray(b.amplitude[channel], float)
        born_at_hopf = b is diagram.branches[0]
        if born_at_hopf:  # the branch starts at the Hopf point with zero amplitude
            mu, amp = np.append(mu, diagram.hopf.mu), np.append(amp, 0.0)
        tables[b.kind] = _branch_amplitude(mu, amp)

    def truth(mu, branch: str = "stable") -> np.ndarray:
        if branch not in ("stable", "unstable"):
            raise SimulationError(f"branch must be 'stable' or 'unstable'; got {branch!r}")
        m = np.asarray(mu, dtype=float)
        if branch not in tables:
            return np.full(m.shape, np.nan)
        M, A = tables[branch]
        out = np.interp(m, M, A)
        return np.where((m >= M[0]) & (m <= M[-1]), out, np.nan)

    return truth


@dataclass(frozen=True, eq=False)
class SimulatedTruth:
    """What a fit of a simulated experiment is checked against.

    Attributes:
        diagram: The continued bifurcation diagram of the system.
        offsets: Sensor offset added to each observed channel.
        plan: ``((mu, branch), ...)`` of the training recordings.
        held_out: ``((mu, branch), ...)`` of orbits not used for training.
        noise: Relative RMS measurement noise.
        seed: Seed of the noise, phases and offsets.
        duration_s: Record length (s).
        sample_rate_hz: Sampling rate (Hz).
    """

    diagram: BifurcationDiagram
    offsets: dict = field(default_factory=dict)
    plan: tuple = ()
    held_out: tuple = ()
    noise: float = 0.01
    seed: int = 0
    duration_s: float = 20.0
    sample_rate_hz: float = 500.0

    @property
    def system(self):
        """The simulated :class:`~bayeshopf.simulators.System`."""
        return self.diagram.system

    @property
    def criticality(self) -> str:
        """``"subcritical"`` or ``"supercritical"`` (from the continuation)."""
        return self.diagram.criticality

    @property
    def mu0(self) -> float:
        """The Hopf point μ0."""
        return float(self.diagram.hopf.mu)

    @property
    def mu_fold(self) -> float | None:
        """The fold of cycles μ_SN (``None`` without a fold)."""
        return float(self.diagram.folds[0].mu) if self.diagram.folds else None

    @property
    def a2(self) -> float | None:
        """``2√(μ0 − μ_SN)``, the normal form's a2 with the same fold (``None`` without one)."""
        if self.mu_fold is None:
            return None
        return float(2.0 * np.sqrt(self.mu0 - self.mu_fold))

    def values(self) -> dict[str, float | None]:
        """``{"mu0", "a2", "mu_fold"}``: the true values of the fitted quantities."""
        return {"mu0": self.mu0, "a2": self.a2, "mu_fold": self.mu_fold}

    def amplitude(self, mu, branch: str = "stable") -> np.ndarray:
        """True peak-to-peak of z1 at μ on ``branch`` (:func:`amplitude_truth`); nan where none."""
        return self._amplitude(mu, branch)

    @property
    def _amplitude(self) -> AmplitudeTruth:
        cached = self.__dict__.get("_amp")
        if cached is None:
            cached = amplitude_truth(self.diagram)
            object.__setattr__(self, "_amp", cached)
        return cached

    def exact_amplitude(self, mu: float, branch: str = "stable") -> float:
        """Peak-to-peak of z1 of the Newton-corrected orbit at ``mu`` (no interpolation)."""
        return float(self.diagram.orbit_at(mu, branch).amplitude[self.system.planar[0]])

    def orbit(self, mu: float, branch: str = "stable") -> np.ndarray:
        """The true orbit in the planar pair, offsets included, shape ``(n_pts, 2)``.

        This is the noise-free signal of a recording, for
        :func:`~bayeshopf.plotting.phase.plot_phase_portraits`.
        """
        orbit = self.diagram.orbit_at(mu, branch)
        cols = [self.system.state_names.index(c) for c in self.system.planar]
        off = np.array([self.offsets.get(c, 0.0) for c in self.system.planar])
        return orbit.states[:, cols] + off

    def to_dict(self) -> dict:
        """JSON-serialisable form: the true values, Hopf and fold points, plans and settings."""
        return {
            "system": self.system.name,
            "criticality": self.criticality,
            **self.values(),
            "hopf_frequency_hz": float(self.diagram.hopf.frequency_hz),
            "amplitude_channel": self.system.planar[0],
            "offsets": dict(self.offsets),
            "plan": [list(p) for p in self.plan],
            "held_out": [list(p) for p in self.held_out],
            "noise": self.noise,
            "seed": self.seed,
            "duration_s": self.duration_s,
            "sample_rate_hz": self.sample_rate_hz,
        }


def _offsets(seed: int, sd: dict[str, float]) -> dict[str, float]:
    """Offsets ``o_c ~ N(0, sd_c)`` from a stream independent of the recordings' noise."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x0FF5E7]))
    return {c: float(rng.normal(0.0, s)) for c, s in sd.items()}


def _experiment(name: str, plan, held_out, *, seed: int, noise: float, offsets,
                offset_sd, duration_s: float, sample_rate_hz: float
                ) -> tuple[RecordingSet, SimulatedTruth]:
    system = get_system(name)
    diagram = bifurcation_diagram(system)
    offs = _offsets(seed, offset_sd) if offsets is None else dict(offsets)
    plan = tuple((float(m), str(b)) for m, b in plan)
    rs = simulate_recordings(
        system, [m for m, _ in plan], [b for _, b in plan], noise=noise, offsets=offs,
        duration_s=duration_s, sample_rate_hz=sample_rate_hz, seed=seed, diagram=diagram,
    )
    truth = SimulatedTruth(
        diagram=diagram, offsets=offs, plan=plan,
        held_out=tuple((float(m), str(b)) for m, b in held_out), noise=float(noise),
        seed=int(seed), duration_s=float(duration_s), sample_rate_hz=float(sample_rate_hz),
    )
    return rs, truth


def flutter_experiment(
    seed: int = 0,
    noise: float = 0.01,
    fast: bool = False,
    *,
    plan: Sequence[tuple[float, str]] = FLUTTER_PLAN,
    held_out: Sequence[tuple[float, str]] = FLUTTER_HELD_OUT,
    offsets: dict[str, float] | None = None,
) -> tuple[RecordingSet, SimulatedTruth]:
    r"""The paper's 3-DOF aerofoil experiment (Section 4.2), blind and with sensor effects.

    Recordings of heave ``h`` (m) and pitch ``alpha`` (rad) of the
    ``flutter3dof`` system at the stable and unstable LCOs of ``plan`` (the
    unstable ones as control-based continuation measures them), each

    .. math::  y_c(t_k) = \bar z_c(t_k + \tau_0) + o_c + \sigma_c \epsilon_{c,k}

    with relative RMS noise ``noise`` and offsets :math:`o_c \sim N(0, s_c)`,
    :math:`s = (1\,\mathrm{mm}, 0.005\,\mathrm{rad})`, drawn from ``seed``
    (:func:`~bayeshopf.simulators.simulate_recordings`).

    **Main arguments**

    Args:
        seed: Seed of the phases, the noise and the offsets.
        noise: Relative RMS measurement noise (0.01: 1 %).
        fast: Shorter records (8 s at 250 Hz instead of 20 s at 500 Hz).

    **Other arguments**

    Args:
        plan: ``((mu, branch), ...)`` of the recordings (:data:`FLUTTER_PLAN`).
        held_out: Orbits kept for checking predictions (:data:`FLUTTER_HELD_OUT`).
        offsets: Offsets per channel instead of drawing them.

    Returns:
        ``(recordings, truth)``: the :class:`~bayeshopf.data.recording.RecordingSet`
        and its :class:`SimulatedTruth`.
    """
    ensure_x64()
    duration, rate = (8.0, 250.0) if fast else (20.0, 500.0)
    return _experiment("flutter3dof", plan, held_out, seed=seed, noise=noise, offsets=offsets,
                       offset_sd=FLUTTER_OFFSET_SD, duration_s=duration, sample_rate_hz=rate)


def vanderpol_experiment(
    seed: int = 0,
    noise: float = 0.01,
    fast: bool = False,
    *,
    plan: Sequence[tuple[float, str]] = VANDERPOL_PLAN,
    held_out: Sequence[tuple[float, str]] = VANDERPOL_HELD_OUT,
    offsets: dict[str, float] | None = None,
) -> tuple[RecordingSet, SimulatedTruth]:
    r"""The paper's Van der Pol experiment (Section 4.1), blind and with sensor effects.

    :math:`\dot z_1 = z_2,\ \dot z_2 = 2\mu z_2 - z_1^2 z_2 - z_1`: a
    supercritical Hopf point at μ = 0 and one stable LCO for μ > 0, of
    period :math:`2\pi` near μ = 0 and 7.7 at μ = 1, where the orbit is already
    relaxation-like (:math:`z_2` peaks twice as high as :math:`z_1`; see
    :data:`VANDERPOL_PLAN` for why the default plan stops at 0.5). Both
    states are recorded with relative RMS noise ``noise`` and offsets
    :math:`o_c \sim N(0, 0.02)` drawn from ``seed``.

    **Main arguments**

    Args:
        seed: Seed of the phases, the noise and the offsets.
        noise: Relative RMS measurement noise.
        fast: Shorter records (60 s at 10 Hz instead of 150 s at 20 Hz).

    **Other arguments**

    Args:
        plan: ``((mu, branch), ...)`` (:data:`VANDERPOL_PLAN`: μ = 0.05 … 0.5;
            :data:`VANDERPOL_PAPER_PLAN`: the paper's 0.1 … 1.0).
        held_out: Orbits kept for checking predictions (:data:`VANDERPOL_HELD_OUT`).
        offsets: Offsets per channel instead of drawing them.

    Returns:
        ``(recordings, truth)``.
    """
    ensure_x64()
    duration, rate = (60.0, 10.0) if fast else (150.0, 20.0)
    return _experiment("vanderpol", plan, held_out, seed=seed, noise=noise, offsets=offsets,
                       offset_sd=VANDERPOL_OFFSET_SD, duration_s=duration, sample_rate_hz=rate)


def held_out_check(fit, truth: SimulatedTruth, points=None, *, mass: float = 0.9) -> list[dict]:
    """Held-out orbits against the fit's posterior predictive intervals.

    For each ``(mu, branch)`` the true amplitude (Newton-corrected orbit) is
    compared with the ``mass`` predictive interval of a new recording there,
    ``fit.amplitude(mu, branch, predictive=True)``.

    Args:
        fit: A :class:`~bayeshopf.posterior.HybridPosterior` (or any object
            with ``amplitude(mu, branch, predictive=True)`` returning draws
            ``(n, n_mu)``, ``nan`` where the branch does not exist).
        truth: The experiment's :class:`SimulatedTruth`.
        points: ``((mu, branch), ...)``; default ``truth.held_out``.
        mass: Probability mass of the interval.

    Returns:
        One record per point: ``mu``, ``branch``, ``true``, ``median``, ``lo``,
        ``hi``, ``inside`` and ``p_exists`` (share of draws with an orbit there).
    """
    ensure_x64()
    rows = []
    for mu, branch in (truth.held_out if points is None else points):
        draws = np.asarray(fit.amplitude([mu], branch, predictive=True))[:, 0]
        ok = np.isfinite(draws)
        true = truth.exact_amplitude(mu, branch)
        if ok.any():
            iv = interval(draws[ok], mass)
            med, lo, hi = iv.median, iv.lo, iv.hi
        else:
            med = lo = hi = float("nan")
        rows.append({"mu": float(mu), "branch": branch, "true": true, "median": med, "lo": lo,
                     "hi": hi, "inside": bool(lo <= true <= hi), "p_exists": float(ok.mean())})
    return rows


def held_out_recordings(truth: SimulatedTruth, points=None) -> RecordingSet:
    """Recordings at the held-out orbits, as the training ones were made.

    Same system, noise, offsets, record length and sampling; the phases and the
    noise come from seed ``truth.seed + 1_000_003``, so they are independent of
    the training recordings. For phase portraits of orbits the fit never saw.

    Args:
        truth: The experiment's :class:`SimulatedTruth`.
        points: ``((mu, branch), ...)``; default ``truth.held_out``.
    """
    ensure_x64()
    pts = truth.held_out if points is None else tuple(points)
    return simulate_recordings(
        truth.system, [m for m, _ in pts], [b for _, b in pts], noise=truth.noise,
        offsets=truth.offsets, duration_s=truth.duration_s,
        sample_rate_hz=truth.sample_rate_hz, seed=truth.seed + 1_000_003,
        diagram=truth.diagram,
    )
