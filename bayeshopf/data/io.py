"""Read and write LCO recordings.

Two formats are supported:

* **Interchange** (:func:`read_interchange`, :func:`write_interchange`): a folder
  holding ``manifest.csv`` (columns ``file,mu,branch``; optional leading comment
  lines ``# mu_label: ...`` and ``# mu_units: ...``) and one CSV per recording
  with header ``t,<channel>,<channel>,...``. A channel header may carry its unit
  in square brackets, e.g. ``h [m]``.
  The manifest may list ``.mat`` files too; they are read as the rig
  description says (below), and the manifest's μ and branch win over the
  file's μ variable and its name.
* **MATLAB** (:func:`read_cbc_mat`): a folder of ``.mat`` files read as a
  :class:`~bayeshopf.data.rig.RigDescription` says (rows or variables of the
  channels, scales, time, μ, and what a sensor writes when it has no reading;
  such samples are left out). The built-in description is the wind-tunnel
  flutter rig recorded with control-based continuation (``data`` 5 x N,
  ``time``, ``Wind_sped``); a ``rig.toml`` beside the data replaces it. Without
  a manifest the branch comes from the file name ("stable"/"unstable").

:func:`load_recordings` picks the reader from what a folder holds. Every problem
with the input raises :class:`~bayeshopf.errors.DataError` with one line naming
the file, what was expected and what was found. Readers open files read-only.
"""

from __future__ import annotations

import csv
import os
import re
import shutil
import uuid
import warnings
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import NoReturn

import numpy as np
import scipy.io

from bayeshopf._atomic import swap_in
from bayeshopf.data.recording import Recording, RecordingSet
from bayeshopf.data.rig import RigDescription, find_rig, load_rig
from bayeshopf.errors import DataError, OutputError

__all__ = [
    "dropped_report",
    "load_recordings",
    "read_cbc_mat",
    "read_interchange",
    "write_interchange",
]

MANIFEST = "manifest.csv"
MANIFEST_COLUMNS = ("file", "mu", "branch")
DT_TOLERANCE = 0.01  # largest relative deviation of dt from the mean accepted
RigLike = RigDescription | str | os.PathLike[str]

_HEADER_RE = re.compile(r"^(?P<name>[^\[\]]*?)\s*(?:\[(?P<unit>[^\[\]]*)\])?$")
_BAD_NAME_RE = re.compile(r"[,\[\]\"\r\n]")


def _one_line(exc: BaseException) -> str:
    """``"Type: message"`` of an exception squeezed onto one line."""
    msg = " ".join(str(exc).split()).split("; use `usecols`")[0]  # numpy's hint misleads
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


def _fmt_names(names: Iterable[str]) -> str:
    names = list(names)
    return ", ".join(names) if names else "(none)"


def _require_folder(folder: str | os.PathLike[str]) -> Path:
    folder = Path(folder)
    if not folder.exists():
        raise DataError(f"{folder}: data folder expected; not found")
    if not folder.is_dir():
        raise DataError(f"{folder}: expected a folder; found a file")
    return folder


def _check_samples(where: str, t: np.ndarray, channels: Mapping[str, np.ndarray]) -> None:
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


# --------------------------------------------------------------------------- interchange


