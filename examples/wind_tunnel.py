"""The wind-tunnel flutter rig: the paper's experimental result, with bands and leave-one-out.

Fits the 7 CBC recordings of the authors' flutter rig (4 stable and 3 unstable
LCOs) with ``bh.fit``, as ``bayeshopf fit`` does. The rig has unstable LCOs,
measured by control-based continuation, so the fit is subcritical: a
supercritical Hopf bifurcation has no unstable branch. It then refits without
each recording in turn (Bayesian, and the MAP plug-in), checks the normal form
on the stable/unstable pairs without any map, and regresses the actuator
command on the normal-form state.

    python examples/wind_tunnel.py [DATA_DIR] [OUTPUT_DIR]

DATA_DIR defaults to ``$BAYESHOPF_FLUTTER_CBC`` or ``../shared/data/flutter_cbc``;
``bh.read_recordings("flutter_cbc", download=True)`` fetches the files instead.
Writes ``wind_tunnel.json`` and the figures to OUTPUT_DIR (default: a new
temporary folder). ``BAYESHOPF_FAST=1`` runs short fits and two folds only.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import bayeshopf as bh

FAST = os.environ.get("BAYESHOPF_FAST", "0") == "1"
#: The paper's point estimates (its Section 5).
PAPER = {"mu0": 17.67, "mu_fold": 14.66}


def _json(x):
    """JSON form of numpy scalars and arrays in the summary."""
    return x.tolist() if hasattr(x, "tolist") else float(x)


def main(argv: list[str]) -> int:
    data = argv[1] if len(argv) > 1 else os.environ.get(
        "BAYESHOPF_FLUTTER_CBC", str(Path(__file__).parents[1] / ".." / "shared" / "data"
                                     / "flutter_cbc"))
    out = Path(argv[2]) if len(argv) > 2 else Path(tempfile.mkdtemp(prefix="bayeshopf-wt-"))
    out.mkdir(parents=True, exist_ok=True)
    settings = bh.Settings.fast() if FAST else bh.Settings()
    rs = bh.read_recordings(data)
    print(f"{len(rs)} recordings ({int(rs.is_unstable.sum())} unstable) from {data}")

    # 1. The fit: subcritical (the rig has unstable LCOs), intervals next to the
    #    paper's point estimates, diagnostics, figures.
    fit = bh.fit(rs, settings, criticality="subcritical", seed=0, progress=False)
    print(f"\n{'':8s} {'median':>8s} {'90% interval':>20s} {'paper':>7s}")
    summary = {"criticality": "subcritical"}
    for name in ("mu0", "a2", "mu_fold"):
        iv = fit.interval(name)
        summary[name] = iv.to_json()
        paper = f"{PAPER[name]:7.2f}" if name in PAPER else " " * 7
        print(f"{name:8s} {iv.median:8.2f} [{iv.lo:8.2f}, {iv.hi:8.2f}] {paper}")
    ppc = fit.ppc()
    print(f"{int(ppc.covered.sum())}/{ppc.covered.size} training amplitudes inside their 90% "
          "predictive bands")
    freq = fit.frequency_check()
    print(f"{sum(e['inside_ci90'] for e in freq)}/{len(freq)} measured frequencies inside their "
          "90% predictive bands")
    for w in fit.diagnostics.warnings:
        print(f"warning: {w}")
    summary["diagnostics"] = dict(fit.diagnostics.details)
    bh.plotting.plot_all(fit, rs, out / "figures")

    # 2. Leave-one-out: Bayesian against the MAP plug-in.
    folds = rs.names[2:4] if FAST else None
    loo = bh.validation.leave_one_out(rs, "subcritical", seed=0, settings=settings, folds=folds,
                                      keep_fits=True, progress=False)
    summary["leave_one_out"] = {"summary": loo.summary(), "folds": loo.table()}
    print(f"\nleave-one-out over {len(loo.folds)} folds:")
    for s in loo.summary().values():
        print(f"  {s['label']:22s} inside 90%: {s['coverage']}/{s['n_folds']} "
              f"(P = {s['coverage_p']:.2f} if calibrated), held-out error "
              f"{100 * s['mean_relative_error']:.1f}% (max {100 * s['max_relative_error']:.1f}%), "
              f"fold spread (sd) {s['mu_fold_sd']:.2f} {rs.mu_units}")
    bh.plotting.save_figure(
        bh.plotting.validation.plot_leave_one_out(loo, fit.features, mu_units=rs.mu_units),
        out / "figures" / "leave_one_out.png")

    # 3. The same question without any map: at a μ with both orbits,
    #    x = (A_s A_u)²/(A_s² + A_u²)² = −β(μ)/a2² whatever the map's gain; with the
    #    paper's β = μ − μ0 a straight line, so the pairs give μ0, a2 and the fold,
    #    and two pairs predict the third.
    pairs = bh.diagnostics.pair_invariant.pair_invariants(fit.features)
    line = bh.diagnostics.pair_invariant.invariant_line(pairs)
    print("\nmap-free pair invariant: " + ", ".join(
        f"{name} {line.interval(name).median:.2f} [{line.interval(name).lo:.2f}, "
        f"{line.interval(name).hi:.2f}]" for name in ("mu0", "a2", "mu_fold")))
    summary["pair_invariant"] = {name: line.interval(name).to_json()
                                 for name in ("mu0", "a2", "mu_fold")}
    bh.plotting.save_figure(
        bh.plotting.pair_invariant.plot_pair_invariant(pairs, fit=fit, mu_units=rs.mu_units),
        out / "figures" / "pair_invariant.png")
    for held, other in bh.diagnostics.pair_invariant.leave_one_pair_out(pairs):
        pred = other.unstable_amplitude(held.mu, held.stable_amplitude)
        print(f"  without {held.unstable}: {1e3 * held.unstable_amplitude:.1f} mm measured, "
              f"{1e3 * pred.median:.1f} [{1e3 * pred.lo:.1f}, {1e3 * pred.hi:.1f}] mm "
              "from the other pairs")

    # 4. A third channel: the actuator command, regressed after inverting the map.
    channel = bh.inference.channels.fit_channel(fit, rs, "actuator", n_draws=40 if FAST else 100)
    bh.plotting.save_figure(bh.plotting.channels.plot_channel(channel, fit),
                            out / "figures" / "actuator.png")
    summary["actuator_amplitude"] = channel.measured_amplitude.tolist()

    (out / "wind_tunnel.json").write_text(json.dumps(summary, indent=2, default=_json))
    print(f"\nwrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
