"""Atomic writes: a file or an output folder appears whole or not at all.

Shared by every writer of outputs (figures, posterior files, summaries, stored
programs and simulations), so that an interrupted run never leaves a
half-written file and a reader never sees one.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
from collections.abc import Iterable, Iterator
from pathlib import Path

from bayeshopf.errors import OutputError


@contextlib.contextmanager
def replacing(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A fresh temporary path beside ``path``, moved onto ``path`` when the block succeeds.

    The caller writes the whole file to the yielded path; on leaving the block
    it replaces ``path`` in one :func:`os.replace` (atomic on one file system).
    If the block raises, the temporary file is removed and ``path`` (if it
    existed) is left as it was. Missing parent folders are created. The name
    is fresh (``.{name}.{random}.tmp``) and not created here, so the writer's
    own ``open`` gives the file the usual permissions (0o666 less the umask),
    not ``tempfile``'s 0o600.

    Args:
        path: The destination file.

    Yields:
        The temporary path to write.

    Example:
        >>> with replacing(out / "summary.json") as tmp:     # doctest: +SKIP
        ...     tmp.write_text(text)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.{secrets.token_hex(8)}.tmp"
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def swap_in(tmp: Path, folder: Path, tag: str) -> None:
    """Move the finished folder ``tmp`` to ``folder``, replacing an existing one.

    The old folder is renamed aside first and restored if the final rename
    fails, so ``folder`` is at every moment either the old or the new content.

    Args:
        tmp: The complete new folder, on the same file system as ``folder``.
        folder: Where it must end up.
        tag: Unique suffix for the aside name ``.{name}.old-{tag}``.

    Raises:
        OSError: If a rename fails (the old folder is then back in place).
    """
    if not folder.exists():
        os.rename(tmp, folder)
        return
    old = folder.parent / f".{folder.name}.old-{tag}"
    os.rename(folder, old)
    try:
        os.rename(tmp, folder)
    except OSError:
        os.rename(old, folder)
        raise
    shutil.rmtree(old, ignore_errors=True)


def move_into(stage: Path, folder: Path, files: Iterable[Path] | None = None) -> list[Path]:
    """Move the finished files of the folder ``stage`` into ``folder``, each by :func:`os.replace`.

    Where ``folder`` does not exist, ``stage`` itself is renamed to it (one
    :func:`os.replace`). Otherwise every file moves to the same place relative
    to ``folder`` (missing subfolders are made), replacing a file of that name
    and leaving the others in ``folder`` as they were: each file is at every
    moment either the old or the new one. ``stage`` must be on the same file
    system as ``folder``; what is left of it is the caller's to remove.

    Args:
        stage: The folder the files were written into.
        folder: Where they must end up.
        files: The files of ``stage`` to move (default all, subfolders included).

    Returns:
        The paths the files now have.
    """
    if files is None and not folder.exists():
        os.replace(stage, folder)
        return sorted(p for p in folder.rglob("*") if p.is_file())
    moved = []
    for src in sorted(stage.rglob("*")) if files is None else files:
        dst = folder / Path(src).relative_to(stage)
        if Path(src).is_dir():
            dst.mkdir(exist_ok=True)
        else:
            os.replace(src, dst)
            moved.append(dst)
    return moved


@contextlib.contextmanager
def new_folder(folder: Path) -> Iterator[Path]:
    """A fresh empty folder beside ``folder``, swapped in for it when the block succeeds.

    The caller writes the whole content into the yielded folder; on leaving
    the block it replaces ``folder`` (an existing one as a whole, by
    :func:`swap_in`). Whatever happens, the temporary folder is gone
    afterwards and ``folder`` is either the old or the new content. Missing
    parent folders are created.

    Yields:
        The temporary folder ``.{name}.tmp-{tag}`` to write.

    Raises:
        OSError: If a folder cannot be made or renamed.
    """
    tag = secrets.token_hex(4)
    tmp = folder.parent / f".{folder.name}.tmp-{tag}"
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        os.mkdir(tmp)
        yield tmp
        swap_in(tmp, folder, tag)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def vacant_folder(folder: str | os.PathLike[str], overwrite: bool, how: str) -> Path:
    """``folder`` as a path, where it is new or empty, or may be replaced (``overwrite``).

    Args:
        folder: The folder to write.
        overwrite: Whether a non-empty ``folder`` may be replaced.
        how: How the user allows that, for the message (``"pass overwrite=True"``).

    Raises:
        OutputError: If a file is in its place, or it is not empty and not
            ``overwrite``.
    """
    folder = Path(folder)
    if folder.exists():
        if not folder.is_dir():
            raise OutputError(f"{folder}: a folder to write into expected; found a file")
        if any(folder.iterdir()) and not overwrite:
            raise OutputError(f"{folder}: an empty or new folder expected; found a non-empty "
                              f"folder ({how} to replace it)")
    return folder
