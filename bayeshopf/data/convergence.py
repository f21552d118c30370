"""Whether the CBC controller converged on a recording.

Control-based continuation holds an orbit with a feedback controller and
iterates its target until the control is non-invasive; only then is the
recorded orbit one of the uncontrolled system. A rig's files may record how
that iteration ended (the flutter rig's ``.mat`` files carry ``error1``,
``error_tol`` and ``success``). A rig description names those fields in a
``[convergence]`` table::

    [convergence]
    success = "success"        # a flag variable: non-zero when the controller converged
    error = "error1"           # the controller's remaining error ...
    tolerance = "error_tol"    # ... and its tolerance: a variable, or a number
    branches = ["unstable"]    # the branches that need a converged controller

A recording *converged* when its success flag (if named and present in the
file) is non-zero and ``|error| <= tolerance`` (if both are named and present).
A field named but absent from a file is unknown and does not count against it.
Only recordings of the listed ``branches`` (default both) are required to have
converged; :func:`unconverged` lists those that did not, so that a fit can
warn and leave them out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from bayeshopf.errors import DataError

__all__ = ["Convergence", "ConvergenceSpec"]

_BRANCHES = ("stable", "unstable")


@dataclass(frozen=True)
class Convergence:
    """How the controller's iteration ended on one recording.

    Attributes:
        success: The file's success flag (``None`` when not recorded).
        error: The controller's remaining error (``None`` when not recorded).
        tolerance: The tolerance of ``error`` (``None`` when not recorded).
        required: Whether the rig description requires this recording's
            controller to have converged (its branch is listed).
    """

    success: bool | None = None
    error: float | None = None
    tolerance: float | None = None
    required: bool = True

    @property
    def converged(self) -> bool:
        """``success`` (if known) and ``|error| <= tolerance`` (if both known)."""
        if self.success is False:
            return False
        if self.error is not None and self.tolerance is not None:
            return abs(self.error) <= self.tolerance
        return True

    def describe(self) -> str:
        """What was recorded, e.g. ``"error -0.33 against tolerance 0.01, success 1"``."""
        parts = []
        if self.error is not None:
            parts.append(f"error {self.error:.3g}"
                         + (f" against tolerance {self.tolerance:.3g}"
                            if self.tolerance is not None else ""))
        if self.success is not None:
            parts.append(f"success {int(self.success)}")
        return ", ".join(parts) or "nothing recorded"


@dataclass(frozen=True)
class ConvergenceSpec:
    """Where a rig's files record the controller's convergence (module docstring).

    Attributes:
        success: Variable of the success flag, or ``None``.
        error: Variable of the remaining error, or ``None``.
        tolerance: Variable of the error's tolerance, or a number; needed
            with ``error``.
        branches: Branches whose recordings must have converged.
    """

    success: str | None = None
    error: str | None = None
    tolerance: str | float | None = None
    branches: tuple[str, ...] = _BRANCHES

    def __post_init__(self) -> None:
        where = "[convergence]"
        for key in ("success", "error"):
            v = getattr(self, key)
            if v is not None and (not isinstance(v, str) or not v.strip()):
                raise DataError(f"{where}: '{key}' must name a variable; found {v!r}")
        tol = self.tolerance
        if tol is not None:
            if isinstance(tol, bool) or not isinstance(tol, str | int | float):
                raise DataError(f"{where}: 'tolerance' must name a variable or be a number; "
                                f"found {tol!r}")
            if isinstance(tol, int | float):
                if not math.isfinite(tol) or tol < 0:
                    raise DataError(f"{where}: 'tolerance' must be a finite number >= 0; "
                                    f"found {tol!r}")
                object.__setattr__(self, "tolerance", float(tol))
        if self.success is None and self.error is None:
            raise DataError(f"{where}: 'success' or 'error' (a variable of the files) expected; "
                            "found neither")
        if (self.error is None) != (self.tolerance is None):
            raise DataError(f"{where}: 'error' and 'tolerance' expected together; found only "
                            f"{'error' if self.error is not None else 'tolerance'}")
        branches = (self.branches,) if isinstance(self.branches, str) else self.branches
        if (not isinstance(branches, list | tuple) or not branches
                or any(b not in _BRANCHES for b in branches)):
            raise DataError(f"{where}: 'branches' must list 'stable' and/or 'unstable'; found "
                            f"{self.branches!r}")
        object.__setattr__(self, "branches", tuple(dict.fromkeys(branches)))

    @property
    def variables(self) -> tuple[str, ...]:
        """The variables a file is read for."""
        return tuple(v for v in (self.success, self.error, self.tolerance)
                     if isinstance(v, str))

    def to_dict(self) -> dict[str, Any]:
        """The table's keys as in a rig file (unset keys left out)."""
        out: dict[str, Any] = {k: getattr(self, k) for k in ("success", "error", "tolerance")
                               if getattr(self, k) is not None}
        if self.branches != _BRANCHES:
            out["branches"] = list(self.branches)
        return out

    def read(self, scalars: dict[str, float], branch: str) -> Convergence | None:
        """The convergence of one recording from the scalar variables of its file.

        Args:
            scalars: Variable name -> value of the named variables the file holds.
            branch: The recording's branch.

        Returns:
            ``None`` when the file holds none of the named variables.
        """
        def value(v: str | float | None) -> float | None:
            if isinstance(v, str):
                return scalars.get(v)
            return v

        success = value(self.success)
        error = value(self.error)
        if success is None and error is None:
            return None
        return Convergence(success=None if success is None else bool(success != 0),
                           error=error, tolerance=value(self.tolerance),
                           required=branch in self.branches)
