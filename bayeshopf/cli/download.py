"""``bayeshopf download``: fetch a published data set and print its folder."""

from __future__ import annotations

import argparse

from bayeshopf.data.datasets import download_flutter_cbc

#: Published data sets this command fetches.
DATASETS = ("flutter_cbc",)

DESCRIPTION = ("Download a published data set with its pinned SHA-256 hashes and print the "
               "folder that holds it (files already there are not fetched again). flutter_cbc: "
               "the wind-tunnel rig's 7 CBC recordings (11 MB) from "
               "github.com/Kyounghyunlee/ML_Hopf, or from $BAYESHOPF_FLUTTER_CBC_URL.")


def add_arguments(g: argparse.ArgumentParser) -> None:
    """The options of ``download``."""
    g.add_argument("dataset", choices=DATASETS)
    g.add_argument("--to", default=None,
                   help="folder to download into (default: the user cache, "
                   "$BAYESHOPF_DATA_DIR/flutter_cbc if set)")


def run(args) -> int:
    """Run ``bayeshopf download``; returns the exit code."""
    print(download_flutter_cbc(args.to))
    return 0
