"""Quick start: fit a known Hopf system and compare the posterior with the truth.

Generates synthetic stable and unstable limit-cycle recordings of a planted
subcritical Hopf system (the flutter-rig-like demo set), fits the Bayesian
hybrid normal-form model (``bh.fit``, as ``bayeshopf fit`` does), prints the
Hopf point μ0, the cubic coefficient a2 and the fold μ_fold with their 90%
intervals next to the planted values and the convergence checks, predicts the
LCO amplitude and frequency at a new airspeed, and saves the figures.

    python examples/quickstart.py [OUTPUT_DIR]

The figures go to OUTPUT_DIR (default: a new temporary folder). Set
``BAYESHOPF_FAST=1`` for short NUTS chains (a smoke test; the convergence
checks then usually warn).
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import bayeshopf as bh

FAST = os.environ.get("BAYESHOPF_FAST", "0") == "1"
#: A new airspeed (m/s), between the recordings, where both LCO branches exist.
NEW_MU = 17.0


def main(argv: list[str]) -> int:
    out = Path(argv[1]) if len(argv) > 1 else Path(tempfile.mkdtemp(prefix="bayeshopf-quickstart-"))

    # 1. Recordings: 4 stable and 3 unstable LCOs of a system whose truth we know.
    rs, truth = bh.data.synthetic.demo_system(seed=0, fast=FAST)
    print(f"bayeshopf {bh.__version__}: {len(rs)} synthetic recordings "
          f"({int(rs.is_unstable.sum())} unstable), channels {rs.planar}, "
          f"{rs.mu_label} {rs.mus.min():g}–{rs.mus.max():g} {rs.mu_units}")

    # 2. Fit: Fourier features -> deterministic start and MAP -> importance sampling
    #    (NUTS where its check fails) on the few nonlinear parameters, the map
    #    integrated out exactly.
    settings = bh.Settings.fast() if FAST else bh.Settings()
    fit = bh.fit(rs, settings, criticality="subcritical", seed=0, progress=False)
    steps = ", ".join(f"{k} {v:.1f} s" for k, v in fit.timings.items())
    print(f"fitted ({'fast' if FAST else 'default'} settings): {steps}")
    d = fit.diagnostics.details
    post = d["posterior"]
    if post["method"] == "importance":
        check = (f"importance sampling: Pareto k̂ {post['pareto_k']:.2f}, "
                 f"{post['ess']:.0f} effective draws")
    else:
        worst = max(v["r_hat"] for v in post["sites"].values())
        check = f"NUTS R̂ ≤ {worst:.3f}, {post['divergences']} divergences"
    print(f"MAP gradient norm {d['map']['grad_norm']:.1e}; {check}")
    for w in fit.diagnostics.warnings:
        print(f"warning: {w}")
    print()

    # 3. Intervals against the planted truth.
    true = {"mu0": truth.mu0, "a2": truth.a2, "mu_fold": truth.mu_fold}
    print(f"{'':8s} {'median':>9s} {'90% interval':>22s} {'true':>8s}  inside")
    for name, value in true.items():
        iv = fit.interval(name)
        print(f"{name:8s} {iv.median:9.3f} [{iv.lo:9.3f}, {iv.hi:9.3f}] {value:8.3f}  "
              f"{'yes' if iv.contains(value) else 'NO'}")

    # 4. Predict the amplitude (peak-to-peak heave) and frequency of the model's
    #    curve at a new airspeed (predictive=True would describe a new recording).
    print(f"\namplitude at {rs.mu_label} = {NEW_MU:g} {rs.mu_units} "
          f"({rs.units[0]}, peak-to-peak of {rs.planar[0]}):")
    for branch in ("stable", "unstable"):
        p = fit.predict([NEW_MU], branch, predictive=False).sel(mu=NEW_MU)
        print(f"  {branch:8s} {float(p.amplitude):.4f}  90% [{float(p.amplitude_lo):.4f}, "
              f"{float(p.amplitude_hi):.4f}]  true {float(truth.amplitude(NEW_MU, branch)):.4f}  "
              f"(branch exists in {100 * float(p.p_exists):.0f}% of draws); "
              f"frequency {float(p.frequency):.4f} Hz [{float(p.frequency_lo):.4f}, "
              f"{float(p.frequency_hi):.4f}]")

    # 5. Figures: bifurcation diagram with bands, phase portraits, predictive check,
    #    frequency against μ, time series.
    paths = bh.plotting.plot_all(fit, rs, out, truth=truth)
    print("\nfigures:")
    for p in paths:
        print(f"  {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
