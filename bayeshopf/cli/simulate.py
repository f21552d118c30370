"""``bayeshopf simulate``: recordings of a known system's stable and unstable LCOs.

Writes an interchange folder (``manifest.csv`` and one CSV per recording, only
the observed channels) that ``bayeshopf fit`` reads, plus ``simulation.json``
with the truth (Hopf point, folds, the amplitude of every recorded orbit) and
the settings. Bad input is reported by :func:`bayeshopf.cli.main.main` as one
line with exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from bayeshopf._atomic import replacing
from bayeshopf.cli._checks import check_out
from bayeshopf.discrepancy.effects import effect_names, simulate_with_effect, truth_points
from bayeshopf.errors import OutputError
from bayeshopf.simulators import (
    SimulationError,
    bifurcation_diagram,
    get_system,
    simulate_recordings,
    simulation_info,
    write_simulation,
)

DESCRIPTION = ("Continue the periodic orbits of a known system from its Hopf point and write "
               "recordings of stable and unstable LCOs as control-based continuation measures "
               "them (the open-loop orbit plus sensor noise and offsets) to an interchange "
               "folder that 'bayeshopf fit' reads. Without --mu, a default set across the "
               "branches is recorded (flutter3dof: 4 stable + 4 unstable LCOs between the fold "
               "and the Hopf point).")


def add_arguments(s: argparse.ArgumentParser) -> None:
    """The options of ``simulate``."""
    s.add_argument("system", help="vanderpol, flutter3dof, or package.module:attr of your own "
                   "bayeshopf.simulators.System")
    s.add_argument("--out", required=True, help="output folder (refused if not empty)")
    s.add_argument("--mu", type=float, nargs="+", default=None, metavar="MU",
                   help="bifurcation parameter of each recording (default: the system's set)")
    s.add_argument("--branch", nargs="+", default=None, metavar="BRANCH",
                   help="stable or unstable, one per --mu, or one for all (default stable)")
    s.add_argument("--noise", type=float, default=0.01,
                   help="measurement noise relative to each channel's RMS (default 0.01)")
    s.add_argument("--offset", nargs="+", default=[], metavar="CHANNEL=VALUE",
                   help="sensor offsets, e.g. h=0.002 alpha=-0.01 (default none)")
    s.add_argument("--duration", type=float, default=20.0, help="record length in s (default 20)")
    s.add_argument("--rate", type=float, default=500.0,
                   help="sampling rate in Hz (default 500)")
    s.add_argument("--seed", type=int, default=0, help="seed of phases and noise (default 0)")
    s.add_argument("--force", action="store_true", help="replace a non-empty output folder")
    s.add_argument("--effect", default=None, metavar="NAME",
                   help="plant a hidden effect: a library term <coordinate>_<kind> "
                   "(e.g. alpha_cubic_stiffness, h_coulomb_friction) or delayed_aero (outside "
                   "the library); the recordings carry no trace of it")
    s.add_argument("--effect-value", type=float, default=None, metavar="X",
                   help="size of the effect in the term's unit (required with --effect)")
    s.add_argument("--truth-out", default=None, metavar="FILE",
                   help="write the hidden effect and the true Hopf point and fold to this JSON "
                   "file (with --effect nothing about the truth is written beside the data)")


def _parse_offsets(items: list[str]) -> dict[str, float]:
    """``--offset CHANNEL=VALUE ...`` as ``{channel: value}``."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            if not sep or not name.strip():
                raise ValueError
            out[name.strip()] = float(value)
        except ValueError:
            raise SimulationError(
                f"--offset: CHANNEL=VALUE expected (e.g. h=0.002); got {item!r}"
            ) from None
    return out


