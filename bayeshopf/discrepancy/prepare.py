"""What every discrepancy analysis starts from: features, library system and nominal orbits.

Both :func:`bayeshopf.discrepancy.analysis.analyse` and
:func:`bayeshopf.discrepancy.calibration.calibrate` begin with
:func:`prepare`; it sits here so that the two import it one way.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from bayeshopf.data.recording import RecordingSet
from bayeshopf.discrepancy.features import DEFAULT_K, measure
from bayeshopf.discrepancy.orbits import solve_orbits
from bayeshopf.discrepancy.select import Fitter
from bayeshopf.discrepancy.terms import KINDS, library, library_params, library_system
from bayeshopf.errors import BayesHopfError
from bayeshopf.simulators.base import System
from bayeshopf.simulators.continuation import BifurcationDiagram, bifurcation_diagram

__all__ = ["Prepared", "prepare"]


class Prepared(NamedTuple):
    """Result of :func:`prepare` (unpacks as ``fitter, diagram, notes``).

    Attributes:
        fitter: The :class:`~bayeshopf.discrepancy.select.Fitter` of the
            recordings against the library system, its ``base`` orbits those
            with every coefficient 0.
        diagram: The nominal simulator's bifurcation diagram.
        notes: The warm starts' notes (recordings whose μ has no orbit on the
            nominal branch), empty ones left out.
    """

    fitter: Fitter
    diagram: BifurcationDiagram
    notes: list[str]


def _base_warm_starts(system: System, rs: RecordingSet):
    """Warm starts on the simulator's branches, and a note where the branch has no orbit.

    Each is interpolated between the continuation points around the recording's
    μ (:meth:`~bayeshopf.simulators.arclength.Branch.guess`); the orbits are
    then solved together (:func:`prepare`), not one by one here. Where the
    branch does not reach μ, its nearest point, with the reason as a note.
    """
    diagram = bifurcation_diagram(system)
    x0, T, note = [], [], []
    for r in rs:
        try:
            x, period, _ = diagram.branch(r.branch).guess(r.mu)
            x0.append(x)
            T.append(period)
            note.append("")
        except BayesHopfError as exc:
            b = diagram.branch(r.branch)
            i = int(np.argmin(np.abs(b.mu - r.mu)))
            x0.append(b.x0[i])
            T.append(b.period[i])
            note.append(str(exc))
    return diagram, np.stack(x0), np.array(T), note


def prepare(recordings: RecordingSet, system: System, K: int = DEFAULT_K, kinds=KINDS, *,
            parameters: Sequence[str] = ()) -> Prepared:
    """What every analysis starts from: features, library system and the nominal orbits.

    The observed channels are measured with the planar reference first; the
    library is sized by their median amplitudes and frequency (and leaves out
    the terms whose force is that of one of ``parameters``, the calibrated
    ones: :func:`~bayeshopf.discrepancy.terms.library`); the library system's
    orbits at the recordings, every coefficient 0, are shot from the nominal
    diagram's warm starts.

    Returns:
        A :class:`Prepared` ``(fitter, diagram, notes)``.
    """
    obs = system.observed
    ref = recordings.planar[0] if recordings.planar[0] in obs else obs[0]
    channels = (ref,) + tuple(c for c in obs if c != ref)
    mf = measure(recordings, channels, K=K)
    amp = dict(zip(channels, np.median(mf.amplitude, axis=0), strict=True))
    lib = library(system, amp, float(np.median(mf.y[:, 0])), kinds=kinds,
                  parameters=parameters)
    L = library_system(system, lib)
    diagram, x0, T, notes = _base_warm_starts(system, recordings)
    stable = np.array([b == "stable" for b in mf.branch])
    base = solve_orbits(L, {**L.params, **library_params(lib)}, x0, T, mf.mu, stable)
    return Prepared(Fitter(L, lib, mf, base), diagram, [n for n in notes if n])