def _read_manifest(path: Path) -> tuple[list[tuple[str, float, str]], dict[str, str]]:
    """Rows ``(file, mu, branch)`` and ``# key: value`` metadata of a manifest."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            lines = f.read().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{MANIFEST}: cannot be read ({_one_line(exc)})") from exc
    meta: dict[str, str] = {}
    body: list[tuple[int, str]] = []
    for lineno, line in enumerate(lines, start=1):
        if line.lstrip().startswith("#"):
            key, sep, value = line.lstrip().lstrip("#").partition(":")
            if sep:
                meta[key.strip().lower()] = value.strip()
        elif line.strip():
            body.append((lineno, line))
    if not body:
        raise DataError(f"{MANIFEST}: header with columns file, mu, branch expected; found none")
    try:
        parsed = list(csv.reader(line for _, line in body))
    except csv.Error as exc:
        raise DataError(f"{MANIFEST}: cannot be parsed as CSV ({_one_line(exc)})") from exc
    header = [c.strip() for c in parsed[0]]
    missing = [c for c in MANIFEST_COLUMNS if c not in header]
    if missing:
        raise DataError(
            f"{MANIFEST}: column(s) {_fmt_names(missing)} expected (header must contain "
            f"file, mu, branch); found columns {_fmt_names(header)}"
        )
    col = {c: header.index(c) for c in MANIFEST_COLUMNS}
    rows: list[tuple[str, float, str]] = []
    seen: set[str] = set()
    for i, ((lineno, _), fields) in enumerate(zip(body[1:], parsed[1:], strict=True), start=1):
        where = f"{MANIFEST} row {i} (line {lineno})"
        if len(fields) != len(header):
            raise DataError(
                f"{where}: {len(header)} fields expected (as in the header); found {len(fields)}"
            )
        file, mu_text, branch = (fields[col[c]].strip() for c in MANIFEST_COLUMNS)
        if not file:
            raise DataError(f"{where}: file name expected; found an empty field")
        if file in seen:
            raise DataError(f"{where}: each file listed once expected; found '{file}' again")
        seen.add(file)
        try:
            mu = float(mu_text)
        except ValueError:
            raise DataError(f"{where}: mu must be a number; found {mu_text!r}") from None
        if not np.isfinite(mu):
            raise DataError(f"{where}: mu must be a finite number; found {mu_text!r}")
        if branch.lower() not in ("stable", "unstable"):
            raise DataError(f"{where}: branch must be 'stable' or 'unstable'; found {branch!r}")
        rows.append((file, mu, branch.lower()))
    if not rows:
        raise DataError(f"{MANIFEST}: at least one recording row expected; found none")
    return rows, meta


def _read_csv(path: Path, name: str) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, str]]:
    """Time, channels and units of one interchange CSV."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            header_line = f.readline()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # empty-file warning: handled below
                values = np.loadtxt(f, delimiter=",", dtype=np.float64, ndmin=2)
    except (OSError, ValueError) as exc:  # UnicodeDecodeError is a ValueError
        raise DataError(f"{name}: cannot be parsed as a CSV of numbers ({_one_line(exc)})") from exc
    names: list[str] = []
    units: dict[str, str] = {}
    for cell in next(csv.reader([header_line]), []):
        m = _HEADER_RE.match(cell.strip())
        if m is None or not m["name"]:
            raise DataError(
                f"{name}: column header 'name' or 'name [unit]' expected; found {cell!r}"
            )
        names.append(m["name"])
        units[m["name"]] = (m["unit"] or "").strip()
    if len(set(names)) != len(names):
        raise DataError(f"{name}: distinct column names expected; found {_fmt_names(names)}")
    if "t" not in names:
        raise DataError(f"{name}: column 't' expected; found columns {_fmt_names(names)}")
    if len(names) < 2:
        raise DataError(f"{name}: at least one channel besides 't' expected; found none")
    if values.size and values.shape[1] != len(names):
        raise DataError(
            f"{name}: {len(names)} values per row expected (one per header column); "
            f"found {values.shape[1]}"
        )
    cols = values.T if values.size else np.empty((len(names), 0))
    data = dict(zip(names, cols, strict=True))
    t = data.pop("t")
    units.pop("t")
    _check_samples(name, t, data)
    return t, data, units


