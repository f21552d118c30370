"""NUTS's mass matrix started at the MAP's Laplace covariance against the identity.

Run: ``python benchmarks/bench_nuts_start.py``. On the rig and on the 3-DOF demo
(``flutter_experiment(seed=0)``), from the same MAP point and with the same
chain keys, 4 chains × (500 + 500) with a dense mass matrix: once started at the
inverse Hessian of the potential at the MAP (the default), once at the identity.
Reports the mean leapfrog steps per iteration in warm-up and in the draws (the
cost, whatever the machine's load), divergences, R̂ and bulk ESS of μ0, a2,
μ_fold and w, and the 90% intervals. Writes ``benchmarks/results/nuts_start.json``.

Both data sets were used to choose the core's settings (seed 0 and the rig);
the calibration over seeds 100–119 (``bench_calibration_collapsed.py``) is the
check on data not used for that.
"""

import json
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
from _common import RESULTS_DIR, atomic_write  # noqa: E402


def case(name, recordings):
    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference import collapsed as ci

    f = extract_harmonics(recordings)
    spec = ci.build_spec(f, "subcritical")
    kw = ci.model_arguments(spec, f)
    mp = ci.fit_map(kw)
    settings = ci.CollapsedSettings()
    laplace = ci.laplace_covariance
    rows = []
    for start in ("laplace", "identity"):
        ci.laplace_covariance = (laplace if start == "laplace"     # the identity: NUTS's own
                                 else (lambda vg, x: (np.eye(np.shape(x)[0]), False)))
        try:
            t0 = time.perf_counter()
            run = ci.sample_posterior(kw, mp, settings, seed=0, progress=False)
            wall = time.perf_counter() - t0
        finally:
            ci.laplace_covariance = laplace
        conv = ci.convergence(run.chains)
        rows.append({
            "case": name, "start": run.sampler["mass_matrix_start"], **run.sampler,
            "divergences": run.divergences, "wall_s_with_compile": wall,
            "sites": {k: {"r_hat": v["r_hat"], "ess_bulk": v["ess_bulk"]} for k, v in conv.items()},
            "intervals": {k: np.quantile(run.samples[k], [0.05, 0.5, 0.95]).tolist()
                          for k in ("mu0", "a2", "mu_fold")},
        })
        r = rows[-1]
        print(f"{name}, {start}: steps/iteration {r['leapfrog_steps_warmup']:.1f} (warm-up), "
              f"{r['leapfrog_steps_draws']:.1f} (draws); {r['divergences']} divergences; "
              f"R̂ ≤ {max(v['r_hat'] for v in r['sites'].values()):.4f}, ESS ≥ "
              f"{min(v['ess_bulk'] for v in r['sites'].values()):.0f}; {wall:.1f} s", flush=True)
    return rows


def main():
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu()    # before any JAX work, as the CLI does
    from bayeshopf.data import load_recordings
    from bayeshopf.simulators.truth import flutter_experiment

    rows = case("rig", load_recordings(HERE.parent.parent / "shared/data/flutter_cbc"))
    rows += case("demo (3-DOF, seed 0)", flutter_experiment(seed=0)[0])
    atomic_write(RESULTS_DIR / "nuts_start.json", json.dumps(rows, indent=1))


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    main()
