"""``bayeshopf next``: where to measure next, from a saved fit (:mod:`bayeshopf.design`).

The plotting code (Matplotlib) is imported only where the figure is drawn, so
that ``next --no-figure`` does not load it.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from bayeshopf import fit_folder
from bayeshopf._format import format_interval, format_number
from bayeshopf.cli import _schema
from bayeshopf.cli._checks import check_ci, check_share
from bayeshopf.cli._options import add_ci, add_fit_dir, add_format
from bayeshopf.design import Candidate, DesignResult, next_measurements, parse_candidates
from bayeshopf.errors import DataError, FitError

DESCRIPTION = ("From a folder written by 'bayeshopf fit' (no refit), rank candidate "
               "(airspeed, branch) measurements by the expected shrinkage of the target's "
               "interval: the posterior reweighted by each simulated measurement "
               "(bayeshopf.design). Prints a table and writes DIR/figures/next_<target>.png "
               "(gain against μ over the diagram).")


def add_arguments(s: argparse.ArgumentParser) -> None:
    """The options of ``next``, in the sections of its ``--help``."""
    add_fit_dir(s)
    s.add_argument("--target", choices=("fold", "hopf", "diagram"), default="fold",
                   help="what to learn: the fold (default), the Hopf point, or the diagram")
    s.add_argument("--seed", type=int, default=0, help="seed of the simulated measurements")

    where = s.add_argument_group("candidates", "where a measurement may be made, and where not")
    where.add_argument("--candidates", default=None, metavar="MU_MIN:MU_MAX:STEP",
                       help="candidate μ grid (default: 41 points from the fold's band to "
                       "beyond the data)")
    where.add_argument("--branch", choices=("stable", "unstable", "both"), default="both")
    where.add_argument("--min-p-exists", type=float, default=0.9, metavar="P",
                       help="never recommend where the branch exists in fewer than this share "
                       "of posterior draws (default 0.9); such candidates are listed as "
                       "skipped")
    where.add_argument("--min-amplitude", type=float, default=0.0, metavar="A",
                       help="never recommend where the predicted amplitude (peak-to-peak, in "
                       "the fit's amplitude unit) is below A (default 0: no limit)")
    where.add_argument("--resolution", type=float, default=0.0, metavar="DMU",
                       help="resolution in μ (the fit's μ unit): candidates closer than DMU "
                       "merge (the best is kept) and a fold or Hopf gain below DMU is flagged "
                       "as below the tunnel's resolution (default 0: none)")

    shown = s.add_argument_group("outputs", "what is printed and drawn")
    shown.add_argument("--n", type=int, default=3, help="how many to recommend (default 3)")
    shown.add_argument("--all", action="store_true",
                       help="print every candidate, not only the best")
    add_ci(shown, "the intervals")
    shown.add_argument("--json", action="store_true",
                       help="print the whole result as JSON (schema of bayeshopf.cli._schema)")
    shown.add_argument("--no-figure", action="store_true", help="skip the figure")
    add_format(shown)


def run(args) -> int:
    """Run ``bayeshopf next``; returns the exit code."""
    check_ci(args.ci)
    if args.n < 1:
        raise DataError(f"--n {args.n}: at least 1 expected")
    check_share(args.min_p_exists, "--min-p-exists")
    for flag, v in (("--min-amplitude", args.min_amplitude), ("--resolution", args.resolution)):
        if not (math.isfinite(v) and v >= 0):
            raise DataError(f"{flag} {v:g}: a finite value of at least 0 expected")
    candidates = None
    if args.candidates is not None:
        try:
            candidates = parse_candidates(args.candidates)
        except ValueError as e:
            raise DataError(f"--candidates: {e}") from None
    saved = fit_folder.load_fit(args.fit_dir)
    print(f"next: reading the fit in {args.fit_dir} and ranking candidates "
          f"(target {args.target})", file=sys.stderr)
    fit = saved.posterior
    if args.target == "fold" and "mu_fold" not in fit.samples:
        raise FitError("--target fold: a subcritical fit expected (this one has no fold); "
                       "use --target hopf or --target diagram")
    result = next_measurements(fit, target=args.target, candidates=candidates,
                               branch=args.branch, n=args.n, ci=args.ci,
                               min_p_exists=args.min_p_exists, min_amplitude=args.min_amplitude,
                               resolution=args.resolution, seed=args.seed)
    if args.json:
        print(_schema.dumps(result_json(result, args.fit_dir)))
    else:
        _print(result, args.all)
    if not args.no_figure:
        from bayeshopf.plotting._io import save_figure
        from bayeshopf.plotting.design import plot_design

        path = Path(args.fit_dir) / "figures" / f"next_{args.target}.{args.format}"
        save_figure(plot_design(result, fit), path)
        print(f"wrote {path}", file=sys.stderr)
    return 0


def _amplitude(c: Candidate, ci: float) -> dict | None:
    """A candidate's predicted amplitude as a schema interval (``None`` when skipped)."""
    m, lo, hi = c.amplitude
    if not all(math.isfinite(x) for x in (m, lo, hi)):
        return None
    return _schema.interval_json(m, lo, hi, ci)


