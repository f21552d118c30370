"""Writing figures to disk atomically."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from matplotlib.figure import Figure

from bayeshopf._atomic import replacing


def save_figure(fig: Figure, path: str | os.PathLike[str], dpi: int = 150) -> Path:
    """Write ``fig`` to ``path`` atomically, then close it.

    The figure is rendered into a temporary file in the destination folder and
    moved into place with :func:`os.replace`, so a reader never sees a
    half-written file and an interrupted save leaves the old file (if any)
    untouched. Missing parent folders are created. The format follows the file
    suffix (``.png`` when there is none). Closing unregisters the figure from
    pyplot (if it was made there) and clears it, so it cannot be saved again.

    Args:
        fig: The figure to write.
        path: Destination file.
        dpi: Resolution in dots per inch (for raster formats).

    Returns:
        The destination path.
    """
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or "png"
    try:
        with replacing(path) as tmp, open(tmp, "xb") as fh:
            fig.savefig(fh, format=fmt, dpi=dpi, bbox_inches="tight")
    finally:
        _close(fig)
    return path


def _close(fig: Figure) -> None:
    """Release ``fig``: unregister it from pyplot if it was made there, drop its artists."""
    plt = sys.modules.get("matplotlib.pyplot")
    if plt is not None:
        plt.close(fig)
    fig.clear()
