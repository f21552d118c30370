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
        "one-sentence verdict.")
    s.add_argument("data", help="recordings: an interchange folder or CBC .mat files")
    s.add_argument("--simulator", required=True,
                   help="flutter3dof, vanderpol, or package.module:attr of your own System")
    s.add_argument("--out", required=True, help="output folder (refused if not empty)")
    s.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    s.add_argument("--no-hybrid", action="store_true",
                   help="skip the Bayesian hybrid fit of the recordings (saves minutes)")
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
                     progress=not args.quiet)
    write_report(report, args.out, force=args.force, figures=not args.no_figures)
    d = report.to_json()
    print(d["verdict"]["sentence"])
    print(f"{'model':30s} {'probability':>11s} {'median':>11s} {'90% interval':>26s}")
    for c in d["candidates"][:5]:
        co = c["coefficient"]
        if co is None:
            print(f"{c['name']:30s} {c['probability']:11.3g}")
        else:
            print(f"{c['name']:30s} {c['probability']:11.3g} {co['median']:11.4g} "
                  f"[{co['ci90'][0]:11.4g}, {co['ci90'][1]:11.4g}] {co['units']}")
    print(f"wrote {args.out}/report.json, report.md" + ("" if args.no_figures else
                                                         " and figures/")
          + f" in {d['runtime_s']:.0f} s")
    return 0
