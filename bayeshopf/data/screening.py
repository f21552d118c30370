"""Which controlled recordings of a set did not converge, and the set without them.

A rig description may name the CBC controller's convergence fields
(:class:`~bayeshopf.data.convergence.ConvergenceSpec`); each recording then
carries its :class:`~bayeshopf.data.convergence.Convergence`. A controlled
recording on which the controller did not converge is not an orbit of the
uncontrolled system: :func:`bayeshopf.fit` leaves it out by default.
"""

from __future__ import annotations

from bayeshopf.data.recording import RecordingSet
from bayeshopf.errors import DataError

__all__ = ["converged_only", "convergence_report", "screened", "unconverged"]


def unconverged(rs: RecordingSet) -> tuple[int, ...]:
    """Indices of the recordings whose controller was required to converge and did not."""
    return tuple(i for i, r in enumerate(rs)
                 if r.convergence is not None and r.convergence.required
                 and not r.convergence.converged)


def convergence_report(rs: RecordingSet) -> list[str]:
    """One line per recording of :func:`unconverged` (for the log)."""
    return [f"{rs[i].name}: the controller did not converge ({rs[i].convergence.describe()}); "
            "not an orbit of the uncontrolled system" for i in unconverged(rs)]


def converged_only(rs: RecordingSet) -> RecordingSet:
    """``rs`` without the recordings of :func:`unconverged` (``rs`` itself when none).

    Raises:
        DataError: If no recording is left.
    """
    bad = set(unconverged(rs))
    if not bad:
        return rs
    if len(bad) == len(rs):
        raise DataError(f"recording set: at least one recording on which the controller "
                        f"converged expected; found none of {len(rs)} ({rs[0].name}: "
                        f"{rs[0].convergence.describe()})")
    return rs.subset([i for i in range(len(rs)) if i not in bad])


def screened(rs: RecordingSet, keep: bool = False) -> tuple[RecordingSet, list[str]]:
    """``rs`` without its unconverged controlled recordings (all of it with ``keep``).

    Returns:
        The recordings to fit and one line per recording left out (or kept
        although it did not converge), for the caller's warning.
    """
    lines = convergence_report(rs)
    if keep:
        return rs, [f"{line}; kept" for line in lines]
    return converged_only(rs), [f"{line}; left out" for line in lines]
