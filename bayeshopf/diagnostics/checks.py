"""The fit's checks as a typed record: one status per check, with its messages.

:func:`bayeshopf.posterior.diagnose` computes the checks as a JSON-ready
mapping (what ``summary.json`` stores); :class:`Diagnostics` reads that mapping
into one :class:`Check` per question a user asks of a fit:

* ``map``: did the optimiser reach the MAP (gradient below its tolerance)?
* ``sampler``: did NUTS converge (R̂, bulk ESS, no divergences), or SVI plateau?
* ``orbits``: is every recording's posterior-median orbit within its error bar?
* ``amplitudes``: is every measured amplitude inside its 90% predictive band?
* ``model_error``: is the model error small against the measured spread and
  the orbits' size (and, with the window at the fold, is its depth within
  what its prior allows)?
* ``frequency``: is every measured frequency inside its 90% predictive band
  (``None`` without the frequency model)?
* ``leave_one_out``: the held-out check, when the fit ran one (else ``None``).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

__all__ = ["Check", "Diagnostics", "Status"]


class Status(enum.Enum):
    """Outcome of one check."""

    OK = "ok"
    WARNING = "warning"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class Check:
    """One check of a fit.

    Attributes:
        name: The check (``"map"``, ``"sampler"``, …).
        status: :attr:`Status.OK` or :attr:`Status.WARNING`.
        messages: One line per finding that made it a warning (empty when OK).
    """

    name: str
    status: Status
    messages: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """Whether the check passed."""
        return self.status is Status.OK


#: Each check's warnings, by the start of the line :func:`~bayeshopf.posterior.diagnose` writes.
_PREFIXES = {
    "map": ("MAP:",),
    "sampler": ("NUTS:", "SVI:"),
    "orbits": (": orbit error",),
    "amplitudes": ("measured amplitude outside",),
    "model_error": ("model error of", "relative model error", "the fold's window"),
    "frequency": ("measured frequency",),
    "leave_one_out": ("leave-one-out",),
}


def _owner(line: str) -> str | None:
    for name, marks in _PREFIXES.items():
        if any(line.startswith(m) or m in line for m in marks):
            return name
    return None


def _status(failed: bool) -> Status:
    return Status.WARNING if failed else Status.OK


@dataclass(frozen=True)
class Diagnostics:
    """Every check of a fit, each with a :class:`Status` (immutable).

    Attributes:
        map: The MAP optimiser's convergence.
        sampler: NUTS's R̂, ESS and divergences, or SVI's ELBO plateau.
        orbits: Each recording's orbit error against its limit.
        amplitudes: Each measured amplitude against its predictive band.
        model_error: The model error against the measured spread and orbit size.
        frequency: Each measured frequency against its predictive band, or ``None``.
        leave_one_out: The held-out check, or ``None`` when none was run.
        warnings: Every warning line, in the order the checks produced them.
        details: The checks' numbers (read-only; what ``summary.json`` stores
            under ``diagnostics``).
    """

    map: Check
    sampler: Check
    orbits: Check
    amplitudes: Check
    model_error: Check
    frequency: Check | None
    leave_one_out: Check | None
    warnings: tuple[str, ...]
    details: Mapping

    @property
    def checks(self) -> tuple[Check, ...]:
        """The checks that were run, in order."""
        return tuple(c for c in (self.map, self.sampler, self.orbits, self.amplitudes,
                                 self.model_error, self.frequency, self.leave_one_out)
                     if c is not None)

    @property
    def ok(self) -> bool:
        """Whether every check passed."""
        return all(c.ok for c in self.checks)

    def __str__(self) -> str:
        lines = [f"{c.name:<14} {c.status.value}" for c in self.checks]
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    @classmethod
    def from_dict(cls, d: Mapping) -> Diagnostics:
        """Read the mapping of :func:`~bayeshopf.posterior.diagnose` (or of a ``summary.json``).

        Raises:
            KeyError: When ``d`` lacks ``warnings``, ``map``, ``posterior`` or ``fit``.
        """
        warnings = tuple(str(w) for w in d["warnings"])
        by = {name: [] for name in _PREFIXES}
        for w in warnings:
            owner = _owner(w)
            if owner is not None:
                by[owner].append(w)
        fit, post = d["fit"], d["posterior"]
        if post.get("method") == "svi":
            sampler_failed = not post["elbo_plateau"]["plateau"]
        elif post.get("method") == "importance":       # its check passed, or NUTS ran instead
            sampler_failed = False
        else:
            sampler_failed = (bool(post.get("divergences", 0))
                              or not all(v["ok"] for v in post["sites"].values()))

        def check(name: str, failed: bool) -> Check:
            return Check(name, _status(failed or bool(by[name])), tuple(by[name]))

        freq = fit.get("frequency")
        loo = d.get("leave_one_out")
        return cls(
            map=check("map", not d["map"]["converged"]),
            sampler=check("sampler", sampler_failed),
            orbits=check("orbits", not all(e["ok"] for e in fit["orbit_error"])),
            amplitudes=check("amplitudes", not all(fit["amplitude_covered"])),
            model_error=check("model_error", False),
            frequency=(None if freq is None
                       else check("frequency", not all(e["inside_ci90"] for e in freq))),
            leave_one_out=(None if loo is None
                           else check("leave_one_out", not loo.get("ok", True))),
            warnings=warnings,
            details=MappingProxyType(dict(d)),
        )
