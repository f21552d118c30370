"""Missing physics, blind: a simulator a few percent off that also lacks a term.

    .venv/bin/python examples/missing_physics.py [OUT]      # OUT defaults to missing_physics/

1. Records 4 stable and 4 unstable LCOs of a 3-DOF aerofoil whose heave
   stiffness is 4% higher, aerodynamic lift slope 3% higher and pitch damping
   5% lower than the simulator's (flutter3dof) nominal values, and whose heave
   has a cubic damping of 20 N/(m/s)³ that the simulator lacks, with 1.5%
   noise and sensor offsets (`with_params` and `simulate_with_effect`; the
   truth is kept apart).
2. Runs `bh.discrepancy.analyse` on the recordings with the plain
   simulator: it is not told either. The analysis calibrates the simulator's
   uncertain parameters, then names what is still missing. Prints the verdict,
   the calibrated parameters, the models and the fit at each stage, and writes
   report.json, report.md, figures/.
3. With the wind-tunnel recordings available (`../shared/data/flutter_cbc` or
   `$BAYESHOPF_FLUTTER_CBC`), runs the same analysis on them (no ground truth
   there).

Both analyses include the Bayesian hybrid fit of the recordings
(`bh.fit` at the default `bh.Settings`, a minute or two each); its Hopf
and fold intervals and its convergence are printed.

``BAYESHOPF_FAST=1`` skips the Bayesian hybrid fit and the wind-tunnel data
(a smoke test of the whole flow, a few minutes).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import bayeshopf as bh
import bayeshopf.cli.discrepancy  # noqa: F401  (loads bh.cli.discrepancy: write_report)

FAST = os.environ.get("BAYESHOPF_FAST", "0") == "1"
# the truth's Hopf point is at 17.18 m/s (k_h +4%, c0 +3%, c_alpha -5%): record below it
PLAN = [(15.5, "stable"), (16.0, "stable"), (16.5, "stable"), (17.0, "stable"),
        (15.5, "unstable"), (16.0, "unstable"), (16.5, "unstable"), (17.0, "unstable")]


def show(report) -> None:
    d = report.to_json()
    print(d["verdict"]["sentence"])
    print(f"\nparameters named off ({d['parameters']['model']}):")
    print(f"{'parameter':10s} {'nominal':>10s} {'median':>10s}  90% interval")
    for p in d["parameters"]["table"]:
        if p["off"]:
            print(f"{p['name']:10s} {p['nominal']:10.4g} {p['median']:10.4g}  "
                  f"[{p['ci90'][0]:.4g}, {p['ci90'][1]:.4g}]  ({100 * p['shift']:+.1f}%)")
    print(f"\n{'model':44s} {'probability':>11s}")
    for m in sorted(d["models"], key=lambda m: -m["probability"])[:4]:
        print(f"{m['label']:44s} {m['probability']:11.3g}")
    print()
    for stage, f in d["fit"].items():
        fold = "none" if f["fold"] is None else f"{f['fold']:.3f}"
        print(f"{stage:10s} fold {fold} m/s; amplitude error "
              + ", ".join(f"{c} {100 * v:.2f}%" for c, v in f["amplitude_error"].items()
                          if v is not None))
    if d.get("hybrid"):
        h = d["hybrid"]
        print("hybrid fit of the recordings: " + "; ".join(
            f"{k} {h[k]['median']:.2f} [{h[k]['ci90'][0]:.2f}, {h[k]['ci90'][1]:.2f}]"
            for k in ("hopf", "fold") if h.get(k)))
        c, st = h["convergence"], h["settings"]
        if c.get("r_hat") is not None:
            print(f"  NUTS {st['num_chains']} chains x {st['num_samples']} draws: largest R-hat "
                  f"{c['r_hat']:.3f}, smallest bulk ESS {c['ess_bulk']:.0f}, "
                  f"{c['divergences']} divergences; converged: {c['ok']}")
        for w in h["warnings"]:
            print(f"  warning: {w}")


def main(out: Path) -> None:
    flutter = bh.simulators.get_system("flutter3dof")
    off = flutter.with_params(k_h=1.04 * flutter.params["k_h"], c0=1.03 * flutter.params["c0"],
                              c_alpha=0.95 * flutter.params["c_alpha"])
    rs, truth = bh.discrepancy.simulate_with_effect(
        off.replace(default_plan=tuple(PLAN)), "h_cubic_damping", 20.0,
        [m for m, _ in PLAN], [b for _, b in PLAN], noise=0.015,
        offsets={"h": 0.001, "alpha": -0.004}, duration_s=8.0 if FAST else 20.0, seed=1)
    print(f"hidden: k_h +4%, c0 +3%, c_alpha -5%; {truth['effect']} = {truth['value']:g} "
          f"{truth['units']}\n")
    report = bh.discrepancy.analyse(rs, flutter, seed=0, hybrid=not FAST, progress=False)
    show(report)
    bh.cli.discrepancy.write_report(report, out / "blind", force=True)
    print(f"\nwrote {out / 'blind'}/report.json, report.md, figures/")

    data = Path(os.environ.get("BAYESHOPF_FLUTTER_CBC", "../shared/data/flutter_cbc"))
    if FAST or not data.is_dir():
        return
    print("\nwind-tunnel recordings (no ground truth):")
    real = bh.discrepancy.analyse(bh.read_recordings(data), flutter, seed=0, hybrid=True)
    show(real)
    bh.cli.discrepancy.write_report(real, out / "wind_tunnel", force=True)
    print(f"\nwrote {out / 'wind_tunnel'}/report.json, report.md, figures/")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("missing_physics"))
