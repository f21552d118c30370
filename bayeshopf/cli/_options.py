"""Options several commands share, defined once: fit folder, recordings, CI, figure format."""

from __future__ import annotations

import argparse


def add_fit_dir(p: argparse.ArgumentParser) -> None:
    """The positional ``fit_dir``: a folder that ``fit`` or ``demo`` wrote."""
    p.add_argument("fit_dir", help="folder written by 'bayeshopf fit' or 'bayeshopf demo'")


def add_recordings(p: argparse.ArgumentParser, purpose: str) -> None:
    """``--recordings DATA``: the recordings a fit was made from, for ``purpose``."""
    p.add_argument("--recordings", metavar="DATA", default=None,
                   help="the recordings the fit was made from (folder, as for 'fit'), for "
                   + purpose)


def add_ci(p: argparse.ArgumentParser, of: str = "the bands and intervals") -> None:
    """``--ci``: the probability mass of ``of`` (default 0.9)."""
    p.add_argument("--ci", type=float, default=0.9,
                   help=f"probability mass of {of} (default 0.9)")


def add_format(p: argparse.ArgumentParser, of: str = "figure") -> None:
    """``--format``: the file format of the figures (png, pdf or svg; default png)."""
    p.add_argument("--format", choices=("png", "pdf", "svg"), default="png",
                   help=f"{of} format (default png; pdf and svg are vector)")
