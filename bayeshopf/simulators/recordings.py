r"""Recordings of simulated limit cycles, as an experiment gives them.

:func:`simulate_recordings` turns the continued periodic orbits of a
:class:`~bayeshopf.simulators.base.System` into a
:class:`~bayeshopf.data.recording.RecordingSet` that the rest of bayeshopf
reads like measured data: one recording per requested ``(μ, branch)``, only the
observed channels, uniformly sampled, with measurement noise, sensor offsets
and a finite record length.

**Why the unstable recordings are the continued orbits.** In an experiment the
unstable LCOs are measured by control-based continuation (CBC): a feedback
controller :math:`u = K(x^*(t) - x(t))` makes the system follow a target
orbit :math:`x^*`, and the target is adjusted (Newton or Picard iterations on
its Fourier coefficients) until the control effort vanishes. The controller is
*non-invasive*: at convergence :math:`u \equiv 0`, so the closed-loop orbit
solves the open-loop equations and is the uncontrolled system's periodic
orbit, unstable or not; the controller only keeps it from drifting away. What
is left in a converged CBC recording is therefore the open-loop periodic orbit
plus what the sensors add: noise and offsets. The simulators compute that
orbit directly, by shooting and continuation, and add the same sensor effects.
(A time integration would leave an unstable orbit within a few periods.) A
stable LCO is sampled the same way; integrating the ODE from a point of the
orbit gives the same signal up to the solver tolerance.

**Signal model.** For a recording at :math:`(\mu, \text{branch})` with period
:math:`T`, the clean orbit :math:`\bar z_c(t)` of each observed channel
:math:`c` is represented by its Fourier series (from 1024 samples per period),
and the recording is

.. math::

    y_c(t_k) = \bar z_c(t_k + \tau_0) + o_c + \sigma_c\,\epsilon_{c,k}, \qquad
    t_k = k / f_s, \quad k = 0, \dots, \lfloor d f_s \rceil - 1,

with the phase :math:`\tau_0 \sim \mathcal U[0, T)` drawn per recording,
the sensor offset :math:`o_c`, white Gaussian :math:`\epsilon_{c,k}` and
:math:`\sigma_c` = ``noise`` times the RMS of the centred clean signal
:math:`\bar z_c - \langle\bar z_c\rangle` (relative RMS noise). The phase and the
noise of recording :math:`i` come from the :math:`i`-th child of
``numpy.random.SeedSequence(seed)``, so equal seeds give identical recordings.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from bayeshopf._atomic import new_folder, vacant_folder
from bayeshopf._x64 import ensure_x64
from bayeshopf.data.io import write_interchange
from bayeshopf.data.recording import Recording, RecordingSet
from bayeshopf.errors import OutputError
from bayeshopf.simulators.base import SimulationError, System
from bayeshopf.simulators.continuation import BifurcationDiagram, bifurcation_diagram
from bayeshopf.simulators.registry import get_system

__all__ = ["SIMULATION_INFO", "simulate_recordings", "simulation_info", "write_simulation"]

#: Name of the JSON file :func:`write_simulation` adds next to the manifest.
SIMULATION_INFO = "simulation.json"
#: Samples per period of the orbit whose Fourier series is sampled.
N_ORBIT = 1024
_CHUNK = 4096


def _plan(system: System, mu, branch) -> list[tuple[float, str]]:
    """Validated ``[(mu, branch), ...]``; ``None`` for both gives the system's default."""
    if mu is None:
        if branch is not None:
            raise SimulationError("branch given without mu; pass the mu of each recording too")
        if not system.default_plan:
            raise SimulationError(f"{system.name}: no default plan; pass mu and branch")
        return list(system.default_plan)
    try:
        mus = np.atleast_1d(np.asarray(mu, dtype=np.float64))
    except (TypeError, ValueError):
        raise SimulationError(f"mu must be a sequence of numbers; got {mu!r}") from None
    if mus.ndim != 1 or mus.size == 0:
        raise SimulationError(f"mu must be a non-empty flat sequence of numbers; got {mu!r}")
    if not np.all(np.isfinite(mus)):
        raise SimulationError(f"mu must be finite; got {mus.tolist()}")
    if branch is None:
        branches = ["stable"] * mus.size
    elif isinstance(branch, str):
        branches = [branch] * mus.size
    else:
        branches = list(branch)
        if len(branches) == 1:
            branches = branches * mus.size
        if len(branches) != mus.size:
            raise SimulationError(
                f"branch must give one branch per mu (or one for all); got {len(branches)} "
                f"branches for {mus.size} values of mu"
            )
    for b in branches:
        if b not in ("stable", "unstable"):
            raise SimulationError(f"branch must be 'stable' or 'unstable'; got {b!r}")
    return [(float(m), str(b)) for m, b in zip(mus, branches, strict=True)]