def read_interchange(
    folder: str | os.PathLike[str],
    planar: tuple[str, str] | None = None,
    rig: RigLike | None = None,
) -> RecordingSet:
    """Read a folder in the interchange format.

    The manifest may list ``.mat`` files beside (or instead of) CSV files: they
    are read as ``rig`` describes (:func:`read_cbc_mat`), with μ and branch
    taken from the manifest; the manifest's μ wins over the file's μ variable
    (e.g. ``Wind_sped``) and no branch is needed in the file name.

    Args:
        folder: Folder holding ``manifest.csv`` and the recordings it lists.
        planar: Names of the planar pair (z1, z2). Defaults to the first two
            channels (after ``t``) of the first recording, or the rig
            description's pair when that recording is a ``.mat`` file.
        rig: Description of the ``.mat`` files (a
            :class:`~bayeshopf.data.rig.RigDescription` or a rig file path);
            default the built-in flutter rig.

    Returns:
        The recordings in manifest order, with ``mu_label``/``mu_units`` from the
        manifest's ``# mu_label:`` and ``# mu_units:`` lines (else the rig
        description's when a ``.mat`` file is listed, else ``"mu"`` and ``""``).

    Raises:
        DataError: If the folder, manifest or a recording is missing or malformed,
            a planar channel is missing, or the recordings' channels differ.
    """
    folder = _require_folder(folder)
    described = None if rig is None else load_rig(rig)
    manifest = folder / MANIFEST
    if not manifest.is_file():
        found = sorted(p.name for p in folder.iterdir())[:8]
        raise DataError(
            f"{folder}: {MANIFEST} expected; not found (folder holds {_fmt_names(found)})"
        )
    rows, meta = _read_manifest(manifest)
    recordings: list[Recording] = []
    used_rig: RigDescription | None = None
    for i, (file, mu, branch) in enumerate(rows, start=1):
        path = folder / file
        if not path.is_file():
            raise DataError(f"{file}: listed in {MANIFEST} row {i} but not found in {folder}")
        mat = None
        if path.suffix.lower() == ".mat":
            used_rig = described or RigDescription.flutter_cbc()
            mat = _read_one_mat(path, used_rig, mu=mu, branch=branch)
            t, channels, units = mat.t, dict(mat.channels), dict(mat.units)
        else:
            t, channels, units = _read_csv(path, file)
        if recordings:
            first = recordings[0]
            if set(channels) != set(first.channels):
                raise DataError(
                    f"{file}: channels {_fmt_names(first.channels)} expected (as in "
                    f"{first.name}); found {_fmt_names(channels)}"
                )
        if planar is None and mat is not None:
            planar = used_rig.planar
        pair = planar if planar is not None else tuple(channels)[:2]
        if len(pair) < 2:
            raise DataError(
                f"{file}: two channels besides 't' expected (the planar pair); "
                f"found {_fmt_names(channels)}"
            )
        for c in pair:
            if c not in channels:
                raise DataError(
                    f"{file}: column '{c}' expected (the planar pair is {pair[0]}, {pair[1]}); "
                    f"found columns t, {_fmt_names(channels)}"
                )
        planar = (pair[0], pair[1])
        recordings.append(
            mat if mat is not None else
            Recording(t, channels, units, mu, branch, name=file, source=str(path.resolve()))
        )
    assert planar is not None
    return RecordingSet(
        tuple(recordings),
        planar,
        mu_label=meta.get("mu_label", used_rig.mu_label if used_rig else "mu"),
        mu_units=meta.get("mu_units", used_rig.mu_units if used_rig else ""),
        extra={"rig": used_rig.name} if used_rig else {},
    )


def _csv_names(rs: RecordingSet) -> list[str]:
    """Unique, filesystem-safe CSV file names for the recordings of ``rs``."""
    out: list[str] = []
    taken = {MANIFEST}
    for i, r in enumerate(rs, start=1):
        base = Path(r.name).name
        stem = base[:-4] if base.lower().endswith(".csv") else (Path(base).stem or base)
        stem = re.sub(r"[^A-Za-z0-9._-]", "_", stem).strip("._") or f"rec{i}"
        fname, k = f"{stem}.csv", 2
        while fname.lower() in taken:
            fname, k = f"{stem}_{k}.csv", k + 1
        taken.add(fname.lower())
        out.append(fname)
    return out


