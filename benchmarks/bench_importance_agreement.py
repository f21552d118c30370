"""Importance sampling against NUTS on the same model and data, data set by data set.

    python benchmarks/bench_importance_agreement.py --seeds 1-8 [--model default|discrepancy]
    python benchmarks/bench_importance_agreement.py --summary --seeds 1-8

Each data set is the nominal 3-DOF aerofoil simulated by
:func:`bayeshopf.simulators.truth.flutter_experiment` (``seed``: its phases, noise
and sensor offsets), fitted with
``Settings(inference="importance", discrepancy=False, nn_width=16)``
(``--model discrepancy``: with ``discrepancy=True, nn_width=None``), seed
0, then NUTS on the same model from the same MAP point
(:func:`bayeshopf.inference.collapsed.compare_with_nuts`, the CLI's
``--nuts-check``). Recorded per data set: the method that ran (importance
sampling, or NUTS where its check failed), its Pareto k̂ and effective draws,
the 90% intervals of μ0, a2 and the fold by both, the larger end difference
as a fraction of NUTS's width (the package's agreement: at most
:data:`~bayeshopf.inference.svi.AGREEMENT_FRACTION`), NUTS's R̂ and ESS, and the
posterior stage's wall time of each.

Writes one JSON line per data set and model to
``benchmarks/results/importance_agreement.jsonl`` (appended); ``--summary``
prints the table.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from _common import RESULTS_DIR, exit_on_help

exit_on_help(__doc__)

OUT = RESULTS_DIR / "importance_agreement.jsonl"


def one(seed: int, model: str) -> dict:
    import bayeshopf as bh
    from bayeshopf.inference.collapsed import compare_with_nuts
    from bayeshopf.simulators.truth import flutter_experiment

    rs, _ = flutter_experiment(seed=seed)
    extra = ({"discrepancy": True, "nn_width": None} if model == "discrepancy" else
             {"discrepancy": False, "nn_width": 16})       # the default before session 78
    fit = bh.fit(rs, settings=bh.Settings(inference="importance", **extra), seed=0,
                 progress=False)
    post = fit.posterior
    t0 = time.perf_counter()
    chk = compare_with_nuts(post, progress=False)
    nuts_s = time.perf_counter() - t0
    return {"seed": seed, "model": model, "method": post.run.method,
            "check": {k: v for k, v in post.run.sampler.items() if not isinstance(v, dict)},
            "fallback": post.run.sampler.get("importance", {}).get("fallback"),
            "posterior_s": post.run.seconds, "nuts_s": nuts_s, "sites": chk["sites"],
            "agree": chk["agree"], "nuts_convergence": chk["convergence"],
            "nuts_divergences": chk["divergences"]}


def parse_seeds(s: str) -> list[int]:
    a, _, b = s.partition("-")
    return list(range(int(a), int(b or a) + 1))


def summary(seeds: list[int]) -> None:
    recs = [json.loads(x) for x in OUT.read_text().splitlines() if x]
    recs = [r for r in recs if r["seed"] in set(seeds)]
    print("| model | seed | method | k̂ | ESS | μ0 gap | a2 gap | fold gap | agree | NUTS R̂ max "
          "| posterior s (IS / NUTS) |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---|---:|---|")
    for r in sorted(recs, key=lambda r: (r["model"], r["seed"])):
        g = {k: f"{100 * v['end_gap_fraction']:.0f}%" for k, v in r["sites"].items()}
        c, nan = r["check"], float("nan")
        rhat = max(v["r_hat"] for v in r["nuts_convergence"].values())
        print(f"| {r['model']} | {r['seed']} | {r['method']} | {c.get('pareto_k', nan):.2f} "
              f"| {c.get('ess', nan):.0f} | {g['mu0']} | {g['a2']} | {g['mu_fold']} "
              f"| {'yes' if r['agree'] else 'no'} | {rhat:.3f} | {r['posterior_s']:.1f} / "
              f"{r['nuts_s']:.1f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1-8")
    ap.add_argument("--model", choices=("default", "discrepancy"), default="default")
    ap.add_argument("--summary", action="store_true")
    a = ap.parse_args()
    if a.summary:
        summary(parse_seeds(a.seeds))
        return
    OUT.parent.mkdir(parents=True, exist_ok=True)
    for seed in parse_seeds(a.seeds):
        rec = one(seed, a.model)
        with OUT.open("a") as fh:
            fh.write(json.dumps(rec) + "\n")
        print(f"agreement {a.model} seed {seed}: {rec['method']}, agree {rec['agree']}",
              file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