def result_json(result: DesignResult, fit_dir) -> dict:
    """The ranking in the command line's JSON schema (:mod:`bayeshopf.cli._schema`)."""
    rank = {(c.mu, c.branch): i + 1 for i, c in enumerate(result.recommended)}

    def row(c: Candidate) -> dict:
        return {"rank": rank.get((c.mu, c.branch)), "mu": c.mu, "branch": c.branch,
                "p_exists": c.p_exists, "amplitude": _amplitude(c, result.ci),
                "width_after": c.width_after, "gain": c.gain, "gain_mcse": c.gain_mcse,
                "ess": c.ess, "note": c.note or None, "skipped": c.skipped or None}

    return _schema.document(
        "next", ci=result.ci, units={"mu": result.mu_units,
                                     "amplitude": result.amplitude_units, "frequency": "Hz"},
        fit_dir=str(fit_dir), target=result.target, width_now=result.width_now,
        min_p_exists=result.min_p_exists, min_amplitude=result.min_amplitude,
        resolution=result.resolution,
        recommended=[row(c) for c in result.recommended],
        candidates=[row(c) for c in result.candidates])


def _print(result, every: bool) -> None:
    mu_u = f" [{result.mu_units}]" if result.mu_units else ""
    amp_u = f" [{result.amplitude_units}]" if result.amplitude_units else ""
    what = {"fold": "fold", "hopf": "Hopf point", "diagram": "diagram band (mean)"}[result.target]
    print(f"{what}: {100 * result.ci:.0f}% width now {format_number(result.width_now)}"
          f"{amp_u if result.target == 'diagram' else mu_u}")
    rows = result.ranked() if every else result.recommended
    print(f"{'rank':>4} {'mu' + mu_u:>12} {'branch':>9} {'P(exists)':>9} "
          f"{'amplitude' + amp_u:>14} {'band':>22} {'width after':>11} {'gain':>9} "
          f"{'± MC se':>9}")
    rank = {(c.mu, c.branch): i + 1 for i, c in enumerate(result.recommended)}
    for c in rows:
        r = rank.get((c.mu, c.branch))
        m, lo, hi = format_interval(*c.amplitude)
        gain = "no gain" if c.note.startswith("no gain") else format_number(c.gain)
        notes = "; ".join(x for x in ((f"skipped: {c.skipped}" if c.skipped else ""),
                                      "" if c.note.startswith("no gain") else c.note) if x)
        print(f"{r if r else '':>4} {c.mu:>12g} {c.branch:>9} {c.p_exists:>9.2f} "
              f"{m:>14} {'[' + lo + ', ' + hi + ']':>22} {format_number(c.width_after):>11} "
              f"{gain:>9} {format_number(c.gain_mcse):>9}" + (f"  {notes}" if notes else ""))
    if not every:
        parts = []
        for b in ("stable", "unstable"):
            rows_b = [c for c in result.candidates if c.branch == b]
            runs, start = [], None
            for i, c in enumerate(rows_b + [None]):
                if c is not None and c.skipped:
                    start = i if start is None else start
                elif start is not None:
                    lo, hi = rows_b[start].mu, rows_b[i - 1].mu
                    runs.append(f"{lo:.4g}" if lo == hi else f"{lo:.4g}–{hi:.4g}")
                    start = None
            if runs:
                parts.append(f"{b} at μ {', '.join(runs)}")
        if parts:
            print(f"skipped (the branch may not exist there, or its orbit is below "
                  f"--min-amplitude): {'; '.join(parts)}")
    low = [c for c in result.recommended if c.ess < 20]
    if low:
        print(f"warning: next: the importance weights of {len(low)} recommended candidate(s) "
              "rest on fewer than 20 effective draws; refit after measuring")
