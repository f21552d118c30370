"""Leave-one-out on simulated rigs of 11 recordings whose model error is large.

Run: ``python benchmarks/bench_loo_simulated_rig.py screen FIRST LAST [--keep N]``, then
``python benchmarks/bench_loo_simulated_rig.py loo SEED MODEL`` for each kept seed and model
of :data:`MODELS`, and ``python benchmarks/bench_loo_simulated_rig.py --summary``.

The question (issue 51): on a rig like the second one bayeshopf has read (11
recordings, 4 stable and 7 held by control-based continuation, relative model
error about 12%), do the bands of held-out recordings hold them, and which
model predicts them best?

**The rigs.** Each seed draws the 3-DOF aerofoil with its uncertain parameters
from their priors and one effect the simulator lacks, written apart from the
detection code (``bench_loo_reference_class.draw_system(seed, effects=True)``,
which keeps a draw with a Hopf point and exactly one fold 1–6 m/s below it). It
is recorded at 4 stable orbits at the fractions :data:`STABLE_AT` of the way
from its fold to its Hopf point and 7 unstable ones at :data:`UNSTABLE_AT`,
20 s at 500 Hz, 1.5% noise, the seed's noise.

**Screening** (``screen``): the model without the discrepancy
(:data:`SCREEN_MODEL`, the default until session 78, whose ``sigma_rel`` is the
whole relative model error) is fitted to all 11 recordings (seed 0); a rig is
*kept* when the posterior median of its relative model error ``sigma_rel`` lies
in :data:`MODEL_ERROR` (about 12%: within a factor of two).
One JSON line per screened seed goes to ``benchmarks/results/loo_simulated_rig_screen.jsonl``.

**Leave-one-out** (``loo``): each recording is held out in turn, the model refitted
on the other 10 (seed 0; each refit's frame without the held-out recording; before
session 79, one frame of all 11) and the held-out amplitude predicted with its 90%
band. Scored as ``bench_loo_rig.py`` scores the rig: inside or not, and the log
predictive density of the measured amplitude (a Gaussian kernel density of the
refit's predictive draws, times the share of draws in which the branch exists),
summed over the 11. One JSON line per (seed, model) goes to
``benchmarks/results/loo_simulated_rig.jsonl``; for ``kernel`` also
``kernel_own``, the same refits scored with the normal form's own branches
(the rig's Hopf point and fold dropped, ``bench_loo_rig.own_branches``).
"""

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _common import RESULTS_DIR, exit_on_help  # noqa: E402

SCREEN = RESULTS_DIR / "loo_simulated_rig_screen.jsonl"
OUT = RESULTS_DIR / "loo_simulated_rig.jsonl"
STABLE_AT = (0.24, 0.51, 0.85, 1.15)
UNSTABLE_AT = (0.12, 0.24, 0.36, 0.5, 0.64, 0.78, 0.9)
NOISE, DURATION_S, RATE_HZ = 0.015, 20.0, 500.0
#: The kept rigs' relative model error (posterior median of ``sigma_rel``, default model).
MODEL_ERROR = (0.06, 0.24)
#: The model a rig is screened with: without the discrepancy, where ``sigma_rel`` is
#: the whole relative model error (with it, only the part independent across recordings).
SCREEN_MODEL = dict(discrepancy=False, nn_width=16, inference="nuts")
#: The settings each model changes from the defaults: "default" is the package's
#: default when run (since session 78 the discrepancy at infinite width, importance
#: sampling; before, the model without it and the σ_rel rule), "s01" the model without
#: the discrepancy under NUTS at the fixed scale 0.1, "kernel" the discrepancy at
#: infinite width under NUTS.
MODELS = {"default": {},
          "s01": dict(discrepancy=False, nn_width=16, inference="nuts", extrapolation_scale=0.1),
          "kernel": dict(discrepancy=True, nn_width=None, inference="nuts")}


