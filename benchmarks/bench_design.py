"""Simulated CBC campaigns: where ``next`` recommends, against a descent, a sweep and random points.

On the 3-DOF aerofoil (``flutter3dof``: Hopf 18.2747 m/s, fold 14.9362 m/s),
each campaign starts from 2 stable and 2 unstable recordings (:data:`START`)
and adds 4 recordings one at a time:

* ``design``: the best candidate of :func:`bayeshopf.design.next_measurements`
  (target ``fold``) of the current fit;
* ``sweep``: 4 points evenly spaced inside the initial fit's candidate range
  (the range the design searches, ends left out), branches alternating from
  the unstable one;
* ``random``: μ uniform over the same range, branch at random;
* ``descent``: what an experimenter does without the model: step down from
  the lowest recording by a fixed ``Δμ`` (:data:`DELTA_MU`, ``--delta-mu``),
  branches alternating from the unstable one; a step that finds no orbit
  halves ``Δμ`` for the next one (the orbit was lost below the fold, so the
  next attempt goes half as far down from the lowest recording).

A point where the simulator has no orbit on that branch is a failed attempt:
it costs a recording and adds nothing (CBC would not find the orbit either).
After each addition the model is refitted (NUTS, :data:`SETTINGS`), and the
90% widths of the fold and the Hopf point, and whether they contain the truth,
are recorded. Noise seeds 100–109 (the design was developed on seed 0 of the
demo set only; nothing was tuned on these seeds).

Usage: ``python benchmarks/bench_design.py [--seeds 100:110] [--steps 4]
[--strategies design,descent] [--delta-mu 0.3]``; writes
``benchmarks/design.md`` (every campaign's rows:
``benchmarks/results/design.json``). ``--smoke`` runs the
smallest comparison (seed 100, 2 steps, design against descent; 5 fits) and
writes it to the temporary folder unless ``--out`` is given.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _common import RESULTS_DIR, atomic_write  # noqa: E402

OUT = Path(__file__).parent
START = ((16.0, "stable"), (17.4, "stable"), (16.4, "unstable"), (17.4, "unstable"))
STRATEGIES = ("design", "sweep", "random", "descent")
#: The descent's step down from the lowest recording (m/s), as in issue 52's campaign.
DELTA_MU = 0.3
NOISE = 0.01
DURATION_S, RATE_HZ = 10.0, 500.0


def _settings():
    from bayeshopf.inference.collapsed import CollapsedSettings

    return CollapsedSettings(num_chains=2, num_warmup=250, num_samples=300, max_tree_depth=8)


def _fit(rs):
    from bayeshopf.posterior import fit_hybrid

    return fit_hybrid(rs, "subcritical", seed=0, settings=_settings(), progress=False)


def _state(fit, truth) -> dict:
    out = {}
    for k, true in (("mu_fold", truth.mu_fold), ("mu0", truth.mu0)):
        iv = fit.interval(k)
        out[k] = {"lo": iv.lo, "hi": iv.hi, "median": iv.median, "width": iv.hi - iv.lo,
                  "inside": bool(iv.contains(true))}
    return out


def _record(truth, mu: float, branch: str, seed: int):
    """A new recording at (μ, branch), or ``None`` when the simulator has no such orbit."""
    from bayeshopf.simulators import SimulationError, simulate_recordings

    try:
        return simulate_recordings(truth.system, [mu], [branch], noise=NOISE,
                                   offsets=truth.offsets, duration_s=DURATION_S,
                                   sample_rate_hz=RATE_HZ, seed=seed, diagram=truth.diagram)[0]
    except SimulationError:
        return None


def descent_point(lowest: float, delta: float, k: int) -> tuple[float, str]:
    """The descent's ``k``-th point (0-based): ``lowest − delta``, unstable on even ``k``."""
    return float(lowest - delta), "unstable" if k % 2 == 0 else "stable"


