"""Checks and message helpers shared by the readers of :mod:`bayeshopf.data`.

Every problem raises :class:`~bayeshopf.errors.DataError` with one line naming
the file, what was expected and what was found.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from bayeshopf.errors import DataError

MANIFEST = "manifest.csv"
MANIFEST_COLUMNS = ("file", "mu", "branch")
DT_TOLERANCE = 0.01  # largest relative deviation of dt from the mean accepted
#: Largest ratio between the sample rates of two recordings of one set. A set
#: whose rates differ more is taken as a time column in the wrong unit.
RATE_SPREAD = 100.0


def one_line(exc: BaseException) -> str:
    """``"Type: message"`` of an exception squeezed onto one line."""
    msg = " ".join(str(exc).split()).split("; use `usecols`")[0]  # numpy's hint misleads
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


def fmt_names(names: Iterable[str]) -> str:
    """``"a, b, c"``, or ``"(none)"``."""
    names = list(names)
    return ", ".join(names) if names else "(none)"


def require_folder(folder: str | os.PathLike[str]) -> Path:
    """``folder`` as a path, after checking that it is an existing folder."""
    folder = Path(folder)
    if not folder.exists():
        raise DataError(f"{folder}: data folder expected; not found")
    if not folder.is_dir():
        raise DataError(f"{folder}: expected a folder; found a file")
    return folder


def check_samples(where: str, t: np.ndarray, channels: Mapping[str, np.ndarray]) -> None:
    """Check sample count, finiteness and uniform increasing time.

    Gaps of whole sample intervals (samples left out) are accepted.

    Raises:
        DataError: On the first problem found.
    """
    n = t.size
    if n < 3:
        raise DataError(f"{where}: expected at least 3 samples; found {n}")
    for name, x in {"t": t, **channels}.items():
        bad = ~np.isfinite(x)
        if bad.any():
            raise DataError(
                f"{where}: channel '{name}' has {int(bad.sum())} non-finite sample(s) (NaN/inf), "
                f"first at index {int(np.argmax(bad))}; expected finite numbers"
            )
    dt = np.diff(t)
    if (dt <= 0).any():
        i = int(np.argmax(dt <= 0))
        raise DataError(
            f"{where}: t must be strictly increasing; found t[{i + 1}] = {t[i + 1]:.9g} "
            f"after t[{i}] = {t[i]:.9g}"
        )
    mean_dt = (t[-1] - t[0]) / (n - 1)
    dev = float(np.max(np.abs(dt - mean_dt)) / mean_dt)
    if dev > DT_TOLERANCE:
        step = float(np.median(dt))
        ratio = dt / step
        if np.all(ratio > 0.5) and np.max(np.abs(ratio - np.rint(ratio))) <= DT_TOLERANCE:
            return  # uniform with gaps of whole sample intervals
        raise DataError(
            f"{where}: t must be uniformly spaced; dt varies by {100 * dev:.3g}% "
            f"(expected < {100 * DT_TOLERANCE:g}%)"
        )


def check_rates(names: Sequence[str], steps: Sequence[float]) -> None:
    """Refuse a set whose sample rates differ by more than :data:`RATE_SPREAD`.

    The rate of a recording is ``1 / dt`` (its median sample spacing, in s).
    The recording farthest (in log ratio) from the set's median rate is named.

    Args:
        names: Recording names (for the message).
        steps: Their sample spacings ``dt`` in seconds.

    Raises:
        DataError: If ``max(rate) / min(rate) > RATE_SPREAD``.
    """
    rates = 1.0 / np.asarray(steps, dtype=np.float64)
    if rates.size < 2 or rates.max() <= RATE_SPREAD * rates.min():
        return
    ref = float(np.median(rates))
    i = int(np.argmax(np.abs(np.log(rates / ref))))
    raise DataError(
        f"{names[i]}: a sample rate within a factor {RATE_SPREAD:g} of the other recordings' "
        f"(median {ref:.6g} Hz) expected; found {rates[i]:.6g} Hz (is its time column in "
        "another unit? give it in the header, e.g. 't [ms]')"
    )
