"""The paper's numerical examples (Section 4), fitted blind: Van der Pol and the 3-DOF aerofoil.

For each system, noisy recordings of its limit cycles are simulated
(:mod:`bayeshopf.simulators.truth`: 1 % noise, sensor offsets, the unstable
aerofoil orbits as control-based continuation measures them), the Bayesian
hybrid model is fitted with ``bh.fit``, as ``bayeshopf fit`` does (a
deterministic start; the paper started μ0 and a2 at their true values), and the
posterior is checked against the simulator's own answers: the Hopf point, the
fold, and the amplitude of held-out orbits that the fit never saw.

    python examples/numerical_examples.py [OUTPUT_DIR] [--system vanderpol|flutter3dof|both]

The figures go to OUTPUT_DIR (default: a new temporary folder). Set
``BAYESHOPF_FAST=1`` for shorter records and short NUTS chains (a smoke test;
the convergence checks then usually warn).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import bayeshopf as bh

FAST = os.environ.get("BAYESHOPF_FAST", "0") == "1"
EXPERIMENTS = {"vanderpol": bh.simulators.truth.vanderpol_experiment,
               "flutter3dof": bh.simulators.truth.flutter_experiment}
TITLES = {"vanderpol": "Van der Pol oscillator (paper Section 4.1)",
          "flutter3dof": "3-DOF aeroelastic aerofoil (paper Section 4.2)"}


def run(name: str, out: Path, settings: bh.Settings) -> dict:
    """Simulate, fit, check and draw one example; returns its numbers."""
    rs, truth = EXPERIMENTS[name](seed=0, fast=FAST)
    print(f"== {TITLES[name]}: {len(rs)} recordings "
          f"({int(rs.is_unstable.sum())} unstable), {rs.mu_label} "
          f"{rs.mus.min():g}–{rs.mus.max():g} {rs.mu_units}, {100 * truth.noise:g}% noise, "
          "offsets " + ", ".join(f"{k} {v:+.2g}" for k, v in truth.offsets.items()))
    t0 = time.perf_counter()
    fit = bh.fit(rs, settings, criticality=truth.criticality, seed=0, progress=False)
    print(f"{truth.criticality} fit in {time.perf_counter() - t0:.0f} s")
    for w in fit.diagnostics.warnings:
        print(f"warning: {w}")
    print()
    curved = fit.spec.unfolding == "curved"

    print(f"{'':8s} {'median':>9s} {'90% interval':>22s} {'true':>9s}  inside")
    values = {}
    for q, true in truth.values().items():
        if true is None or (q == "a2" and curved):
            continue
        iv = fit.interval(q)
        values[q] = (iv, true)
        print(f"{q:8s} {iv.median:9.4f} [{iv.lo:9.4f}, {iv.hi:9.4f}] {true:9.4f}  "
              f"{'yes' if iv.contains(true) else 'NO'}")
    if truth.criticality == "supercritical":
        iv = fit.interval("a4")
        print(f"a4       {iv.median:9.4f} [{iv.lo:9.4f}, {iv.hi:9.4f}]  (quintic term in the gauge "
              "a2 = -1; its scale is the learnt map's, no true value)")
    if curved:
        iv, w = fit.interval("a2"), fit.interval("w_unfold")
        print(f"a2       {iv.median:9.4f} [{iv.lo:9.4f}, {iv.hi:9.4f}]  (cubic coefficient of the "
              f"curved unfolding, w = {w.median:.2f}; not the linear one's 2√(μ0 − μ_SN))")

    rows = bh.simulators.truth.held_out_check(fit, truth)
    n_in = sum(r["inside"] for r in rows)
    print(f"\nheld-out orbits (peak-to-peak of {rs.planar[0]}, {rs.units[0] or 'no unit'}), "
          "true against the 90% predictive interval of a new recording:")
    for r in rows:
        print(f"  {r['branch']:8s} {r['mu']:6.3g}  true {r['true']:.4g}  "
              f"predicted {r['median']:.4g} [{r['lo']:.4g}, {r['hi']:.4g}]  "
              f"{'inside' if r['inside'] else 'OUTSIDE'}")
    print(f"held-out: {n_in}/{len(rows)} inside their 90% predictive intervals\n")

    figures = {
        "bifurcation": bh.plotting.truth.plot_diagram_vs_truth(fit, truth, rows,
                                                               title=TITLES[name]),
        "phase_portraits": bh.plotting.plot_phase_portraits(fit, rs, truth=truth.orbit),
        "held_out_phase_portraits": bh.plotting.plot_phase_portraits(
            fit, bh.simulators.truth.held_out_recordings(truth), truth=truth.orbit),
    }
    paths = [bh.plotting.save_figure(fig, out / f"{name}_{key}.png")
             for key, fig in figures.items()]
    for p in paths:
        print(f"  wrote {p}")
    print()
    return {"values": values, "held_out": rows, "paths": paths}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", nargs="?", default=None, help="output folder (default: temporary)")
    ap.add_argument("--system", choices=("vanderpol", "flutter3dof", "both"), default="both")
    args = ap.parse_args(argv)
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bayeshopf-section4-"))
    out.mkdir(parents=True, exist_ok=True)
    settings = bh.Settings.fast() if FAST else bh.Settings()
    print(f"bayeshopf {bh.__version__}: {'fast' if FAST else 'default'} settings\n")
    names = ("vanderpol", "flutter3dof") if args.system == "both" else (args.system,)
    for name in names:
        run(name, out, settings)
    return 0


if __name__ == "__main__":
    sys.exit(main())