def _offsets(system: System, offsets) -> dict[str, float]:
    out = dict.fromkeys(system.observed, 0.0)
    for k, v in dict(offsets or {}).items():
        if k not in out:
            raise SimulationError(
                f"offset for {k!r}: expected an observed channel of {system.name} "
                f"({', '.join(system.observed)})"
            )
        v = float(v)
        if not np.isfinite(v):
            raise SimulationError(f"offset for {k!r} must be finite; got {v}")
        out[k] = v
    return out


def _positive(name: str, value) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise SimulationError(f"{name} must be a number; got {value!r}") from None
    if not np.isfinite(x) or x <= 0:
        raise SimulationError(f"{name} must be a finite number > 0; got {value!r}")
    return x


def _evaluate(coeffs: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """``Re Σ_k c_k e^{2πikφ}`` (c_0 once, c_k>0 twice) at phases ``φ``, shape ``(n_t, n_ch)``."""
    k = np.arange(coeffs.shape[0])
    w = np.where(k == 0, 1.0, 2.0)[:, None] * coeffs
    out = np.empty((phase.size, coeffs.shape[1]))
    for i in range(0, phase.size, _CHUNK):
        E = np.exp(2j * np.pi * np.outer(phase[i:i + _CHUNK], k))
        out[i:i + _CHUNK] = (E @ w).real
    return out


def simulate_recordings(
    system: System | str,
    mu: Sequence[float] | None = None,
    branch: Sequence[str] | str | None = None,
    *,
    noise: float = 0.01,
    offsets: Mapping[str, float] | None = None,
    duration_s: float = 20.0,
    sample_rate_hz: float = 500.0,
    seed: int = 0,
    diagram: BifurcationDiagram | None = None,
) -> RecordingSet:
    r"""Noisy recordings of a system's stable and unstable LCOs (module docstring).

    **Main arguments**

    Args:
        system: A :class:`~bayeshopf.simulators.base.System` or its name for
            :func:`~bayeshopf.simulators.get_system`.
        mu: μ of each recording; default ``system.default_plan``.
        branch: ``"stable"`` or ``"unstable"`` per recording (one value applies
            to all; default all stable, or the default plan's).
        noise: Measurement noise, as a fraction of each channel's RMS about its
            mean over the orbit (``0.01``: 1 % relative RMS noise).
        offsets: Sensor offset per observed channel, in its unit (default 0).
        duration_s: Record length in seconds.
        sample_rate_hz: Sampling rate in Hz.
        seed: Seed of the phases and the noise.

    **Other arguments**

    Args:
        diagram: Continued orbits to sample (default
            :func:`~bayeshopf.simulators.bifurcation_diagram` of ``system``,
            computed once per process).

    Returns:
        The recordings in the order asked, observed channels only, planar pair
        ``system.planar``, μ labelled ``system.parameter_label`` in
        ``system.parameter_units``.

    Raises:
        SimulationError: For an unknown system, mismatched ``mu``/``branch``, a
            μ where the branch has no LCO, or a bad setting.
    """
    ensure_x64()
    system = get_system(system)
    plan = _plan(system, mu, branch)
    noise = float(noise)
    if not np.isfinite(noise) or noise < 0:
        raise SimulationError(f"noise must be a finite number >= 0; got {noise!r}")
    offs = _offsets(system, offsets)
    duration_s = _positive("duration_s", duration_s)
    fs = _positive("sample_rate_hz", sample_rate_hz)
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise SimulationError(f"seed must be a non-negative integer; got {seed!r}")
    n_t = int(round(duration_s * fs))
    if n_t < 3:
        raise SimulationError(
            f"duration_s × sample_rate_hz must give at least 3 samples; got {n_t}"
        )
    if diagram is None:
        diagram = bifurcation_diagram(system)
    elif diagram.system is not system:
        raise SimulationError(
            f"diagram is of system {diagram.system.name!r}; expected one of {system.name!r}"
        )
    # check every request before the (slower) orbit corrections
    for m, b in plan:
        br = diagram.branch(b)
        if not br.exists(m):
            lo, hi = br.mu_span
            u = f" {system.parameter_units}" if system.parameter_units else ""
            raise SimulationError(
                f"{b} branch of {system.name}: no LCO at {system.parameter} = {m:g}{u}; "
                f"it exists for {lo:.4g} <= {system.parameter} <= {hi:.4g}{u}"
            )
    obs = list(system.observed_index)
    t = np.arange(n_t) / fs
    children = np.random.SeedSequence(int(seed)).spawn(len(plan))
    recordings: list[Recording] = []
    seen: dict[str, int] = {}
    for (m, b), child in zip(plan, children, strict=True):
        orbit = diagram.orbit_at(m, b, n_points=N_ORBIT)
        clean = orbit.states[:, obs]
        f0 = 1.0 / orbit.period
        if fs <= 2.0 * f0:
            raise SimulationError(
                f"sample_rate_hz must exceed twice the oscillation frequency at "
                f"{system.parameter} = {m:g} (2 × {f0:.4g} Hz); got {fs:g}"
            )
        coeffs = np.fft.rfft(clean, axis=0) / clean.shape[0]
        coeffs = coeffs[: clean.shape[0] // 2]              # drop the Nyquist term
        keep = np.abs(coeffs).max(axis=1) > 1e-15 * np.abs(coeffs).max()
        coeffs = coeffs[: int(np.nonzero(keep)[0].max()) + 1]
        rng = np.random.default_rng(child)
        tau0 = rng.uniform(0.0, orbit.period)
        phase = np.mod((t + tau0) / orbit.period, 1.0)
        z = _evaluate(coeffs, phase)
        rms = clean.std(axis=0)
        z = z + rng.standard_normal(z.shape) * (noise * rms)
        # like the rig's files (v14_9): no dot, so the CSV name keeps the whole value
        name = f"{b}_{system.parameter}{m:g}".replace(".", "_")
        seen[name] = seen.get(name, 0) + 1
        if seen[name] > 1:
            name = f"{name}_{seen[name]}"
        channels = {c: z[:, j] + offs[c] for j, c in enumerate(system.observed)}
        recordings.append(Recording(
            t=t, channels=channels, units=system.observed_units, mu=m, branch=b, name=name,
            source=f"simulated {system.name} (bayeshopf.simulators, seed={seed})",
        ))
    return RecordingSet(
        tuple(recordings), system.planar, mu_label=system.parameter_label,
        mu_units=system.parameter_units,
        extra={"simulated": system.name, "seed": str(seed), "noise": repr(noise),
               "hopf_mu": repr(diagram.hopf.mu),
               "fold_mu": ",".join(repr(f.mu) for f in diagram.folds)},
    )


def simulation_info(rs: RecordingSet, diagram: BifurcationDiagram, **settings) -> dict:
    """JSON-serialisable truth of a simulated set: system, Hopf point, folds, settings.

    Every recording's entry gives the noise-free orbit's period, and the
    peak-to-peak amplitude and mean of each observed channel (without offsets).
    """
    system = diagram.system
    recs = []
    for r in rs:
        orbit = diagram.orbit_at(r.mu, r.branch)
        recs.append({"name": r.name, "mu": r.mu, "branch": r.branch, "period": orbit.period,
                     "amplitude": dict(orbit.amplitude), "mean": dict(orbit.mean)})
    return {"system": system.describe(), "truth": diagram.summary(), "settings": settings,
            "recordings": recs}


def write_simulation(rs: RecordingSet, folder: str | os.PathLike[str], *,
                     info: Mapping | None = None, overwrite: bool = False) -> Path:
    """Write an interchange folder plus ``simulation.json``, atomically.

    The recordings are written by :func:`~bayeshopf.data.io.write_interchange`
    into a temporary sibling folder, ``info`` is added as
    :data:`SIMULATION_INFO`, and the folder is renamed into place, so ``folder``
    never holds a partial result.

    Raises:
        OutputError: If ``folder`` is a file, or is not empty and ``overwrite``
            is false, or cannot be written.
    """
    folder = vacant_folder(folder, overwrite, "overwrite=True replaces it")
    try:
        with new_folder(folder) as tmp:
            write_interchange(rs, tmp)
            if info is not None:
                (tmp / SIMULATION_INFO).write_text(json.dumps(info, indent=2) + "\n",
                                                   encoding="utf-8")
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(f"{folder}: cannot be written ({type(exc).__name__}: {exc})") from exc
    return folder
