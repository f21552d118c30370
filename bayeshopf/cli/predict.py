"""``bayeshopf predict``: amplitude and frequency at μ from a saved fit.

One μ is printed as a sentence, several as a table; ``--csv`` and ``--json``
(:mod:`bayeshopf.cli._schema`) print one row or one entry per μ. Where the
branch exists in fewer than ``--min-p-exists`` of the posterior draws there is
no value: ``—`` in the sentence and the table, empty cells in CSV, ``null`` in
JSON (a median and interval of the few draws that have the orbit would read as
an orbit that is there).
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import dataclass

import numpy as np

from bayeshopf import fit_folder
from bayeshopf._format import NO_VALUE, format_interval, format_number
from bayeshopf.cli import _schema
from bayeshopf.cli._checks import check_ci, check_share
from bayeshopf.cli._options import add_ci, add_fit_dir
from bayeshopf.diagnostics.summaries import Interval
from bayeshopf.errors import DataError

DESCRIPTION = ("Amplitude and frequency (median and credible interval) at one or several μ on "
               "a branch, from a folder written by 'bayeshopf fit' or 'bayeshopf demo'. Where "
               "the branch exists in fewer than --min-p-exists of the posterior draws, no "
               "value is given ('—' in the table, empty in CSV, null in JSON).")

#: Default share of posterior draws in which the branch must exist for a value.
MIN_P_EXISTS = 0.5


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``predict``."""
    add_fit_dir(p)
    p.add_argument("--mu", nargs="+", action="extend", required=True, metavar="MU",
                   help="values of the bifurcation parameter, or START:STOP:STEP "
                   "(STOP included), e.g. --mu 15 15.5 16 or --mu 14:17:0.5; repeated "
                   "--mu add values")
    add_ci(p, "the intervals")
    p.add_argument("--branch", choices=("stable", "unstable"), default="stable")
    p.add_argument("--min-p-exists", type=float, default=MIN_P_EXISTS, metavar="P",
                   help="share of posterior draws in which the branch must exist at μ for a "
                   f"value to be given (default {MIN_P_EXISTS:g})")
    p.add_argument("--predictive", action="store_true",
                   help="band of a new measurement instead of the curve (adds the model "
                   "error, which grows away from the recordings, and the measurement error)")
    p.add_argument("--json", action="store_true",
                   help="print JSON: one object with a 'predictions' list, one entry per μ")
    p.add_argument("--csv", action="store_true", help="print CSV, one row per μ")


@dataclass(frozen=True)
class Prediction:
    """``predict`` at one μ: ``None`` where the branch exists in too few draws."""

    mu: float
    p_exists: float
    amplitude: Interval | None
    frequency: Interval | None


def mu_values(tokens: list[str]) -> list[float]:
    """``--mu`` values in the order given: numbers and ``START:STOP:STEP`` (STOP included).

    Raises:
        DataError: Naming the ``--mu`` token that is neither.
    """
    out: list[float] = []
    for tok in tokens:
        parts = tok.split(":")
        try:
            nums = [float(x) for x in parts]
        except ValueError:
            nums = []
        if len(parts) == 1 and nums:
            out.append(nums[0])
        elif len(nums) == 3 and nums[2] > 0 and nums[1] >= nums[0]:
            n = int(np.floor((nums[1] - nums[0]) / nums[2] + 1e-9)) + 1
            out.extend(float(v) for v in np.round(nums[0] + nums[2] * np.arange(n), 12))
        else:
            raise DataError(f"--mu {tok}: a number or START:STOP:STEP with STEP > 0 and "
                            f"STOP >= START expected; found {tok!r}")
    return out


def predict_at(saved, mu: float, args) -> Prediction:
    """Amplitude and frequency at ``mu``, or ``None`` below ``--min-p-exists``."""
    p = saved.p_exists(mu, args.branch)
    if p == 0 or p < args.min_p_exists:
        return Prediction(mu, p, None, None)
    amp = saved.predict(mu, args.branch, predictive=args.predictive, ci=args.ci)
    freq = saved.frequency(mu, args.branch, args.predictive, ci=args.ci)
    return Prediction(mu, p, amp, freq)


def _percent(p: float) -> str:
    """A share of draws in percent, with the digits a small share needs."""
    return f"{100 * p:.0f}%" if p == 0 or p >= 0.01 else f"{100 * p:.1g}%"


