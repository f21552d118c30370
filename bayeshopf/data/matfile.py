"""Read LCO recordings from MATLAB ``.mat`` files as a rig description says.

A :class:`~bayeshopf.data.rig.RigDescription` names the rows or variables of
the channels, their scales and units, the time and μ variables, what a sensor
writes when it has no reading, and where the CBC controller's convergence is
recorded. The built-in description is the wind-tunnel flutter rig recorded with
control-based continuation (``data`` 5 x N, ``time``, ``Wind_sped``).

Samples at which a channel has no reading (NaN, the description's sentinel, a
full-turn jump) are left out with their time stamps; the time variable is
converted to seconds (the description's ``time_unit``) and every channel is
given in the description's unit (:mod:`bayeshopf.data.units`). Every problem
raises :class:`~bayeshopf.errors.DataError` with one line naming the file.
Files are opened read-only.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

import numpy as np
import scipy.io

from bayeshopf.data._common import (
    MANIFEST,
    check_rates,
    check_samples,
    fmt_names,
    one_line,
    require_folder,
)
from bayeshopf.data.recording import Recording, RecordingSet
from bayeshopf.data.rig import RigDescription, load_rig
from bayeshopf.data.units import harmonise, time_in_seconds
from bayeshopf.errors import DataError

__all__ = ["dropped_report", "read_cbc_mat", "read_one_mat"]



def _branch_from_name(name: str) -> str:
    low = name.lower()
    if "unstable" in low:
        return "unstable"
    if "stable" in low:
        return "stable"
    raise DataError(
        f"{name}: file name containing 'stable' or 'unstable' (the branch) expected; found "
        f"neither (or list the file with its branch in a {MANIFEST}: file,mu,branch)"
    )


def _mat_variables(path: Path) -> list[str]:
    """Names of the variables a .mat file holds (for messages; empty if unreadable)."""
    try:
        with open(path, "rb") as f:
            return [v[0] for v in scipy.io.whosmat(f)]
    except Exception:  # noqa: BLE001 - only used to word a message
        return []


def _time_hint(rig: RigDescription, n: int, n_time: int) -> str:
    """How to read a record whose time vector holds ``n_time`` stamps for ``n`` samples."""
    if n_time > n and n_time % n == 0:
        k = n_time // n
        return (f"set time_mismatch = \"decimate\" in the rig description to take every {k}th "
                "stamp, or time_mismatch = \"sample_rate\" with sample_rate to space the "
                "samples at the rig's rate")
    if rig.time_mismatch == "decimate":
        return (f"time_mismatch = \"decimate\" needs {n_time} = k x {n}; set time_mismatch = "
                "\"sample_rate\" with sample_rate in the rig description instead")
    return ("set time_mismatch = \"sample_rate\" with sample_rate in the rig description to "
            "space the samples at the rig's rate")


def read_one_mat(
    path: Path, rig: RigDescription, mu: float | None = None, branch: str | None = None
) -> Recording:
    """One recording of a ``.mat`` file as ``rig`` describes it.

    ``mu`` and ``branch`` (from a manifest) override the file's μ variable and
    file name. Samples at which a channel has no reading are left out.
    """
    name = path.name
    if not path.is_file():
        raise DataError(f"{name}: .mat file expected at {path}; not found")
    try:
        with open(path, "rb") as f:
            mat = scipy.io.loadmat(f, variable_names=list(rig.variables))
    except Exception as exc:  # scipy raises many types for corrupt files
        raise DataError(f"{name}: cannot be read as a MATLAB .mat file ({one_line(exc)})") from exc

    def absent(var: str, what: str) -> NoReturn:
        held = _mat_variables(path)
        raise DataError(
            f"{name}: variable '{var}' ({what}; {rig.where}) expected; not found (file holds "
            f"{fmt_names(held[:10])}{', ...' if len(held) > 10 else ''})"
        )

    def numeric(var: str) -> np.ndarray:
        try:
            return np.asarray(mat[var], dtype=np.float64)
        except (TypeError, ValueError):
            raise DataError(f"{name}: '{var}' must be numeric; found {mat[var].dtype} values") \
                from None

    raw: dict[str, np.ndarray] = {}
    for c in rig.channels:
        var = c.variable or rig.data_variable
        if var not in mat:
            by_row = [d.name for d in rig.channels if d.variable is None]
            absent(var, f"{rig.data_rows} x N samples" if var == rig.data_variable
                   and rig.data_rows else f"channels {fmt_names(by_row)} by row"
                   if var == rig.data_variable else f"channel '{c.name}'")
        a = numeric(var)
        if c.row is None:
            if a.ndim > 2 or (a.ndim == 2 and min(a.shape) != 1):
                raise DataError(f"{name}: '{var}' (channel '{c.name}') must be a vector, or the "
                                f"channel needs a 'row' in {rig.where}; found shape {a.shape}")
            raw[c.name] = a.ravel()
            continue
        if var == rig.data_variable and rig.data_rows is not None and (
                a.ndim != 2 or a.shape[0] != rig.data_rows):
            raise DataError(
                f"{name}: '{var}' of shape {rig.data_rows} x N expected; found {a.shape}")
        if a.ndim != 2:
            raise DataError(f"{name}: '{var}' must be a matrix with one channel per row; "
                            f"found shape {a.shape}")
        if c.row >= a.shape[0]:
            raise DataError(
                f"{name}: row {c.row} of '{var}' expected (channel '{c.name}' in {rig.where}; "
                f"rows count from 0); '{var}' has {a.shape[0]} rows"
            )
        raw[c.name] = a[c.row]
    first = rig.channels[0].name
    n = raw[first].size
    for c, x in raw.items():
        if x.size != n:
            raise DataError(f"{name}: channel '{c}' with {n} samples (as '{first}') expected; "
                            f"found {x.size}")

    tv = rig.time_variable
    if tv is not None and tv in mat:
        t = time_in_seconds(numeric(tv).ravel(), rig.time_unit, name)
        if t.size != n:
            if rig.time_mismatch == "decimate" and t.size > n and t.size % n == 0:
                t = t[:: t.size // n]
            elif rig.time_mismatch == "sample_rate" and t.size:
                assert rig.sample_rate is not None
                t = t[0] + np.arange(n) / rig.sample_rate
            else:
                of = (f"'{rig.data_variable}'" if any(c.variable is None for c in rig.channels)
                      else "the channels")
                raise DataError(f"{name}: '{tv}' with {n} samples (as {of}) expected; found "
                                f"{t.size} ({_time_hint(rig, n, t.size)})")
    elif rig.sample_rate is not None:
        t = np.arange(n) / rig.sample_rate
    else:
        absent(str(tv), "the time stamps in s; or give sample_rate")
    check_samples(name, t, {})

    if mu is None:
        if rig.mu_variable is not None and rig.mu_variable in mat:
            value = numeric(rig.mu_variable).ravel()
            if value.size != 1:
                raise DataError(f"{name}: scalar '{rig.mu_variable}' expected; found shape "
                                f"{np.shape(mat[rig.mu_variable])}")
            mu = float(value[0])
            if not np.isfinite(mu):
                raise DataError(f"{name}: finite '{rig.mu_variable}' expected; found {mu}")
        else:
            mu = rig.mu_from_name(name)
            if mu is None:
                ways = [f"variable '{rig.mu_variable}'"] if rig.mu_variable else []
                if rig.mu_pattern:
                    ways.append(f"a file name matching {rig.mu_pattern!r}")
                raise DataError(
                    f"{name}: mu expected from {' or '.join(ways) or 'the rig description'}; "
                    f"found none (or list the file with its mu in a {MANIFEST}: file,mu,branch)"
                )
    if branch is None:
        branch = _branch_from_name(name)

    drop = np.zeros(n, dtype=bool)
    for c in rig.channels:
        drop |= c.no_reading(raw[c.name]) | np.isnan(raw[c.name])  # NaN: always no reading
    for c in rig.channels:
        bad = ~np.isfinite(raw[c.name]) & ~drop
        if bad.any():
            raise DataError(
                f"{name}: channel '{c.name}' has {int(bad.sum())} infinite sample(s), "
                f"first at index {int(np.argmax(bad))}; expected finite numbers or NaN (or "
                "missing = [\"nan\"] for the channel in the rig description)"
            )
    keep = ~drop
    if keep.sum() < 3:
        raise DataError(f"{name}: at least 3 samples with a reading expected; found "
                        f"{int(keep.sum())} of {n} ({rig.where} marks the rest as no reading)")
    channels = {c.name: c.to_physical(raw[c.name][keep]) for c in rig.channels}
    units = {c.name: c.unit for c in rig.channels}
    convergence = None
    if rig.convergence is not None:
        scalars = {}
        for var in rig.convergence.variables:
            if var in mat:
                value = numeric(var).ravel()
                if value.size != 1:
                    raise DataError(f"{name}: scalar '{var}' expected (convergence in "
                                    f"{rig.where}); found shape {np.shape(mat[var])}")
                scalars[var] = float(value[0])
        convergence = rig.convergence.read(scalars, branch)
    return Recording(t[keep], channels, units, mu, branch, name=name,
                     source=str(path.resolve()), dropped=int(drop.sum()),
                     convergence=convergence)


def read_cbc_mat(
    path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    rig: RigDescription | str | os.PathLike[str] | None = None,
) -> RecordingSet:
    """Read a folder (or list) of ``.mat`` files as a rig description says.

    Without ``rig`` the files are read as the paper's flutter rig
    (:meth:`~bayeshopf.data.rig.RigDescription.flutter_cbc`): ``data`` (5 x N;
    rows heave [V], CBC target [V], actuator [V], pitch [rad], running mean of
    heave [V]), ``time`` (s) and ``Wind_sped`` (m/s, used as μ; it is trusted
    over the file name). The channels are ``h`` and ``mean_h`` (heave in m,
    0.18 m/V), ``alpha`` (pitch, rad), ``cbc_target`` and ``actuator`` (V).
    Without ``time`` the samples are taken as 5 kHz; without ``Wind_sped`` μ is
    parsed from a ``v15_6``-style file name. The branch is read from the file
    name ("stable"/"unstable"); list the files in a ``manifest.csv``
    (:func:`read_interchange`) to give branch and μ otherwise.

    Samples at which a channel has no reading (NaN, the description's
    sentinel, infinite values with ``missing = ["nan"]``, a full-turn jump) are
    left out with their time stamps; :attr:`Recording.dropped` counts them
    (:func:`dropped_report`).

    Args:
        path: A folder of ``.mat`` files, or a list of ``.mat`` file paths.
        rig: A :class:`~bayeshopf.data.rig.RigDescription` or the path of a rig
            file; default the built-in flutter rig.

    Returns:
        Recordings with the description's planar pair, control channel,
        ``mu_label`` and ``mu_units``, stable branch first, each branch sorted
        by μ; each with its :attr:`~bayeshopf.data.recording.Recording.convergence`
        when the description names convergence fields.

    Raises:
        DataError: If the folder or a file is missing or unreadable, a variable
            or row the description names is missing, the samples are bad, a
            unit is unknown, the sample rates differ by more than
            :data:`~bayeshopf.data._common.RATE_SPREAD`, or a file name tells no
            branch ("stable"/"unstable").
    """
    rig = RigDescription.flutter_cbc() if rig is None else load_rig(rig)
    if isinstance(path, str | os.PathLike):
        folder = require_folder(path)
        files = sorted(folder.glob("*.mat"))
        if not files:
            found = sorted(p.name for p in folder.iterdir())[:8]
            raise DataError(f"{folder}: .mat files expected; found {fmt_names(found)}")
    else:
        files = [Path(p) for p in path]
        if not files:
            raise DataError("read_cbc_mat: at least one .mat file expected; got an empty list")
    recs = harmonise(sorted(
        (read_one_mat(p, rig) for p in files),
        key=lambda r: (r.branch == "unstable", r.mu, r.name),
    ), {c.name: c.unit for c in rig.channels})
    check_rates([r.name for r in recs], [r.dt for r in recs])
    return RecordingSet(tuple(recs), rig.planar, mu_label=rig.mu_label, mu_units=rig.mu_units,
                        extra={"rig": rig.name}, control=rig.control)


def dropped_report(rs: RecordingSet) -> list[str]:
    """One line per recording that lost samples with no reading (for the log).

    Returns:
        Lines like ``"CBC_v22_4.mat: 1234 of 20000 samples (6.2%) left out
        (no reading)"``; empty when no sample was left out.
    """
    lines = []
    for r in rs:
        if r.dropped:
            total = r.dropped + r.t.size
            lines.append(f"{r.name}: {r.dropped} of {total} samples "
                         f"({100 * r.dropped / total:.1f}%) left out (a sensor had no reading)")
    return lines