def _write_folder(rs: RecordingSet, tmp: Path) -> None:
    """Write manifest and recording CSVs of ``rs`` into the (empty) folder ``tmp``."""
    fnames = _csv_names(rs)
    first = list(rs[0].channels)
    for r in rs:
        if set(r.channels) != set(first):
            raise DataError(
                f"{r.name}: channels {_fmt_names(first)} expected (as in {rs[0].name}); "
                f"found {_fmt_names(r.channels)}"
            )
    order = list(rs.planar) + [c for c in first if c not in rs.planar]
    for c in order:
        if c == "t" or _BAD_NAME_RE.search(c) or c != c.strip() or not c:
            raise DataError(
                f"channel name {c!r}: expected a non-empty name other than 't' without "
                "commas, brackets, quotes or surrounding spaces"
            )
    for r, fname in zip(rs, fnames, strict=True):
        cols = ["t"]
        for c in order:
            unit = r.units.get(c, "")
            if _BAD_NAME_RE.search(unit):
                raise DataError(
                    f"{r.name}: unit of '{c}' without commas or brackets expected; found {unit!r}"
                )
            cols.append(f"{c} [{unit}]" if unit else c)
        table = np.column_stack([r.t, *(r.channels[c] for c in order)])
        np.savetxt(
            tmp / fname, table, fmt="%.17g", delimiter=",", header=",".join(cols), comments=""
        )
    lines = [
        f"# mu_label: {' '.join(rs.mu_label.split())}",
        f"# mu_units: {' '.join(rs.mu_units.split())}",
        ",".join(MANIFEST_COLUMNS),
        *(f"{fname},{r.mu!r},{r.branch}" for r, fname in zip(rs, fnames, strict=True)),
    ]
    (tmp / MANIFEST).write_text("\n".join(lines) + "\n", encoding="utf-8")


def write_interchange(
    rs: RecordingSet, folder: str | os.PathLike[str], *, overwrite: bool = False
) -> Path:
    """Write a recording set as an interchange folder, atomically.

    Everything is written into a temporary sibling folder that is then renamed
    into place, so ``folder`` never holds a partial result. The planar pair is
    written as the first two channels, so :func:`read_interchange` restores it.
    CSV values use ``%.17g`` and round-trip exactly. The CSV file names come from
    the recording names (``.csv`` extension, unsafe characters replaced).

    Args:
        rs: The recordings to write.
        folder: Destination folder; created (with parents) if missing.
        overwrite: Replace ``folder`` if it exists and is not empty.

    Returns:
        The path of the written folder.

    Raises:
        OutputError: If ``folder`` is a file, exists non-empty without
            ``overwrite``, or cannot be written.
        DataError: If the recordings' channels differ or a channel name or unit
            cannot be written in a CSV header.
    """
    folder = Path(folder)
    if folder.exists():
        if not folder.is_dir():
            raise OutputError(f"{folder}: a folder to write into expected; found a file")
        if any(folder.iterdir()) and not overwrite:
            raise OutputError(
                f"{folder}: an empty or new folder expected; found a non-empty folder "
                "(pass overwrite=True to replace it)"
            )
    tag = uuid.uuid4().hex[:8]
    tmp = folder.parent / f".{folder.name}.tmp-{tag}"
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        os.mkdir(tmp)
        _write_folder(rs, tmp)
        swap_in(tmp, folder, tag)
    except OSError as exc:
        raise OutputError(f"{folder}: cannot be written ({_one_line(exc)})") from exc
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return folder


# --------------------------------------------------------------------------- .mat (rig description)


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


