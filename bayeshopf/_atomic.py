"""Atomic replacement of an output folder (shared by every command that writes one)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path


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
