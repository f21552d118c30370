"""The collapsed core on the demo (3-DOF aerofoil) and the rig: timings, NUTS against SVI, fit.

Run: ``python benchmarks/bench_collapsed.py [rig|demo|both]``. Both cases (the
default) write the current ``benchmarks/collapsed.json``; one case alone goes to
``benchmarks/results/collapsed_<case>.json``. It prints a Markdown table. Each case: one cold
``bayeshopf fit``-equivalent run in a fresh process is timed by the caller
(``time bayeshopf fit ...``); here the stages are timed in-process, NUTS (the
default posterior) and SVI are both run from the same MAP point, and their 90%
intervals of μ0, a2 and μ_fold are compared end by end (within 25% of NUTS's
width: the issue's bar).
"""

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS_DIR, atomic_write, exit_on_help  # noqa: E402

HERE = Path(__file__).parent


def run(name, rs, truth=None):
    from bayeshopf.inference import collapsed as ci
    from bayeshopf.posterior import fit_hybrid

    t0 = time.perf_counter()
    post = fit_hybrid(rs, "subcritical", seed=0, progress=False)
    wall = time.perf_counter() - t0
    kwargs = ci.model_arguments(post.spec, post.features)
    t0 = time.perf_counter()
    svi = ci.sample_posterior(kwargs, post.map_point, replace(post.settings, inference="svi"),
                              seed=1, progress=False)
    svi_s = time.perf_counter() - t0
    agree = ci.interval_agreement(post.samples, svi.samples)
    ppc = post.ppc()
    out = {
        "case": name, "wall_s": wall, "timings_s": post.timings, "svi_s": svi_s,
        "intervals": {k: post.interval(k).to_json() for k in ("mu0", "a2", "mu_fold", "w_unfold")},
        "svi_intervals": {k: np.quantile(svi.samples[k], [0.05, 0.5, 0.95]).tolist()
                          for k in ("mu0", "a2", "mu_fold")},
        "svi_elbo_plateau": ci.elbo_plateau(svi.losses),
        "agreement": agree,
        "convergence": post.diagnostics["posterior"],
        "orbit_error": post.diagnostics["fit"]["orbit_error"],
        "amplitude_covered": [bool(c) for c in ppc.covered],
        "warnings": post.diagnostics["warnings"],
    }
    if truth is not None:
        out["truth"] = {"mu0": truth.mu0, "mu_fold": truth.mu_fold}
        out["truth_inside"] = {k: post.interval(k).contains(v) for k, v in out["truth"].items()}
    return out


def main(which="both"):
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu()    # before any JAX work, as the CLI does
    results = []
    if which in ("rig", "both"):
        from bayeshopf.data import load_recordings

        results.append(run("rig", load_recordings(HERE.parent.parent / "shared/data/flutter_cbc")))
    if which in ("demo", "both"):
        from bayeshopf.simulators.truth import flutter_experiment

        rs, truth = flutter_experiment(seed=0)
        results.append(run("demo (3-DOF, seed 0)", rs, truth))
    # the current result is the run of both cases; a single case is a side run
    path = HERE / "collapsed.json" if which == "both" else RESULTS_DIR / f"collapsed_{which}.json"
    atomic_write(path, json.dumps(results, indent=1, default=float))
    for r in results:
        print(f"\n## {r['case']}: {r['wall_s']:.1f} s in-process ({r['timings_s']})")
        for k, v in r["intervals"].items():
            print(f"- {k}: {v}")
        for k, v in r["agreement"].items():
            print(f"- SVI vs NUTS {k}: NUTS {np.round(v['reference'], 4).tolist()}, "
                  f"SVI {np.round(v['other'], 4).tolist()}, end gap "
                  f"{100 * v['end_gap_fraction']:.0f}% of NUTS's width")
        print("- orbit errors:", [round(100 * e["relative"], 2) for e in r["orbit_error"]])
        cov = r["amplitude_covered"]
        print("- amplitudes covered:", sum(cov), "/", len(cov))
        print("- warnings:", r["warnings"])


if __name__ == "__main__":
    exit_on_help(__doc__)
    main(sys.argv[1] if len(sys.argv) > 1 else "both")
