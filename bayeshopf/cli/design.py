"""``bayeshopf next``: where to measure next, from a saved fit (:mod:`bayeshopf.design`)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path


def add_parser(sub) -> argparse.ArgumentParser:
    """Add the ``next`` subcommand to the subparsers ``sub``."""
    s = sub.add_parser(
        "next", help="rank the next measurements by how much they shrink the fold, Hopf or "
        "diagram intervals",
        description="From a folder written by 'bayeshopf fit' (no refit), rank candidate "
        "(airspeed, branch) measurements by the expected shrinkage of the target's interval: "
        "the posterior reweighted by each simulated measurement (bayeshopf.design). Prints a "
        "table and writes DIR/figures/next_<target>.png (gain against μ over the diagram).")
    s.add_argument("fit_dir", help="folder written by 'bayeshopf fit' or 'bayeshopf demo'")
    s.add_argument("--target", choices=("fold", "hopf", "diagram"), default="fold",
                   help="what to learn: the fold (default), the Hopf point, or the diagram")
    s.add_argument("--candidates", default=None, metavar="MU_MIN:MU_MAX:STEP",
                   help="candidate μ grid (default: 41 points from the fold's band to beyond "
                   "the data)")
    s.add_argument("--branch", choices=("stable", "unstable", "both"), default="both")
    s.add_argument("--n", type=int, default=3, help="how many to recommend (default 3)")
    s.add_argument("--ci", type=float, default=0.9, help="interval mass (default 0.9)")
    s.add_argument("--seed", type=int, default=0, help="seed of the simulated measurements")
    s.add_argument("--json", action="store_true", help="print the whole result as JSON")
    s.add_argument("--all", action="store_true", help="print every candidate, not only the best")
    s.add_argument("--no-figure", action="store_true", help="skip the figure")
    s.add_argument("--format", choices=("png", "pdf", "svg"), default="png",
                   help="figure format (default png)")
    return s


def _fmt(x: float, digits: int = 4) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def run(args) -> int:
    """Run ``bayeshopf next``; returns the exit code."""
    from bayeshopf.design import next_measurements, parse_candidates
    from bayeshopf.errors import DataError
    from bayeshopf.report import load_fit

    if not 0 < args.ci < 1:
        raise DataError(f"--ci {args.ci:g}: a probability mass between 0 and 1 expected (e.g. 0.9)")
    if args.n < 1:
        raise DataError(f"--n {args.n}: at least 1 expected")
    candidates = None
    if args.candidates is not None:
        try:
            candidates = parse_candidates(args.candidates)
        except ValueError as e:
            raise DataError(f"--candidates: {e}") from None
    saved = load_fit(args.fit_dir)
    print(f"next: reading the fit in {args.fit_dir} and ranking candidates "
          f"(target {args.target})", file=sys.stderr)
    fit = saved.posterior
    result = next_measurements(fit, target=args.target, candidates=candidates,
                               branch=args.branch, n=args.n, ci=args.ci, seed=args.seed)
    if args.json:
        print(json.dumps(result.to_json(), indent=1))
    else:
        _print(result, args.all)
    if not args.no_figure:
        from bayeshopf.plotting._io import save_figure
        from bayeshopf.plotting.design import plot_design

        path = Path(args.fit_dir) / "figures" / f"next_{args.target}.{args.format}"
        save_figure(plot_design(result, fit), path)
        print(f"wrote {path}", file=sys.stderr)
    return 0


def _print(result, every: bool) -> None:
    mu_u = f" [{result.mu_units}]" if result.mu_units else ""
    amp_u = f" [{result.amplitude_units}]" if result.amplitude_units else ""
    what = {"fold": "fold", "hopf": "Hopf point", "diagram": "diagram band (mean)"}[result.target]
    print(f"{what}: {100 * result.ci:.0f}% width now {_fmt(result.width_now)}"
          f"{amp_u if result.target == 'diagram' else mu_u}")
    rows = result.candidates if every else result.recommended
    print(f"{'rank':>4} {'mu' + mu_u:>12} {'branch':>9} {'P(exists)':>9} "
          f"{'amplitude' + amp_u:>14} {'band':>22} {'width after':>11} {'gain':>9}")
    rank = {(c.mu, c.branch): i + 1 for i, c in enumerate(result.recommended)}
    for c in rows:
        r = rank.get((c.mu, c.branch))
        band = f"[{_fmt(c.amplitude[1])}, {_fmt(c.amplitude[2])}]"
        print(f"{r if r else '':>4} {c.mu:>12.4g} {c.branch:>9} {c.p_exists:>9.2f} "
              f"{_fmt(c.amplitude[0]):>14} {band:>22} {_fmt(c.width_after):>11} "
              f"{_fmt(c.gain, 3):>9}" + (f"  skipped: {c.skipped}" if c.skipped else ""))
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
            print(f"skipped (the branch may not exist there): {'; '.join(parts)}")
    low = [c for c in result.recommended if c.ess < 20]
    if low:
        print(f"warning: next: the importance weights of {len(low)} recommended candidate(s) "
              "rest on fewer than 20 effective draws; refit after measuring")