def campaign(seed: int, steps: int = 4, strategies=STRATEGIES,
             delta_mu: float = DELTA_MU) -> dict:
    """One noise seed: the start fit, then each strategy's campaign."""
    from bayeshopf.data.recording import RecordingSet
    from bayeshopf.design import candidate_grid, next_measurements
    from bayeshopf.simulators.truth import FLUTTER_OFFSET_SD, _experiment

    rs0, truth = _experiment("flutter3dof", START, (), seed=seed, noise=NOISE, offsets=None,
                             offset_sd=FLUTTER_OFFSET_SD, duration_s=DURATION_S,
                             sample_rate_hz=RATE_HZ)
    t0 = time.perf_counter()
    fit0 = _fit(rs0)
    grid = candidate_grid(fit0)
    lo, hi = float(grid[0]), float(grid[-1])
    res = {"seed": seed, "delta_mu": delta_mu,
           "truth": {"mu_fold": truth.mu_fold, "mu0": truth.mu0},
           "range": [lo, hi], "start": _state(fit0, truth), "strategies": {}}
    rng = np.random.default_rng([seed, 7])
    sweep = [(float(m), "unstable" if i % 2 == 0 else "stable")
             for i, m in enumerate(np.linspace(lo, hi, steps + 2)[1:-1])]
    randoms = [(float(rng.uniform(lo, hi)), str(rng.choice(["stable", "unstable"])))
               for _ in range(steps)]
    for strategy in strategies:
        recs, fit, history = list(rs0), fit0, []
        lowest, delta = min(m for m, _ in START), delta_mu
        for k in range(steps):
            predicted = None
            if strategy == "design":
                d = next_measurements(fit, target="fold", candidates=grid, n=1, seed=seed)
                if not d.recommended:
                    history.append({"step": k + 1, "point": None, "found": False,
                                    **_state(fit, truth)})
                    continue
                c = d.recommended[0]
                point, predicted = (c.mu, c.branch), c.width_after
            elif strategy == "descent":
                point = descent_point(lowest, delta, k)
            else:
                point = (sweep if strategy == "sweep" else randoms)[k]
            rec = _record(truth, point[0], point[1], seed=10_000 * seed + 100 * k + 1)
            if strategy == "descent":
                lowest, delta = (point[0], delta) if rec is not None else (lowest, delta / 2)
            if rec is not None:
                recs.append(rec)
                fit = _fit(RecordingSet(tuple(recs), rs0.planar, rs0.mu_label, rs0.mu_units))
            history.append({"step": k + 1, "point": list(point), "found": rec is not None,
                            "predicted_fold_width": predicted, **_state(fit, truth)})
            print(f"seed {seed} {strategy} step {k + 1}: {point[1]} {point[0]:.3f} "
                  f"fold width {history[-1]['mu_fold']['width']:.3f}", file=sys.stderr)
        res["strategies"][strategy] = history
    res["wall_s"] = time.perf_counter() - t0
    return res