def run(args) -> int:
    """Run ``bayeshopf simulate``; errors propagate as ``BayesHopfError``."""
    out = check_out(args.out, args.force, "replace it")
    system = get_system(args.system)
    offsets = _parse_offsets(args.offset)
    if args.branch is not None and args.mu is None:
        raise SimulationError("--branch given without --mu; give the mu of each recording")
    if args.effect is not None or args.effect_value is not None or args.truth_out:
        return _run_effect(args, system, offsets, out)
    rs = simulate_recordings(system, args.mu, args.branch, noise=args.noise, offsets=offsets,
                             duration_s=args.duration, sample_rate_hz=args.rate, seed=args.seed)
    diagram = bifurcation_diagram(system)  # cached: the one the recordings were sampled from
    info = simulation_info(rs, diagram, noise=args.noise, offsets=offsets,
                           duration_s=args.duration, sample_rate_hz=args.rate, seed=args.seed)
    write_simulation(rs, out, info=info, overwrite=args.force)

    p, u = system.parameter, system.parameter_units
    us = f" {u}" if u else ""
    h = diagram.hopf
    freq = f"{h.frequency_hz:.4g} Hz" if u else f"frequency {h.frequency_hz:.4g}"
    mu0 = h.mu if abs(h.mu) > 1e-12 else 0.0  # print 0, not -2.8e-17
    line = f"{system.name}: {diagram.criticality} Hopf point at {p} = {mu0:.5g}{us} ({freq})"
    if diagram.folds:
        line += "; fold of LCOs at " + ", ".join(f"{p} = {f.mu:.5g}{us}" for f in diagram.folds)
    print(line)
    z1 = system.planar[0]
    zu = system.observed_units[z1]
    print(f"{'recording':24s} {p:>8s} {'branch':>9s} {z1 + ' p2p':>12s} {'period':>10s}")
    for r, rec in zip(rs, info["recordings"], strict=True):
        amp = rec["amplitude"][z1]
        print(f"{r.name[:24]:24s} {r.mu:8.4g} {r.branch:>9s} {amp:12.4g} {rec['period']:10.4g}"
              + (f"  [{zu}]" if zu else ""))
    print(f"wrote {out}/ ({len(rs)} recordings of {', '.join(system.observed)}, "
          f"{args.duration:g} s at {args.rate:g} Hz, {100 * args.noise:g}% noise; "
          "simulation.json holds the truth)")
    return 0


def _run_effect(args, system, offsets, out: Path) -> int:
    """``--effect``: recordings with a hidden effect; the truth only in ``--truth-out``."""
    if args.effect is None or args.effect_value is None:
        raise SimulationError("--effect and --effect-value go together; expected both, got "
                              + ("--effect" if args.effect else "--effect-value"
                                 if args.effect_value is not None else "--truth-out")
                              + " alone")
    names = effect_names(system)
    if args.effect not in names:
        raise SimulationError(f"--effect {args.effect}: one of {', '.join(names) or '(none)'} "
                              f"expected for {system.name}; found {args.effect!r}")
    if not math.isfinite(args.effect_value):
        raise SimulationError(f"--effect-value {args.effect_value}: a finite number expected")
    truth_path = Path(args.truth_out) if args.truth_out else None
    if truth_path is not None:
        if truth_path.exists() and not args.force:
            raise OutputError(f"{truth_path}: a new file expected for --truth-out; found an "
                              "existing one (use --force to replace it)")
        if truth_path.resolve().parent == out.resolve() or out.resolve() in \
                truth_path.resolve().parents:
            raise OutputError(f"{truth_path}: --truth-out outside the data folder expected; "
                              f"found it inside {out}")
    rs, truth = simulate_with_effect(system, args.effect, args.effect_value, args.mu,
                                     args.branch, noise=args.noise, offsets=offsets,
                                     duration_s=args.duration, sample_rate_hz=args.rate,
                                     seed=args.seed)
    write_simulation(rs, out, info=None, overwrite=args.force)
    if truth_path is not None:
        truth.update(truth_points(system, args.effect, args.effect_value))
        truth.update(offsets=offsets, noise=args.noise, seed=args.seed,
                     recordings=[{"name": r.name, "mu": r.mu, "branch": r.branch} for r in rs])
        with replacing(truth_path) as tmp:
            tmp.write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {out}/ ({len(rs)} recordings of {', '.join(system.observed)} with a hidden "
          f"effect, {args.duration:g} s at {args.rate:g} Hz, {100 * args.noise:g}% noise)"
          + (f"; the truth is in {truth_path}" if truth_path else "; the truth is not written"))
    return 0