def _read_one_mat(
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
        raise DataError(f"{name}: cannot be read as a MATLAB .mat file ({_one_line(exc)})") from exc

    def absent(var: str, what: str) -> NoReturn:
        held = _mat_variables(path)
        raise DataError(
            f"{name}: variable '{var}' ({what}; {rig.where}) expected; not found (file holds "
            f"{_fmt_names(held[:10])}{', ...' if len(held) > 10 else ''})"
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
                   and rig.data_rows else f"channels {_fmt_names(by_row)} by row"
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
        t = numeric(tv).ravel()
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
    _check_samples(name, t, {})

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
        drop |= c.no_reading(raw[c.name])
    for c in rig.channels:
        bad = ~np.isfinite(raw[c.name]) & ~drop
        if bad.any():
            raise DataError(
                f"{name}: channel '{c.name}' has {int(bad.sum())} non-finite sample(s) (NaN/inf), "
                f"first at index {int(np.argmax(bad))}; expected finite numbers (or missing = "
                "[\"nan\"] for the channel in the rig description)"
            )
    keep = ~drop
    if keep.sum() < 3:
        raise DataError(f"{name}: at least 3 samples with a reading expected; found "
                        f"{int(keep.sum())} of {n} ({rig.where} marks the rest as no reading)")
    channels = {c.name: c.to_physical(raw[c.name][keep]) for c in rig.channels}
    units = {c.name: c.unit for c in rig.channels}
    return Recording(t[keep], channels, units, mu, branch, name=name,
                     source=str(path.resolve()), dropped=int(drop.sum()))


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

    Samples at which a channel has no reading (the description's sentinel,
    NaN or full-turn jump) are left out with their time stamps;
    :attr:`Recording.dropped` counts them (:func:`dropped_report`).

    Args:
        path: A folder of ``.mat`` files, or a list of ``.mat`` file paths.
        rig: A :class:`~bayeshopf.data.rig.RigDescription` or the path of a rig
            file; default the built-in flutter rig.

    Returns:
        Recordings with the description's planar pair, ``mu_label`` and
        ``mu_units``, stable branch first, each branch sorted by μ.

    Raises:
        DataError: If the folder or a file is missing or unreadable, a variable
            or row the description names is missing, the samples are bad, or a
            file name tells no branch ("stable"/"unstable").
    """
    rig = RigDescription.flutter_cbc() if rig is None else load_rig(rig)
    if isinstance(path, str | os.PathLike):
        folder = _require_folder(path)
        files = sorted(folder.glob("*.mat"))
        if not files:
            found = sorted(p.name for p in folder.iterdir())[:8]
            raise DataError(f"{folder}: .mat files expected; found {_fmt_names(found)}")
    else:
        files = [Path(p) for p in path]
        if not files:
            raise DataError("read_cbc_mat: at least one .mat file expected; got an empty list")
    recs = sorted(
        (_read_one_mat(p, rig) for p in files),
        key=lambda r: (r.branch == "unstable", r.mu, r.name),
    )
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


# --------------------------------------------------------------------------- auto-detect


def load_recordings(
    path: str | os.PathLike[str],
    planar: tuple[str, str] | None = None,
    rig: RigLike | None = None,
) -> RecordingSet:
    """Read recordings, choosing the reader from what ``path`` holds.

    A folder with ``manifest.csv`` is read by :func:`read_interchange`; a folder
    with ``.mat`` files by :func:`read_cbc_mat`. A path to a ``manifest.csv`` or
    to a single ``.mat`` file is accepted too. ``.mat`` files are read as
    ``rig`` describes, else as the ``rig.toml`` beside them, else as the
    built-in flutter rig.

    Args:
        path: Folder (or file, see above) to read.
        planar: Names of the planar pair (z1, z2); defaults to the format's own
            (first two channels for interchange, the rig description's pair for
            ``.mat`` files).
        rig: A :class:`~bayeshopf.data.rig.RigDescription` or the path of a rig
            file (TOML or JSON).

    Returns:
        The recordings.

    Raises:
        DataError: If ``path`` does not exist, holds neither format, the rig
            description is invalid, or the chosen reader rejects its contents.
    """
    p = Path(path)
    if rig is not None:
        rig = load_rig(rig)
    elif p.is_dir() or p.is_file():
        rig = find_rig(p if p.is_dir() else p.parent)
    if p.is_file() and p.name == MANIFEST:
        return read_interchange(p.parent, planar, rig)
    if p.is_file() and p.suffix.lower() == ".mat":
        rs = read_cbc_mat([p], rig)
    else:
        folder = _require_folder(p)
        if (folder / MANIFEST).is_file():
            return read_interchange(folder, planar, rig)
        if not any(folder.glob("*.mat")):
            found = sorted(q.name for q in folder.iterdir())[:8]
            raise DataError(
                f"{folder}: {MANIFEST} (interchange format) or .mat files (CBC) expected; "
                f"found {_fmt_names(found)}"
            )
        rs = read_cbc_mat(folder, rig)
    if planar is None or tuple(planar) == rs.planar:
        return rs
    control = None if rs.control in planar else rs.control
    return RecordingSet(rs.recordings, (planar[0], planar[1]), rs.mu_label, rs.mu_units, rs.extra,
                        control)
