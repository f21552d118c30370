"""How long NUTS's chains must be: the default 4 × (500 + 500) against shorter ones.

Run: ``python benchmarks/bench_chain_length.py [--seeds 1 2 3 4]`` on an otherwise
idle machine. On the rig and on the 3-DOF demo (``flutter_experiment(seed=0)``),
from one MAP point each and with two CPU devices (as the CLI on 2 cores), NUTS
runs at each length (the default, 4 × (250 + 250) and 4 × (500 + 250)) for
each sampler seed, extended by 250 draws per chain
while R̂ or bulk ESS of μ0, a2, μ_fold and w fails (R̂ ≤ 1.01, ESS ≥ 400), as
the package does. Reports the draws per chain it ended with, R̂, ESS,
divergences, the leapfrog steps (the cost, whatever the machine's load), the
wall time of the posterior stage (its programs compiled before the timed runs)
and the 90% intervals of μ0, a2 and μ_fold. Writes
``benchmarks/results/chain_length.json``.

The sampler seeds 1–4 were used to choose nothing (the defaults were chosen on
seed 0); this benchmark measures, it does not choose.
"""

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))
from _common import RESULTS_DIR, atomic_write  # noqa: E402

LENGTHS = {"500+500": (500, 500), "250+250": (250, 250), "500+250": (500, 250)}


def case(name, recordings, seeds):
    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference import collapsed as ci

    f = extract_harmonics(recordings)
    spec = ci.build_spec(f, "subcritical")
    kw = ci.model_arguments(spec, f)
    mp = ci.fit_map(kw)
    rows = []
    for label, (warmup, draws) in LENGTHS.items():
        settings = replace(ci.CollapsedSettings(), num_warmup=warmup, num_samples=draws)
        ci.sample_posterior(kw, mp, settings, seed=seeds[0], progress=False)   # compiles
        for seed in seeds:
            t0 = time.perf_counter()
            run = ci.sample_posterior(kw, mp, settings, seed=seed, progress=False)
            wall = time.perf_counter() - t0
            conv = ci.convergence(run.chains)
            s = run.sampler
            rows.append({
                "case": name, "length": label, "seed": seed, **s,
                "leapfrog_steps": 4 * (warmup * s["leapfrog_steps_warmup"]
                                       + s["draws_per_chain"] * s["leapfrog_steps_draws"]),
                "divergences": run.divergences, "wall_s": wall,
                "r_hat_max": max(v["r_hat"] for v in conv.values()),
                "ess_min": min(v["ess_bulk"] for v in conv.values()),
                "intervals": {k: np.quantile(run.samples[k], [0.05, 0.5, 0.95]).tolist()
                              for k in ("mu0", "a2", "mu_fold")},
            })
            r = rows[-1]
            print(f"{name} {label} seed {seed}: {r['draws_per_chain']} draws/chain, "
                  f"R̂ ≤ {r['r_hat_max']:.4f}, ESS ≥ {r['ess_min']:.0f}, "
                  f"{r['divergences']} divergences, {r['leapfrog_steps']:.0f} leapfrog steps, "
                  f"{wall:.1f} s; μ0 {np.round(r['intervals']['mu0'], 3).tolist()}", flush=True)
    return rows


def main(seeds):
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu(host_devices=2)
    from _common import rig_recordings

    from bayeshopf.inference.cache import enable_compilation_cache
    from bayeshopf.simulators.truth import flutter_experiment

    enable_compilation_cache()
    rows = case("rig", rig_recordings(), seeds)
    rows += case("demo", flutter_experiment(seed=0)[0], seeds)
    atomic_write(RESULTS_DIR / "chain_length.json",
                 json.dumps({"seeds": seeds, "rows": rows}, indent=1))
    print("| case | length | draws per chain (by seed) | R̂ max | ESS min | posterior stage |")
    print("|---|---|---|---:|---:|---:|")
    for name in ("rig", "demo"):
        for label in LENGTHS:
            sel = [r for r in rows if r["case"] == name and r["length"] == label]
            draws = ", ".join(str(r["draws_per_chain"]) for r in sel)
            print(f"| {name} | {label} | {draws} | {max(r['r_hat_max'] for r in sel):.4f} | "
                  f"{min(r['ess_min'] for r in sel):.0f} | "
                  f"{np.median([r['wall_s'] for r in sel]):.1f} s |")


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    args = sys.argv[1:]
    main([int(a) for a in args[args.index("--seeds") + 1:]] if "--seeds" in args else [1, 2, 3, 4])