def run(args) -> int:
    """Run ``bayeshopf predict``; returns the exit code."""
    check_ci(args.ci)
    check_share(args.min_p_exists, "--min-p-exists")
    if args.json and args.csv:
        raise DataError("--json and --csv: one output format expected; found both")
    mus = mu_values(args.mu)
    saved = fit_folder.load_fit(args.fit_dir)
    rows = [predict_at(saved, mu, args) for mu in mus]
    if all(r.p_exists == 0 for r in rows):
        fold = saved.summary.get("mu_fold")
        raise DataError(f"--mu {' '.join(args.mu)}: the {args.branch} branch does not exist "
                        "at any of these μ in any posterior draw (Hopf point μ0 ≈ "
                        f"{format_number(saved.summary['mu0']['median'])}"
                        + (f", fold ≈ {format_number(fold['median'])}" if fold else "") + ")")
    units = {"mu": saved.summary.get("mu_units", ""),
             "amplitude": saved.summary.get("amplitude_units", ""), "frequency": "Hz"}
    if args.json:
        print(_schema.dumps(_json(rows, args, units)))
    elif args.csv:
        _csv(rows, args, units)
    elif len(rows) == 1:
        _sentence(rows[0], args, units)
    else:
        _table(rows, args, units)
    return 0


def _json(rows: list[Prediction], args, units: dict) -> dict:
    """The predictions in the command line's JSON schema."""
    return _schema.document(
        "predict", ci=args.ci, units=units, fit_dir=str(args.fit_dir), branch=args.branch,
        predictive=args.predictive, min_p_exists=args.min_p_exists,
        predictions=[{"mu": r.mu, "p_exists": r.p_exists, "exists": r.amplitude is not None,
                      "amplitude": _schema.from_interval(r.amplitude),
                      "frequency": _schema.from_interval(r.frequency)} for r in rows])


def _csv(rows: list[Prediction], args, units: dict) -> None:
    """One row per μ; empty cells where there is no value."""
    u = units["amplitude"]
    w = csv.writer(sys.stdout, lineterminator="\n")
    w.writerow(["mu", "branch", "ci", "p_exists", f"amplitude_median [{u}]",
                f"amplitude_lo [{u}]", f"amplitude_hi [{u}]",
                "frequency_median [Hz]", "frequency_lo [Hz]", "frequency_hi [Hz]"])
    for r in rows:
        a, f = r.amplitude, r.frequency
        w.writerow([repr(r.mu), args.branch, args.ci, r.p_exists,
                    *(("", "", "") if a is None else (a.median, a.lo, a.hi)),
                    *(("", "", "") if f is None else (f.median, f.lo, f.hi))])


def _sentence(r: Prediction, args, units: dict) -> None:
    """One μ as a sentence."""
    u, level = units["amplitude"], f"{100 * args.ci:g}%"
    where = f"{args.branch} LCO at μ = {r.mu:g} {units['mu']}".rstrip()
    exists = f"branch exists in {_percent(r.p_exists)} of posterior draws"
    if r.amplitude is None:
        print(f"{where}: amplitude {NO_VALUE} ({exists}, fewer than the "
              f"{_percent(args.min_p_exists)} asked for by --min-p-exists)")
        return
    m, a, b = format_interval(r.amplitude.median, r.amplitude.lo, r.amplitude.hi)
    print(f"{where}: amplitude {m} {u}, {level} interval [{a}, {b}] {u} ({exists})")
    if r.frequency is not None:
        m, a, b = format_interval(r.frequency.median, r.frequency.lo, r.frequency.hi)
        print(f"frequency {m} Hz, {level} interval [{a}, {b}] Hz")


def _cells(iv: Interval | None, width: int) -> str:
    """A median and its interval as table cells, or :data:`NO_VALUE`."""
    if iv is None:
        return f"{NO_VALUE:>{width}s} {'':24s}"
    m, a, b = format_interval(iv.median, iv.lo, iv.hi)
    return f"{m:>{width}s} {'[' + a + ', ' + b + ']':24s}"


def _table(rows: list[Prediction], args, units: dict) -> None:
    """Several μ as a table: a header and one line per μ."""
    level = f"{100 * args.ci:g}%"
    what = "a new measurement's" if args.predictive else "the curve's"
    print(f"{args.branch} branch, {what} median and {level} interval")
    print(f"{'mu [' + units['mu'] + ']':>10s} {'P(exists)':>9s} "
          f"{'amplitude [' + units['amplitude'] + ']':>14s} {level + ' interval':24s} "
          f"{'frequency [Hz]':>14s} {level + ' interval':24s}".rstrip())
    for r in rows:
        print(f"{r.mu:10g} {r.p_exists:9.2f} {_cells(r.amplitude, 14)} "
              f"{_cells(r.frequency, 14)}".rstrip())
