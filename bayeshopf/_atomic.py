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
from collections.abc import Iterator
from pathlib import Path


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