def _summary(results: list[dict], steps: int) -> tuple[dict, str]:
    table = {}
    lines = ["| strategy | step | fold width (median [min, max]) | fold inside | "
             "Hopf width (median [min, max]) | Hopf inside | orbits not found |",
             "|---|---|---|---|---|---|---|"]
    w0 = {k: [r["start"][k]["width"] for r in results] for k in ("mu_fold", "mu0")}
    in0 = {k: sum(r["start"][k]["inside"] for r in results) for k in ("mu_fold", "mu0")}
    n = len(results)
    lines.append(f"| start (2+2) | 0 | {np.median(w0['mu_fold']):.3f} "
                 f"[{min(w0['mu_fold']):.3f}, {max(w0['mu_fold']):.3f}] | {in0['mu_fold']}/{n} "
                 f"| {np.median(w0['mu0']):.3f} [{min(w0['mu0']):.3f}, {max(w0['mu0']):.3f}] | "
                 f"{in0['mu0']}/{n} | |")
    for s in STRATEGIES:
        if not all(s in r["strategies"] for r in results):
            continue
        table[s] = []
        for k in range(steps):
            h = [r["strategies"][s][k] for r in results]
            wf = [x["mu_fold"]["width"] for x in h]
            wh = [x["mu0"]["width"] for x in h]
            row = {"step": k + 1, "fold_width_median": float(np.median(wf)),
                   "fold_inside": int(sum(x["mu_fold"]["inside"] for x in h)),
                   "hopf_width_median": float(np.median(wh)),
                   "hopf_inside": int(sum(x["mu0"]["inside"] for x in h)),
                   "not_found": int(sum(
                       not r["strategies"][s][j]["found"] for r in results for j in range(k + 1)))}
            table[s].append(row)
            lines.append(f"| {s} | {k + 1} | {row['fold_width_median']:.3f} [{min(wf):.3f}, "
                         f"{max(wf):.3f}] | {row['fold_inside']}/{n} | "
                         f"{row['hopf_width_median']:.3f} [{min(wh):.3f}, {max(wh):.3f}] | "
                         f"{row['hopf_inside']}/{n} | {row['not_found']} |")
    for base in ("sweep", "descent"):
        if "design" not in table or base not in table:
            continue
        final = table[base][-1]["fold_width_median"]
        need = next((r["step"] for r in table["design"] if r["fold_width_median"] <= final), None)
        table[f"recordings_to_reach_{base}_final_fold_width"] = need
        lines.append("")
        lines.append(f"Design recordings needed to reach the {base}'s final median fold width "
                     f"({final:.3f} m/s after {steps}): "
                     f"{need if need is not None else f'not reached in {steps}'}.")
    return table, "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default=None, help="A:B, noise seeds A..B-1 (default 100:110)")
    ap.add_argument("--steps", type=int, default=None, help="recordings added (default 4)")
    ap.add_argument("--strategies", default=None,
                    help=f"comma-separated subset of {','.join(STRATEGIES)} (default all)")
    ap.add_argument("--delta-mu", type=float, default=DELTA_MU,
                    help=f"the descent's step down in μ, m/s (default {DELTA_MU})")
    ap.add_argument("--smoke", action="store_true",
                    help="the smallest comparison: seed 100, 2 steps, design against descent "
                    "(5 NUTS fits, a few minutes); written to the temporary folder unless "
                    "--out is given")
    ap.add_argument("--out", default=None, help="output stem (.md and .json; default "
                    "benchmarks/design, whose .json goes to results/)")
    ap.add_argument("--resume", action="store_true",
                    help="keep the campaigns already in the output's .json and run only the "
                         "seeds it lacks")
    args = ap.parse_args(argv)
    import tempfile

    from bayeshopf.inference.cache import configure_xla_cpu

    smoke = {"seeds": "100:101", "steps": 2, "strategies": "design,descent",
             "out": str(Path(tempfile.gettempdir()) / "bench_design_smoke")} if args.smoke else {}
    args.seeds = args.seeds or smoke.get("seeds", "100:110")
    args.steps = args.steps or smoke.get("steps", 4)
    args.out = args.out or smoke.get("out", str(OUT / "design"))
    strategies = tuple((args.strategies or smoke.get("strategies", ",".join(STRATEGIES)))
                       .split(","))
    unknown = [x for x in strategies if x not in STRATEGIES]
    if unknown:
        ap.error(f"--strategies: one of {', '.join(STRATEGIES)} expected; found "
                 f"{', '.join(unknown)}")
    configure_xla_cpu()
    a, b = (int(x) for x in args.seeds.split(":"))
    results = []
    stem = Path(args.out)
    # every campaign's rows: beside the table, except the committed table's (to results/)
    raw = RESULTS_DIR / f"{stem.name}.json" if stem == OUT / "design" else stem.with_suffix(".json")
    if args.resume and raw.exists():
        results = [r for r in json.loads(raw.read_text())["results"]
                   if a <= r["seed"] < b]
    done = {r["seed"] for r in results}
    for seed in range(a, b):
        if seed in done:
            continue
        results.append(campaign(seed, args.steps, strategies, args.delta_mu))
        results.sort(key=lambda r: r["seed"])
        table, md = _summary(results, args.steps)
        atomic_write(raw, json.dumps(
            {"settings": {"start": START, "noise": NOISE, "duration_s": DURATION_S,
                          "sample_rate_hz": RATE_HZ, "steps": args.steps,
                          "nuts": "2 chains x (250 warm-up + 300 draws), max tree depth 8",
                          "design_target": "fold", "strategies": list(strategies),
                          "delta_mu": args.delta_mu},
             "summary": table, "results": results}, indent=1))
        atomic_write(stem.with_suffix(".md"), "# Simulated CBC campaigns (bench_design.py)\n\n"
                     + __doc__.split("\n\n")[1].replace("adds 4 recordings",
                                                           f"adds {args.steps} recordings")
                     + "\n\n"
                     + f"Seeds {', '.join(str(r['seed']) for r in results)} "
                     f"({len(results)} campaigns).\n\n"
                     + md + "\n")
    print(_summary(results, args.steps)[1])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
