"""``bayeshopf report``: one self-contained HTML page of a saved fit, to mail or archive."""

from __future__ import annotations

import argparse
from pathlib import Path

from bayeshopf import fit_folder, hybrid
from bayeshopf.cli._checks import check_ci
from bayeshopf.cli._options import add_ci, add_fit_dir, add_recordings
from bayeshopf.lab_report import write_lab_report

DESCRIPTION = ("Write one self-contained HTML page of a folder written by 'bayeshopf fit' or "
               "'bayeshopf demo': the figures (as SVG), the Hopf and fold points with their "
               "intervals, every recording's measured and predicted amplitude, the checks and "
               "warnings, the settings, seed and versions. It loads nothing from anywhere, so "
               "it can be mailed or archived as it is.")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``report``."""
    add_fit_dir(p)
    p.add_argument("--out", default=None,
                   help="the HTML file to write (default FIT_DIR/report.html; replaced whole)")
    add_recordings(p, "the time-series figure")
    add_ci(p)


def run(args) -> int:
    """Run ``bayeshopf report``; returns the exit code."""
    check_ci(args.ci)
    fit = hybrid.load_fit(args.fit_dir)
    rs = None
    if args.recordings is not None:
        rs = fit_folder.recordings_in_fit_order(fit_folder.load_fit(args.fit_dir), args.recordings)
    out = Path(args.out) if args.out else Path(args.fit_dir) / "report.html"
    write_lab_report(fit, out, rs, ci=args.ci)
    print(f"wrote {out}")
    return 0
