"""Read and write the interchange format: a manifest and one CSV per recording.

A folder holds ``manifest.csv`` (columns ``file,mu,branch`` and, optionally,
``name``; optional leading comment lines ``# mu_label: ...``, ``# mu_units:
...`` and ``# missing: -9999, ...``) and one CSV per recording with header
``t,<channel>,<channel>,...``. A header cell may carry its unit in square
brackets, e.g. ``h [mm]`` or ``t [ms]``: time is read in seconds and every
channel in one unit across the folder (:mod:`bayeshopf.data.units`).

**No reading.** An empty cell, ``nan``, a value listed in ``# missing:``, or a
channel's ``sentinel`` in the rig description means that the sensor had no
reading: the sample (the whole row, with its time stamp) is left out and
counted in :attr:`~bayeshopf.data.recording.Recording.dropped`. The harmonic
features are least-squares fits over the samples that remain, so a gap needs
no filling. An infinite value is refused.

The manifest may list ``.mat`` files too; they are read as the rig description
says (:mod:`bayeshopf.data.matfile`), and the manifest's μ and branch win over
the file's μ variable and its name. The rig description's ``control`` channel
is kept. Every problem raises :class:`~bayeshopf.errors.DataError` with one
line naming the file, what was expected and what was found.
"""

from __future__ import annotations

import csv
import math
import os
import re
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from bayeshopf._atomic import new_folder, vacant_folder
from bayeshopf.data._common import (
    MANIFEST,
    MANIFEST_COLUMNS,
    check_rates,
    check_samples,
    fmt_names,
    one_line,
    require_folder,
)
from bayeshopf.data.matfile import read_one_mat
from bayeshopf.data.recording import Recording, RecordingSet
from bayeshopf.data.rig import RigDescription, load_rig
from bayeshopf.data.units import harmonise, time_in_seconds
from bayeshopf.errors import DataError, OutputError

__all__ = ["read_interchange", "write_interchange"]

RigLike = RigDescription | str | os.PathLike[str]

_HEADER_RE = re.compile(r"^(?P<name>[^\[\]]*?)\s*(?:\[(?P<unit>[^\[\]]*)\])?$")
_BAD_NAME_RE = re.compile(r"[,\[\]\"\r\n]")


@dataclass(frozen=True)
class _Row:
    """One recording row of a manifest."""

    file: str
    mu: float
    branch: str
    name: str


def _read_manifest(path: Path) -> tuple[list[_Row], dict[str, str]]:
    """Rows and ``# key: value`` metadata of a manifest."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            lines = f.read().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{MANIFEST}: cannot be read ({one_line(exc)})") from exc
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
        raise DataError(f"{MANIFEST}: cannot be parsed as CSV ({one_line(exc)})") from exc
    header = [c.strip() for c in parsed[0]]
    missing = [c for c in MANIFEST_COLUMNS if c not in header]
    if missing:
        raise DataError(
            f"{MANIFEST}: column(s) {fmt_names(missing)} expected (header must contain "
            f"file, mu, branch); found columns {fmt_names(header)}"
        )
    col = {c: header.index(c) for c in MANIFEST_COLUMNS}
    name_col = header.index("name") if "name" in header else None
    rows: list[_Row] = []
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
        name = fields[name_col].strip() if name_col is not None else ""
        rows.append(_Row(file, mu, branch.lower(), name or file))
    if not rows:
        raise DataError(f"{MANIFEST}: at least one recording row expected; found none")
    return rows, meta


def _sentinels(meta: dict[str, str]) -> tuple[float, ...]:
    """The values of the manifest's ``# missing:`` line."""
    text = meta.get("missing", "").strip()
    out = []
    for cell in filter(None, (c.strip() for c in text.split(","))):
        try:
            value = float(cell)
        except ValueError:
            raise DataError(f"{MANIFEST}: '# missing:' must list numbers (the values that mean "
                            f"no reading, comma-separated); found {cell!r}") from None
        if not math.isfinite(value):
            raise DataError(f"{MANIFEST}: '# missing:' must list finite numbers (NaN and empty "
                            f"cells mean no reading anyway); found {cell!r}")
        out.append(value)
    return tuple(out)


def _nan_if_empty(cell: str) -> float:
    return float(cell) if cell.strip() else math.nan


