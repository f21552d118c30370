"""Missing physics, blind: plant a hidden effect in a simulated rig, let the analysis find it.

    .venv/bin/python examples/missing_physics.py [OUT]      # OUT defaults to missing_physics/

1. Records 4 stable and 4 unstable LCOs of the 3-DOF aerofoil (flutter3dof)
   whose pitch spring has 300 N m/rad³ more cubic stiffness than the simulator
   knows, with 1.5% noise and sensor offsets (`simulate_with_effect`; the
   truth is kept apart).
2. Runs `bayeshopf.discrepancy.analyse` on the recordings with the plain
   simulator: it is not told the effect. Prints the verdict, the candidates
   and the fit before and after, and writes report.json, report.md, figures/.
3. With the wind-tunnel recordings available (`../shared/data/flutter_cbc` or
   `$BAYESHOPF_FLUTTER_CBC`), runs the same analysis on them (no ground truth
   there).

Both analyses include the Bayesian hybrid fit of the recordings
(`bayeshopf.posterior.fit_hybrid` at the default `CollapsedSettings`, a minute
or two each); its Hopf and fold intervals and its convergence are printed.

``BAYESHOPF_FAST=1`` skips the Bayesian hybrid fit and the wind-tunnel data
(a smoke test of the whole flow, under a minute).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

from bayeshopf.cli.discrepancy import write_report  # noqa: E402
from bayeshopf.discrepancy import analyse, simulate_with_effect  # noqa: E402
from bayeshopf.simulators import get_system  # noqa: E402

FAST = os.environ.get("BAYESHOPF_FAST", "0") == "1"
PLAN = [(15.75, "stable"), (16.25, "stable"), (16.75, "stable"), (17.25, "stable"),
        (15.75, "unstable"), (16.25, "unstable"), (16.75, "unstable"), (17.25, "unstable")]


def show(report) -> None:
    d = report.to_json()
    print(d["verdict"]["sentence"])
    print(f"\n{'model':28s} {'probability':>11s} {'median':>11s}  90% interval")
    for c in d["candidates"][:4]:
        co = c["coefficient"]
        tail = "" if co is None else (f"{co['median']:11.4g}  [{co['ci90'][0]:.4g}, "
                                      f"{co['ci90'][1]:.4g}] {co['units']}")
        print(f"{c['name']:28s} {c['probability']:11.3g} {tail}")
    fb, fa = d["fit"]["before"], d["fit"]["after"]
    print(f"\nfold {fb['fold']:.3f} -> {fa['fold'] if fa['fold'] is None else round(fa['fold'], 3)}"
          f" m/s; chi2 {fb['chi2']:.0f} -> {fa['chi2']:.0f} ({fa['dof']} dof); amplitude error "
          + ", ".join(f"{c} {100 * fb['amplitude_error'][c]:.2f}% -> "
                      f"{100 * fa['amplitude_error'][c]:.2f}%" for c in fb["amplitude_error"]))
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
    flutter = get_system("flutter3dof")
    rs, truth = simulate_with_effect(flutter, "alpha_cubic_stiffness", 300.0,
                                     [m for m, _ in PLAN], [b for _, b in PLAN],
                                     noise=0.015, offsets={"h": 0.001, "alpha": -0.004},
                                     duration_s=8.0 if FAST else 20.0, seed=1)
    print(f"hidden: {truth['effect']} = {truth['value']:g} {truth['units']}\n")
    report = analyse(rs, flutter, seed=0, hybrid=not FAST, progress=False)
    show(report)
    write_report(report, out / "blind", force=True)
    print(f"\nwrote {out / 'blind'}/report.json, report.md, figures/")

    data = Path(os.environ.get("BAYESHOPF_FLUTTER_CBC", "../shared/data/flutter_cbc"))
    if FAST or not data.is_dir():
        return
    from bayeshopf.datasets import flutter_cbc

    print("\nwind-tunnel recordings (no ground truth):")
    real = analyse(flutter_cbc(str(data)), flutter, seed=0, hybrid=True)
    show(real)
    write_report(real, out / "wind_tunnel", force=True)
    print(f"\nwrote {out / 'wind_tunnel'}/report.json, report.md, figures/")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("missing_physics"))
