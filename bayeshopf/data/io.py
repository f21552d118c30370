"""Read and write LCO recordings: one entry point for every supported format.

Formats (each in its own module; every public name is importable from here):

* **Interchange** (:func:`read_interchange`, :func:`write_interchange`,
  :mod:`bayeshopf.data.interchange`): a folder holding ``manifest.csv``
  (columns ``file,mu,branch`` and optionally ``name``) and one CSV per
  recording with header ``t,<channel>,...``; a header cell may carry its unit
  in square brackets (``h [mm]``, ``t [ms]``). The manifest may list ``.mat``
  files too.
* **MATLAB** (:func:`read_cbc_mat`, :mod:`bayeshopf.data.matfile`): a folder of
  ``.mat`` files read as a :class:`~bayeshopf.data.rig.RigDescription` says;
  the built-in description is the wind-tunnel flutter rig recorded with
  control-based continuation, and a ``rig.toml`` beside the data replaces it.
* **Published data sets** (:mod:`bayeshopf.data.datasets`), by name:
  ``"flutter_cbc"``.

:func:`read_recordings` picks the reader from what it is given;
:func:`load_recordings` does the same for paths. Time is read in seconds and
each channel in one unit across the set (:mod:`bayeshopf.data.units`); NaN,
empty cells and sentinels are "no reading" and are left out with their time
stamps (:func:`dropped_report`); a CBC recording on which the controller did
not converge is marked (:mod:`bayeshopf.data.convergence`). Every problem with
the input raises :class:`~bayeshopf.errors.DataError` with one line naming the
file, what was expected and what was found. Readers open files read-only.
"""

from __future__ import annotations

import os
from pathlib import Path

from bayeshopf.data._common import DT_TOLERANCE as DT_TOLERANCE
from bayeshopf.data._common import MANIFEST as MANIFEST
from bayeshopf.data._common import MANIFEST_COLUMNS as MANIFEST_COLUMNS
from bayeshopf.data._common import check_samples as _check_samples  # noqa: F401
from bayeshopf.data._common import fmt_names as _fmt_names
from bayeshopf.data._common import one_line as _one_line  # noqa: F401
from bayeshopf.data._common import require_folder as _require_folder
from bayeshopf.data.datasets import flutter_cbc
from bayeshopf.data.interchange import read_interchange as read_interchange
from bayeshopf.data.interchange import write_interchange as write_interchange
from bayeshopf.data.matfile import dropped_report as dropped_report
from bayeshopf.data.matfile import read_cbc_mat as read_cbc_mat
from bayeshopf.data.recording import RecordingSet
from bayeshopf.data.rig import RigDescription, find_rig, load_rig
from bayeshopf.data.screening import convergence_report as convergence_report
from bayeshopf.data.screening import unconverged as unconverged
from bayeshopf.errors import DataError

__all__ = [
    "DATASETS",
    "convergence_report",
    "dropped_report",
    "load_recordings",
    "read_cbc_mat",
    "read_interchange",
    "read_recordings",
    "unconverged",
    "write_interchange",
]

RigLike = RigDescription | str | os.PathLike[str]
#: Names of the published data sets :func:`read_recordings` reads.
DATASETS = ("flutter_cbc",)


def _with_planar(rs: RecordingSet, planar: tuple[str, str] | None) -> RecordingSet:
    """``rs`` with the planar pair ``planar`` (its control left out if in the pair)."""
    if planar is None or tuple(planar) == rs.planar:
        return rs
    control = None if rs.control in planar else rs.control
    return RecordingSet(rs.recordings, (planar[0], planar[1]), rs.mu_label, rs.mu_units, rs.extra,
                        control)


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
    return _with_planar(rs, planar)


def read_recordings(
    source: str | os.PathLike[str] | RecordingSet,
    planar: tuple[str, str] | None = None,
    rig: RigLike | None = None,
    *,
    download: bool = False,
) -> RecordingSet:
    """Read recordings in any supported format.

    ``source`` may be an interchange folder or its ``manifest.csv``, a folder
    of ``.mat`` files or one ``.mat`` file (:func:`load_recordings`), the name
    of a published data set (:data:`DATASETS`, e.g. ``"flutter_cbc"``, read by
    :func:`bayeshopf.data.datasets.flutter_cbc`), or a
    :class:`~bayeshopf.data.recording.RecordingSet` (returned as is, with
    ``planar`` applied).

    Args:
        source: What to read (above). A path that exists wins over a data
            set of the same name.
        planar: Names of the planar pair (z1, z2); defaults to the format's own.
        rig: A rig description (or its file) for ``.mat`` files.
        download: For a data set: download it when no local copy is named
            (:func:`bayeshopf.data.datasets.flutter_cbc`).

    Returns:
        The recordings, with the control channel unless it is in ``planar``.

    Raises:
        DataError: If ``source`` is none of the above, or its reader refuses it.
    """
    if isinstance(source, RecordingSet):
        rs = source
    elif isinstance(source, str) and source in DATASETS and not Path(source).exists():
        if rig is not None:
            raise DataError(f"rig: describes .mat files of a folder; data set '{source}' has "
                            "its own description (leave rig out)")
        rs = flutter_cbc(download=download)
    elif isinstance(source, str | os.PathLike):
        return load_recordings(source, planar, rig)
    else:
        raise DataError(f"read_recordings: a folder, a file, a data set name "
                        f"({', '.join(DATASETS)}) or a RecordingSet expected; found "
                        f"{type(source).__name__}")
    return _with_planar(rs, planar)
