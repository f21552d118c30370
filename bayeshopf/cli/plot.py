"""``bayeshopf plot``: a saved fit's figures drawn again, without refitting."""

from __future__ import annotations

import argparse

from bayeshopf import fit_folder
from bayeshopf.cli._checks import check_ci
from bayeshopf.cli._options import add_ci, add_fit_dir, add_format, add_recordings
from bayeshopf.errors import DataError
from bayeshopf.plotting._units import LENGTHS

DESCRIPTION = ("Draw the figures of a folder written by 'bayeshopf fit' or 'bayeshopf demo' "
               "again into DIR/figures (replacing files of the same name once all are drawn), "
               "without refitting: the diagram, the predictive check and the frequency; with "
               "--recordings also the phase portraits and time series.")


def add_arguments(pl: argparse.ArgumentParser) -> None:
    """The options of ``plot``."""
    add_fit_dir(pl)
    add_format(pl, "file")
    add_recordings(pl, "the phase portraits and time series")
    add_ci(pl)
    pl.add_argument("--length-unit", default="auto",
                    help="unit of lengths: m, cm, mm, µm, or auto (default: the one in which "
                    "the largest amplitude reads 1-1000)")
    pl.add_argument("--offsets", choices=("remove", "keep"), default="remove",
                    help="remove (default) or keep each recording's mean in the phase "
                    "portraits and time series")
    pl.add_argument("--dpi", type=int, default=300, help="resolution of png files (default 300)")


def run(args) -> int:
    """Run ``bayeshopf plot``; returns the exit code."""
    check_ci(args.ci)
    if args.length_unit not in ("auto", *LENGTHS):
        raise DataError(f"--length-unit {args.length_unit}: one of auto, "
                        f"{', '.join(LENGTHS)} expected; found {args.length_unit!r}")
    saved = fit_folder.load_fit(args.fit_dir)
    paths = saved.plot(recordings=args.recordings, fmt=args.format, ci=args.ci,
                       length_unit=args.length_unit, offsets=args.offsets, dpi=args.dpi)
    left = "" if args.recordings else " (phase portraits and time series need --recordings)"
    print(f"wrote {', '.join(p.name for p in paths)} into {paths[0].parent}{left}")
    return 0
