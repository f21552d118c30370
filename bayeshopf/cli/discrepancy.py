"""``bayeshopf discrepancy``: where a simulator and the recordings disagree, and what it lacks.

Writes ``report.json``, ``report.md`` and ``figures/`` into ``--out``,
atomically (a temporary sibling folder renamed into place). Bad input is
reported by :func:`bayeshopf.cli.main.main` as one line with exit code 2.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import uuid
from pathlib import Path

from bayeshopf._atomic import swap_in


def add_parser(sub) -> argparse.ArgumentParser:
    """Add the ``discrepancy`` subcommand to the subparsers ``sub``."""
    s = sub.add_parser(
        "discrepancy", help="locate and name the physics a simulator lacks",
        description="Compare LCO recordings with a simulator's periodic orbits, locate the "
        "mismatch, give every candidate missing term (stiffness, freeplay, friction, damping "
        "nonlinearities per coordinate) a posterior probability and a coefficient with a 90% "
        "interval, add the most probable one and report the fit before and after, with a "
        "one-sentence verdict. A simulator that declares uncertain parameters (flutter3dof) "
        "has them calibrated first, as nuisance parameters: the verdict then tells 'the "
        "parameters are off' from 'a term is missing', and the fit is shown nominal, "
        "calibrated and calibrated with the term.")
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
    return s


def _json_default(o):
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def write_report(report, out: str | os.PathLike[str], *, force: bool = False,
                 figures: bool = True) -> Path:
    """Write ``report.json``, ``report.md`` and ``figures/`` into ``out`` atomically."""
    from bayeshopf.errors import OutputError
    from bayeshopf.report import check_output_folder, json_ready

    out = check_output_folder(out, force)
    tag = uuid.uuid4().hex[:8]
    tmp = out.parent / f".{out.name}.discrepancy-{tag}"
    try:
        tmp.mkdir(parents=True)
        data = json.loads(json.dumps(report.to_json(), default=_json_default))
        (tmp / "report.json").write_text(json.dumps(json_ready(data), indent=2, allow_nan=False)
                                         + "\n", encoding="utf-8")
        (tmp / "report.md").write_text(report.to_markdown(), encoding="utf-8")
        if figures:
            from bayeshopf.plotting.discrepancy import plot_discrepancy

            plot_discrepancy(report, tmp / "figures")
        swap_in(tmp, out, tag)
    except OSError as exc:
        raise OutputError(f"{out}: cannot be written ({type(exc).__name__}: {exc})") from exc
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return out


def run(args) -> int:
    """Run ``bayeshopf discrepancy``; errors propagate as ``BayesHopfError``."""
    from bayeshopf.data import load_recordings
    from bayeshopf.discrepancy import analyse
    from bayeshopf.report import check_output_folder
    from bayeshopf.simulators import get_system

    check_output_folder(args.out, args.force)
    system = get_system(args.simulator)
    rs = load_recordings(args.data)
    report = analyse(rs, system, seed=args.seed, hybrid=not args.no_hybrid,
                     progress=not args.quiet, calibrate=False if args.no_calibration else None)
    write_report(report, args.out, force=args.force, figures=not args.no_figures)
    d = report.to_json()
    print("\n".join(_calibrated_lines(d) if "calibration" in d else _single_term_lines(d)))
    print(f"wrote {args.out}/report.json, report.md" + ("" if args.no_figures else
                                                         " and figures/")
          + f" in {d['runtime_s']:.0f} s")
    return 0


def _single_term_lines(d: dict) -> list[str]:
    """What the command prints without calibration: the verdict and the best terms."""
    lines = [d["verdict"]["sentence"],
             f"{'model':30s} {'probability':>11s} {'median':>11s} {'90% interval':>26s}"]
    for c in d["candidates"][:5]:
        co = c["coefficient"]
        if co is None:
            lines.append(f"{c['name']:30s} {c['probability']:11.3g}")
        else:
            lines.append(f"{c['name']:30s} {c['probability']:11.3g} {co['median']:11.4g} "
                         f"[{co['ci90'][0]:11.4g}, {co['ci90'][1]:11.4g}] {co['units']}")
    return lines


def _calibrated_lines(d: dict) -> list[str]:
    """What the command prints with calibration: verdict, parameters, models, fit, remainder."""
    from bayeshopf.discrepancy.analysis import stage_rows

    v = d["verdict"]
    lines = [v["sentence"], "",
             f"uncertain parameters ({d['parameters']['model']}):",
             f"{'parameter':10s} {'nominal':>11s} {'median':>11s}   {'90% interval':26s} "
             f"{'shift':>7s}  off"]
    for p in d["parameters"]["table"]:
        iv = f"[{p['ci90'][0]:.5g}, {p['ci90'][1]:.5g}]"
        lines.append(f"{p['name']:10s} {p['nominal']:11.5g} {p['median']:11.5g}   {iv:26s} "
                     f"{100 * p['shift']:+6.2f}%  {'yes' if p['off'] else ''}")
    lines += ["", f"{'model':30s} {'probability':>11s} {'median':>11s} {'90% interval':>26s}"]
    for m in d["models"][:7]:
        co = m["coefficient"]
        if m.get("coefficients"):                                 # a pair of terms
            lines.append(f"{m['name']:30s} {m['probability']:11.3g} " + "; ".join(
                f"{c['name']} {c['median']:.4g} [{c['ci90'][0]:.4g}, {c['ci90'][1]:.4g}]"
                f" {c['units']}" for c in m["coefficients"]))
        elif co is None:
            lines.append(f"{m['label']:30s} {m['probability']:11.3g}")
        else:
            lines.append(f"{m['name']:30s} {m['probability']:11.3g} {co['median']:11.4g} "
                         f"[{co['ci90'][0]:11.4g}, {co['ci90'][1]:11.4g}] {co['units']}")
    titles, rows = stage_rows(d)
    keep = ("amplitude error", "Hopf point", "fold", "chi²")
    rows = [(q, cells) for q, cells in rows if q.startswith(keep)]
    w = [max(len(t), *(len(cells[j]) for _, cells in rows)) + 3 for j, t in enumerate(titles)]
    lines += ["", f"{'fit':22s}" + "".join(f"{t:>{w[j]}s}" for j, t in enumerate(titles))]
    lines += [f"{q:22s}" + "".join(f"{c:>{w[j]}s}" for j, c in enumerate(cells))
              for q, cells in rows]
    lines += ["", d["mismatch"]["after"]["sentence"]]
    return lines
