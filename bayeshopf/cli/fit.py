"""``bayeshopf fit``: fit a folder of recordings or a published data set, and save the fit."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

from bayeshopf.cli._hybrid import add_fit_options, fit_groups, run_hybrid
from bayeshopf.cli._schema import dumps
from bayeshopf.cli._summary import print_table, summary_json
from bayeshopf.cli.download import DATASETS
from bayeshopf.data import load_recordings
from bayeshopf.data.datasets import flutter_cbc
from bayeshopf.data.io import dropped_report
from bayeshopf.data.screening import screened
from bayeshopf.errors import DataError, FitError

DESCRIPTION = ("Fit a folder of CBC .mat files or an interchange folder (manifest.csv + one "
               "CSV per recording), or a published data set (--dataset). Writes "
               "DIR/summary.json, DIR/posterior.nc, DIR/model.json and DIR/figures/*.png.")

#: ``--criticality`` → the normal form's name.
CRITICALITY = {"sub": "subcritical", "super": "supercritical", "auto": "auto"}


def add_arguments(f: argparse.ArgumentParser) -> None:
    """The options of ``fit``, in the sections of its ``--help``."""
    data = f.add_argument_group("data", "what is fitted: a folder DATA or --dataset")
    data.add_argument("data", nargs="?", default=None,
                      help="folder of .mat files, or interchange folder (or use --dataset)")
    data.add_argument("--dataset", choices=DATASETS, default=None,
                      help="a published data set instead of DATA: flutter_cbc, the wind-tunnel "
                      "rig's 7 CBC recordings ($BAYESHOPF_FLUTTER_CBC if set, else downloaded "
                      "once, 11 MB, SHA-256 checked)")
    data.add_argument("--rig", metavar="FILE", default=None,
                      help="rig description (TOML or JSON) of DATA's .mat files: rows, scales, "
                      "time, mu, what a sensor writes without a reading (default: "
                      "DATA/rig.toml if present, else the built-in flutter_cbc rig)")
    data.add_argument("--planar", nargs=2, metavar=("Z1", "Z2"), default=None,
                      help="channels of the planar pair (default: the first two)")
    data.add_argument("--keep-unconverged", action="store_true",
                      help="keep the CBC recordings on which the controller did not converge "
                      "(where the rig description names the convergence fields; left out by "
                      "default: such a recording is not an orbit of the uncontrolled system)")
    ctl = data.add_mutually_exclusive_group()
    ctl.add_argument("--control", metavar="CHANNEL", default=None,
                     help="the channel holding the CBC controller's output (actuator command): "
                     "its residual fundamental becomes a measured input of the model (default: "
                     "the rig description's 'control'; for interchange folders, a column name)")
    ctl.add_argument("--no-control", action="store_true",
                     help="leave out the orbits' response to the CBC controller's residual "
                     "fundamental (in the model by default where the rig description names a "
                     "control channel, as the built-in flutter_cbc rig does)")

    groups = fit_groups(f)
    groups.model.add_argument("--criticality", choices=tuple(CRITICALITY), default="sub",
                              help="normal form: subcritical (default), supercritical, or "
                              "auto (decided from the data)")
    groups.model.add_argument("--exact-loo", action="store_true",
                              help="with --criticality auto: refit each model without every "
                              "recording whose PSIS Pareto k exceeds 0.7 and use its exact "
                              "leave-one-out density (one fit per refit)")
    groups.inference.add_argument("--leave-one-out", action="store_true",
                                  help="also refit without each recording in turn and predict "
                                  "it (one fit per recording): summary.json's leave_one_out "
                                  "and a warning when too few held-out amplitudes lie inside "
                                  "their 90%% predictive bands")
    groups.outputs.add_argument("--out", required=True,
                                help="output folder (refused if not empty)")
    add_fit_options(groups)


def recordings(args):
    """``fit``'s recordings (DATA or ``--dataset``), with ``--control`` applied.

    Raises:
        DataError: Naming DATA, ``--dataset``, ``--rig`` or ``--control``.
    """
    rs, lines = screened(_read(args), args.keep_unconverged)
    for line in lines:
        print(f"data: {line}", file=sys.stderr)
    if args.control is None:
        return rs
    try:
        return replace(rs, control=args.control)
    except DataError as exc:
        raise DataError(f"--control: {exc}") from None


def _read(args):
    """The folder DATA or the published data set ``--dataset``."""
    if (args.data is None) == (args.dataset is None):
        found = "both" if args.data is not None else "neither"
        raise DataError(f"DATA: a folder of recordings or --dataset {'|'.join(DATASETS)} "
                        f"expected (one of the two); found {found}")
    planar = tuple(args.planar) if args.planar else None
    if args.data is not None:
        rs = load_recordings(args.data, planar=planar, rig=args.rig)
        for line in [] if args.quiet else dropped_report(rs):
            print(f"data: {line}", file=sys.stderr)
        return rs
    if args.rig is not None:
        raise DataError(f"--rig: describes the .mat files of DATA; --dataset {args.dataset} "
                        "has its own description (drop --rig)")
    if not args.quiet:
        print(f"data: {args.dataset} (downloaded once into the user cache unless "
              "$BAYESHOPF_FLUTTER_CBC names a folder)", file=sys.stderr)
    rs = flutter_cbc(download=True)
    if planar is None:
        return rs
    return replace(rs, planar=planar, control=None if rs.control in planar else rs.control)


def run(args) -> int:
    """Run ``bayeshopf fit``; returns the exit code."""
    crit = CRITICALITY[args.criticality]
    if args.exact_loo and crit != "auto":
        raise FitError(f"--exact-loo compares the two normal forms and needs --criticality "
                       f"auto; got --criticality {args.criticality}")
    summary = run_hybrid(recordings(args), crit, args, args.out)
    if args.json:
        print(dumps(summary_json("fit", summary, args.out)))
        return 0
    print_table(summary)
    print(f"\nwrote {args.out}/summary.json, posterior.nc, model.json and figures/ "
          f"in {summary['total_s']:.0f} s")
    return 0