def rig(seed: int):
    """The seed's system, diagram and 11 recordings; ``None`` (and why) for a draw not kept."""
    from bench_loo_reference_class import draw_system

    from bayeshopf.simulators import simulate_recordings

    system, diagram, values, why = draw_system(seed, effects=True)
    if diagram is None:
        return None, why, values
    fold, hopf = diagram.folds[0].mu, diagram.hopf.mu
    plan = [(fold + x * (hopf - fold), "stable") for x in STABLE_AT] + \
           [(fold + x * (hopf - fold), "unstable") for x in UNSTABLE_AT]
    try:
        rs = simulate_recordings(system, [m for m, _ in plan], [b for _, b in plan],
                                 noise=NOISE, duration_s=DURATION_S, sample_rate_hz=RATE_HZ,
                                 seed=seed, diagram=diagram)
    except Exception as e:                       # an orbit of the plan not found
        return None, f"{type(e).__name__}: {e}", values
    return rs, "", values


def _append(path: Path, row: dict) -> None:
    path.parent.mkdir(exist_ok=True)
    with path.open("a") as fh:
        fh.write(json.dumps(row, default=float) + "\n")


def screen(first: int, last: int, keep: int) -> None:
    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.posterior import fit_hybrid

    kept = 0
    for seed in range(first, last + 1):
        rs, why, values = rig(seed)
        row = {"seed": seed, "values": values}
        if rs is None:
            _append(SCREEN, {**row, "skipped": why})
            print(seed, "skipped:", why, flush=True)
            continue
        t0 = time.perf_counter()
        post = fit_hybrid(rs, "subcritical", seed=0, progress=False,
                          settings=replace(CollapsedSettings(), **SCREEN_MODEL))
        iv = post.interval("sigma_rel")
        ok = MODEL_ERROR[0] <= iv.median <= MODEL_ERROR[1]
        _append(SCREEN, {**row, "sigma_rel": iv.median, "kept": ok,
                         "wall_s": time.perf_counter() - t0})
        print(seed, f"sigma_rel {iv.median:.3f}", "kept" if ok else "", flush=True)
        kept += ok
        if kept >= keep:
            return


def loo(seed: int, model: str) -> None:
    from bench_loo_rig import score

    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.validation import leave_one_out

    rs, why, _ = rig(seed)
    if rs is None:
        raise SystemExit(f"seed {seed}: {why}")
    settings = replace(CollapsedSettings(), **MODELS[model])
    t0 = time.perf_counter()
    f = extract_harmonics(rs, n_harmonics=settings.n_harmonics,
                          segment_periods=settings.segment_periods)
    folds = leave_one_out(rs, "subcritical", methods=("bayes",), seed=0, settings=settings,
                          keep_fits=True, progress=True)
    wall = time.perf_counter() - t0
    # with the discrepancy, also the same refits with the normal form's own branches
    for name, own in [(model, False)] + ([(model + "_own", True)] if "kernel" in model else []):
        res = {"seed": seed, "model": name, **score(folds, f, own), "wall_s": wall}
        _append(OUT, res)
        print(seed, name, res["inside"], "/", res["n"], "width", res["mean_width"], "lpd",
              res["log_predictive_density"])


def summary() -> None:
    rows = [json.loads(line) for line in OUT.read_text().splitlines()] if OUT.exists() else []
    print("| seed | model | inside | mean width | log predictive density |")
    print("|---:|---|---:|---:|---:|")
    order = [m for k in MODELS for m in (k, k + "_own")]
    for r in sorted(rows, key=lambda r: (r["seed"], order.index(r["model"]))):
        print(f"| {r['seed']} | {r['model']} | {r['inside']}/{r['n']} | "
              f"{r['mean_width']:.4g} | {r['log_predictive_density']:.2f} |")


def main(argv) -> None:
    if argv[:1] == ["--summary"]:
        summary()
    elif argv[:1] == ["screen"]:
        keep = int(argv[argv.index("--keep") + 1]) if "--keep" in argv else 1
        screen(int(argv[1]), int(argv[2]), keep)
    elif argv[:1] == ["loo"] and argv[2] in MODELS:
        loo(int(argv[1]), argv[2])
    else:
        raise SystemExit(__doc__)


if __name__ == "__main__":
    exit_on_help(__doc__)
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu()
    main(sys.argv[1:])
