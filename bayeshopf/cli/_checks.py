"""Checks of command-line values, worded with the flags.

The library speaks of arguments (``force``, ``ci``, ``mu``); what the command
line prints speaks of its flags (``--force``, ``--ci``, ``--mu``). These checks
run before the library is called, so that a bad value is reported in the
user's words as one line (exit code 2).
"""

from __future__ import annotations

import math
from pathlib import Path

from bayeshopf.errors import DataError, OutputError


def check_ci(value: float, flag: str = "--ci", error: type[Exception] = DataError) -> float:
    """``value`` if it is a probability mass strictly between 0 and 1.

    Raises:
        error: Naming ``flag`` and the value found.
    """
    if not (math.isfinite(value) and 0 < value < 1):
        raise error(f"{flag} {value:g}: a probability mass between 0 and 1 expected "
                    "(e.g. 0.9)")
    return value


def check_share(value: float, flag: str) -> float:
    """``value`` if it is a share in ``[0, 1]``.

    Raises:
        DataError: Naming ``flag`` and the value found.
    """
    if not (math.isfinite(value) and 0 <= value <= 1):
        raise DataError(f"{flag} {value:g}: a share of posterior draws between 0 and 1 "
                        "expected (e.g. 0.5)")
    return value


def check_out(out: str | Path, force: bool, replaces: str = "replace bayeshopf's files in "
              "it; other files are kept") -> Path:
    """The output folder ``--out``: new, empty, or non-empty with ``--force``.

    Raises:
        OutputError: When a file is in its place, or it is not empty without ``--force``.
    """
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise OutputError(f"--out {path}: expected an output folder; found an existing file")
    if path.is_dir() and any(path.iterdir()) and not force:
        raise OutputError(f"--out {path}: output folder is not empty; expected a new or empty "
                          f"folder (use --force to {replaces})")
    return path
