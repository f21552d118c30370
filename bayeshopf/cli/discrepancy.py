"""``bayeshopf discrepancy``: where a simulator and the recordings disagree, and what it lacks.

Writes ``report.json``, ``report.md`` and ``figures/`` into ``--out``,
atomically (a temporary sibling folder renamed into place). Bad input is
reported by :func:`bayeshopf.cli.main.main` as one line with exit code 2. The
plotting code (Matplotlib) is imported only where the figures are drawn.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

from bayeshopf import discrepancy
from bayeshopf._atomic import new_folder
from bayeshopf._format import format_interval, format_values
from bayeshopf.cli._checks import check_out
from bayeshopf.data import load_recordings
from bayeshopf.discrepancy.analysis import stage_rows
from bayeshopf.errors import OutputError
from bayeshopf.fit_folder import check_output_folder, json_ready
from bayeshopf.simulators import get_system

DESCRIPTION = ("Compare LCO recordings with a simulator's periodic orbits, locate the "
               "mismatch, give every candidate missing term (stiffness, freeplay, friction, "
               "damping nonlinearities per coordinate) a posterior probability and a "
               "coefficient with a 90% interval, add the most probable one and report the fit "
               "before and after, with a one-sentence verdict. A simulator that declares "
               "uncertain parameters (flutter3dof) has them calibrated first, as nuisance "
               "parameters: the verdict then tells 'the parameters are off' from 'a term is "
               "missing', and the fit is shown nominal, calibrated and calibrated with the "
               "term.")


def add_arguments(s: argparse.ArgumentParser) -> None:
    """The options of ``discrepancy``."""
    s.add_argument("data", help="recordings: an interchange folder or CBC .mat files")
    s.add_argument("--simulator", required=True,
                   help="flutter3dof, vanderpol, or package.module:attr of your own System")
    s.add_argument("--out", required=True, help="output folder (refused if not empty)")
    s.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    s.add_argument("--no-hybrid", action="store_true",
                   help="skip the Bayesian hybrid fit of the recordings (saves minutes)")
    s.add_argument("--no-calibration", action="store_true",
                   help="keep every simulator parameter nominal and fit single terms only "
                   "(the default calibrates the parameters the simulator declares uncertain)")
    s.add_argument("--no-figures", action="store_true", help="write no figures")
    s.add_argument("--force", action="store_true", help="replace a non-empty output folder")
    s.add_argument("--quiet", action="store_true", help="no progress bars")


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def write_report(report, out: str | os.PathLike[str], *, force: bool = False,
                 figures: bool = True) -> Path:
    """Write ``report.json``, ``report.md`` and ``figures/`` into ``out`` atomically.

    Raises:
        OutputError: When ``out`` is a file, or not empty and ``force`` is false, or
            cannot be written.
    """
    out = check_output_folder(out, force)
    try:
        with new_folder(out) as tmp:
            data = json.loads(json.dumps(report.to_json(), default=_json_default))
            (tmp / "report.json").write_text(
                json.dumps(json_ready(data), indent=2, allow_nan=False) + "\n",
                encoding="utf-8")
            (tmp / "report.md").write_text(report.to_markdown(), encoding="utf-8")
            if figures:
                from bayeshopf.plotting.discrepancy import plot_discrepancy

                plot_discrepancy(report, tmp / "figures")
    except OSError as exc:
        raise OutputError(f"{out}: cannot be written ({type(exc).__name__}: {exc})") from exc
    return out


def run(args) -> int:
    """Run ``bayeshopf discrepancy``; errors propagate as ``BayesHopfError``."""
    check_out(args.out, args.force, "replace it")
    system = get_system(args.simulator)
    rs = load_recordings(args.data)
    report = discrepancy.analyse(rs, system, seed=args.seed, hybrid=not args.no_hybrid,
                     progress=not args.quiet, calibrate=False if args.no_calibration else None)
    write_report(report, args.out, force=args.force, figures=not args.no_figures)
    d = report.to_json()
    print("\n".join(_calibrated_lines(d) if "calibration" in d else _single_term_lines(d)))
    print(f"wrote {args.out}/report.json, report.md" + ("" if args.no_figures else
                                                         " and figures/")
          + f" in {d['runtime_s']:.0f} s")
    return 0


def _coefficient(co: dict, pad: int = 11) -> str:
    """A term's coefficient as ``median [lo, hi] units`` (digits that show the width)."""
    m, a, b = format_interval(co["median"], *co["ci90"])
    return f"{m:>{pad}s} [{a:>{pad}s}, {b:>{pad}s}] {co['units']}"


def _single_term_lines(d: dict) -> list[str]:
    """What the command prints without calibration: the verdict and the best terms."""
    lines = [d["verdict"]["sentence"],
             f"{'model':30s} {'probability':>11s} {'median':>11s} {'90% interval':>26s}"]
    for c in d["candidates"][:5]:
        co = c["coefficient"]
        lines.append(f"{c['name']:30s} {c['probability']:11.3g}"
                     + ("" if co is None else f" {_coefficient(co)}"))
    return lines


def _calibrated_lines(d: dict) -> list[str]:
    """What the command prints with calibration: verdict, parameters, models, fit, remainder."""
    v = d["verdict"]
    lines = [v["sentence"], "",
             f"uncertain parameters ({d['parameters']['model']}):",
             f"{'parameter':10s} {'nominal':>11s} {'median':>11s}   {'90% interval':26s} "
             f"{'shift':>7s}  off"]
    for p in d["parameters"]["table"]:
        lo, hi = p["ci90"]
        nominal, m, a, b = format_values([p["nominal"], p["median"], lo, hi], hi - lo)
        lines.append(f"{p['name']:10s} {nominal:>11s} {m:>11s}   "
                     f"{'[' + a + ', ' + b + ']':26s} "
                     f"{100 * p['shift']:+6.2f}%  {'yes' if p['off'] else ''}")
    lines += ["", f"{'model':30s} {'probability':>11s} {'median':>11s} {'90% interval':>26s}"]
    for m in d["models"][:7]:
        co = m["coefficient"]
        if m.get("coefficients"):                                 # a pair of terms
            lines.append(f"{m['name']:30s} {m['probability']:11.3g} " + "; ".join(
                f"{c['name']} {_coefficient(c, 0)}" for c in m["coefficients"]))
        elif co is None:
            lines.append(f"{m['label']:30s} {m['probability']:11.3g}")
        else:
            lines.append(f"{m['name']:30s} {m['probability']:11.3g} {_coefficient(co)}")
    titles, rows = stage_rows(d)
    keep = ("amplitude error", "Hopf point", "fold", "chi²")
    rows = [(q, cells) for q, cells in rows if q.startswith(keep)]
    w = [max(len(t), *(len(cells[j]) for _, cells in rows)) + 3 for j, t in enumerate(titles)]
    lines += ["", f"{'fit':22s}" + "".join(f"{t:>{w[j]}s}" for j, t in enumerate(titles))]
    lines += [f"{q:22s}" + "".join(f"{c:>{w[j]}s}" for j, c in enumerate(cells))
              for q, cells in rows]
    lines += ["", d["mismatch"]["after"]["sentence"]]
    return lines
