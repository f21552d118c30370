"""``bayeshopf demo``: the 3-DOF aerofoil of the paper's Section 4.2, simulated and fitted blind.

The recordings come from :func:`bayeshopf.simulators.truth.flutter_experiment`
(``--fast``: shorter records and :meth:`CollapsedSettings.fast`); the truth printed
next to the intervals is the simulator's: the Hopf point from the Jacobian,
the fold from the continuation of the periodic orbits, and
``a2 = 2√(μ0 − μ_SN)``, the normal form's a2 with that fold.
"""

from __future__ import annotations

import argparse

from bayeshopf.cli._hybrid import add_fit_options, fit_groups, run_hybrid
from bayeshopf.cli._schema import dumps
from bayeshopf.cli._summary import print_table, summary_json
from bayeshopf.simulators.truth import flutter_experiment

DESCRIPTION = ("Simulate stable and unstable LCO recordings of the paper's 3-DOF aeroelastic "
               "aerofoil in-process (4 + 4 orbits, 1% noise, sensor offsets; no download), fit "
               "the model blind, print the Hopf point, a2 and the fold with 90% intervals next "
               "to the simulator's own values, and write the figures with the true bifurcation "
               "diagram.")


def add_arguments(d: argparse.ArgumentParser) -> None:
    """The options of ``demo``."""
    groups = fit_groups(d)
    groups.outputs.add_argument("--out", default="bayeshopf-demo",
                                help="output folder (default bayeshopf-demo)")
    add_fit_options(groups)


def run(args) -> int:
    """Run ``bayeshopf demo``; returns the exit code."""
    rs, truth = flutter_experiment(seed=args.seed, fast=args.fast)
    summary = run_hybrid(rs, "subcritical", args, args.out, truth=truth,
                         extra={"truth": truth.to_dict()})
    if args.json:
        print(dumps(summary_json("demo", summary, args.out, truth.values())))
        return 0
    print(f"bayeshopf demo: {len(rs)} simulated recordings ({int(rs.is_unstable.sum())} "
          "unstable, by control-based continuation) of the 3-DOF aeroelastic aerofoil "
          f"(Lee, Barton & Renson, Section 4.2), {100 * truth.noise:g}% noise, sensor offsets; "
          "'true' is the simulator's continuation\n")
    print_table(summary, truth.values())
    print(f"\nwrote {args.out}/summary.json, posterior.nc, model.json and figures/ "
          f"in {summary['total_s']:.0f} s")
    return 0