def _load_table(path: Path, name: str) -> tuple[str, np.ndarray]:
    """Header line and values of a CSV; an empty cell reads as NaN."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            header_line = f.readline()
            body = f.read()
    except (OSError, ValueError) as exc:  # UnicodeDecodeError is a ValueError
        raise DataError(f"{name}: cannot be parsed as a CSV of numbers ({one_line(exc)})") from exc
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # empty-file warning: handled by the caller
        try:
            return header_line, np.loadtxt(body.splitlines(), delimiter=",", dtype=np.float64,
                                           ndmin=2)
        except ValueError:
            pass  # an empty cell, or a malformed row: read cell by cell below
        try:
            return header_line, np.loadtxt(body.splitlines(), delimiter=",", dtype=np.float64,
                                           ndmin=2, converters=_nan_if_empty)
        except ValueError as exc:
            raise DataError(f"{name}: cannot be parsed as a CSV of numbers "
                            f"({one_line(exc)})") from exc


def _read_csv(path: Path, name: str, sentinels: tuple[float, ...],
              rig: RigDescription | None
              ) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, str], int]:
    """Time (s), channels, units and the number of rows left out of one CSV."""
    header_line, values = _load_table(path, name)
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
        raise DataError(f"{name}: distinct column names expected; found {fmt_names(names)}")
    if "t" not in names:
        raise DataError(f"{name}: column 't' expected; found columns {fmt_names(names)}")
    if len(names) < 2:
        raise DataError(f"{name}: at least one channel besides 't' expected; found none")
    if values.size and values.shape[1] != len(names):
        raise DataError(
            f"{name}: {len(names)} values per row expected (one per header column); "
            f"found {values.shape[1]}"
        )
    cols = values.T.copy() if values.size else np.empty((len(names), 0))
    data = dict(zip(names, cols, strict=True))
    specs = {c.name: c for c in rig.channels} if rig is not None else {}
    for c, x in data.items():
        if c == "t":
            continue
        for s in sentinels:
            x[x == s] = np.nan
        if c in specs:
            x[specs[c].no_reading(x) & np.isfinite(x)] = np.nan
    gap = np.zeros(cols.shape[1], dtype=bool)
    for c, x in data.items():
        inf = np.isinf(x)
        if inf.any():
            raise DataError(
                f"{name}: channel '{c}' has {int(inf.sum())} infinite sample(s), first at index "
                f"{int(np.argmax(inf))}; expected finite numbers (an empty cell or NaN means no "
                "reading)"
            )
        gap |= np.isnan(x)
    if gap.any():
        data = {c: x[~gap] for c, x in data.items()}
    t = time_in_seconds(data.pop("t"), units.pop("t"), name)
    check_samples(name, t, data)
    return t, data, units, int(gap.sum())


def read_interchange(
    folder: str | os.PathLike[str],
    planar: tuple[str, str] | None = None,
    rig: RigLike | None = None,
) -> RecordingSet:
    """Read a folder in the interchange format (module docstring).

    The manifest may list ``.mat`` files beside (or instead of) CSV files: they
    are read as ``rig`` describes (:func:`~bayeshopf.data.matfile.read_cbc_mat`),
    with μ and branch taken from the manifest; the manifest's μ wins over the
    file's μ variable (e.g. ``Wind_sped``) and no branch is needed in the file
    name.

    Args:
        folder: Folder holding ``manifest.csv`` and the recordings it lists.
        planar: Names of the planar pair (z1, z2). Defaults to the first two
            channels (after ``t``) of the first recording, or the rig
            description's pair when that recording is a ``.mat`` file.
        rig: Description of the ``.mat`` files (a
            :class:`~bayeshopf.data.rig.RigDescription` or a rig file path);
            default the built-in flutter rig. Given, its channel units are the
            units of the set, its sentinels mark no reading in the CSV columns
            of the same name, and its ``control`` channel is the set's control
            when every recording has it.

    Returns:
        The recordings in manifest order, named by the manifest's ``name``
        column (else the file name), with ``mu_label``/``mu_units`` from the
        manifest's ``# mu_label:`` and ``# mu_units:`` lines (else the rig
        description's when a ``.mat`` file is listed, else ``"mu"`` and ``""``),
        and the rig description's ``control`` channel (when a ``.mat`` file is
        listed or ``rig`` is given) unless it is in the planar pair.

    Raises:
        DataError: If the folder, manifest or a recording is missing or malformed,
            a planar channel is missing, the recordings' channels differ, a unit
            is unknown or not convertible, or the sample rates differ by more
            than :data:`~bayeshopf.data._common.RATE_SPREAD`.
    """
    folder = require_folder(folder)
    described = None if rig is None else load_rig(rig)
    manifest = folder / MANIFEST
    if not manifest.is_file():
        found = sorted(p.name for p in folder.iterdir())[:8]
        raise DataError(
            f"{folder}: {MANIFEST} expected; not found (folder holds {fmt_names(found)})"
        )
    rows, meta = _read_manifest(manifest)
    sentinels = _sentinels(meta)
    recordings: list[Recording] = []
    used_rig: RigDescription | None = None
    for i, row in enumerate(rows, start=1):
        file = row.file
        path = folder / file
        if not path.is_file():
            raise DataError(f"{file}: listed in {MANIFEST} row {i} but not found in {folder}")
        if path.suffix.lower() == ".mat":
            used_rig = described or RigDescription.flutter_cbc()
            rec = read_one_mat(path, used_rig, mu=row.mu, branch=row.branch)
            if row.name != file:
                rec = replace(rec, name=row.name)
        else:
            t, channels, units, dropped = _read_csv(path, file, sentinels, described)
            rec = Recording(t, channels, units, row.mu, row.branch, name=row.name,
                            source=str(path.resolve()), dropped=dropped)
        if recordings and set(rec.channels) != set(recordings[0].channels):
            first = recordings[0]
            raise DataError(
                f"{file}: channels {fmt_names(first.channels)} expected (as in "
                f"{first.name}); found {fmt_names(rec.channels)}"
            )
        if planar is None and path.suffix.lower() == ".mat":
            planar = used_rig.planar
        pair = planar if planar is not None else tuple(rec.channels)[:2]
        if len(pair) < 2:
            raise DataError(
                f"{file}: two channels besides 't' expected (the planar pair); "
                f"found {fmt_names(rec.channels)}"
            )
        for c in pair:
            if c not in rec.channels:
                raise DataError(
                    f"{file}: column '{c}' expected (the planar pair is {pair[0]}, {pair[1]}); "
                    f"found columns t, {fmt_names(rec.channels)}"
                )
        planar = (pair[0], pair[1])
        recordings.append(rec)
    assert planar is not None
    rig_of_set = used_rig or described
    declared = {c.name: c.unit for c in rig_of_set.channels} if rig_of_set else {}
    recs = harmonise(recordings, declared)
    check_rates([r.name for r in recs], [r.dt for r in recs])
    control = rig_of_set.control if rig_of_set else None
    if control is not None and (control in planar or control not in recs[0].channels):
        control = None
    return RecordingSet(
        recs,
        planar,
        mu_label=meta.get("mu_label", used_rig.mu_label if used_rig else "mu"),
        mu_units=meta.get("mu_units", used_rig.mu_units if used_rig else ""),
        extra={"rig": used_rig.name} if used_rig else {},
        control=control,
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


def _csv_cell(text: str) -> str:
    """``text`` as one CSV field (quoted when it holds a comma or a quote)."""
    text = " ".join(text.split())
    return f'"{text.replace(chr(34), chr(34) * 2)}"' if ("," in text or '"' in text) else text


def _write_folder(rs: RecordingSet, tmp: Path) -> None:
    """Write manifest and recording CSVs of ``rs`` into the (empty) folder ``tmp``."""
    fnames = _csv_names(rs)
    first = list(rs[0].channels)
    for r in rs:
        if set(r.channels) != set(first):
            raise DataError(
                f"{r.name}: channels {fmt_names(first)} expected (as in {rs[0].name}); "
                f"found {fmt_names(r.channels)}"
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
    named = any(r.name != fname for r, fname in zip(rs, fnames, strict=True))
    lines = [
        f"# mu_label: {' '.join(rs.mu_label.split())}",
        f"# mu_units: {' '.join(rs.mu_units.split())}",
        ",".join(MANIFEST_COLUMNS + (("name",) if named else ())),
        *(f"{fname},{r.mu!r},{r.branch}" + (f",{_csv_cell(r.name)}" if named else "")
          for r, fname in zip(rs, fnames, strict=True)),
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
    the recording names (``.csv`` extension, unsafe characters replaced); when
    a file name differs from its recording's name, the manifest gets a
    ``name`` column, so that the names round-trip too. Convergence records
    (:attr:`~bayeshopf.data.recording.Recording.convergence`) are not written.

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
    folder = vacant_folder(folder, overwrite, "pass overwrite=True")
    try:
        with new_folder(folder) as tmp:
            _write_folder(rs, tmp)
    except OSError as exc:
        raise OutputError(f"{folder}: cannot be written ({one_line(exc)})") from exc
    return folder


