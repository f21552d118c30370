"""Coverage and interval score of μ0 and the fold on simulated rigs with structural error.

Run: ``python benchmarks/bench_discrepancy_coverage.py FIRST LAST [--designs
paired,short,sweep] [--models discrepancy,plain]`` (or ``--seeds 1200,1206,…`` for
chosen seeds); ``--summary [FIRST LAST] [--seeds …] [--models …] [--warned-by MODEL]``
(``--agree REF,OTHER``: also how often OTHER's intervals agree with REF's, set by set)
prints the table of what finished, over the sets that every listed model fitted, with
each coverage's 90% Clopper–Pearson interval (and, with ``kernel_w``, the misses among
the sets its fit's window check flags), and each model's coverage, width and score among
the fits that warn of a relative model error above the limit and among the rest
(``--warned-by MODEL``: every model's sets grouped by that model's warning), and
among the sets whose effect is dry friction and among the rest.

Each seed draws the 3-DOF aerofoil with its uncertain parameters from their priors
(a few percent off nominal) and one effect the simulator lacks, written apart from
the detection code (``bench_loo_reference_class.draw_system(seed, effects=True)``;
the truth is that system's own continuation). It is recorded in three designs,
then fitted by each model of :data:`MODELS` (``plain``: without the model
discrepancy, 16 hidden units; ``discrepancy``: with it; ``kernel`` and
``kernel_plain``: the same two with the map's network at infinite width,
``nn_width=None``; ``kernel_scale``: ``kernel`` with the network's input scale
on μ learned; ``kernel_nu3``: that scale fixed at 3; ``kernel_h``: ``kernel`` with
the horizontal discrepancy, ``unfolding="horizontal"``; ``kernel_w``: ``kernel`` with
the window at the fold, ``unfolding="window"``; ``kernel_f``: ``kernel`` with the
discrepancy's floor ``κ = 1`` near the Hopf point, ``discrepancy_floor=1``;
``kernel_s``: ``kernel``, its row also holding the intervals of μ0 and the fold under
the discrepancy in μ of :mod:`bayeshopf.model.bifurcation_shift` for each ``κ`` of
:data:`KAPPAS`, read by ``--summary`` as models ``kernel_s@κ``, and at ``κ = 2`` with the
floors of :data:`FLOORS` on the scale in μ, ``kernel_s@2fφ`` (both points) and
``kernel_s@2hφ`` (the Hopf point only); ``kernel_s_is``: ``kernel_s`` with the
posterior by importance sampling (``inference="importance"``; its rows record whether
the check passed, ``method``, and k̂), read as ``kernel_s_is@…``; every other setting
the default):

* ``paired``: 4 stable and 3 unstable orbits across the fold–Hopf gap, 20 s at
  500 Hz, 1.5% noise (the reference class's design);
* ``short``: the same orbits, 2 s at 1 kHz (a few periods, one or two segments);
* ``sweep``: 5 stable orbits and 2 unstable ones in the lower half of the gap
  (none near the Hopf point), 20 s at 500 Hz;
* ``dense`` (a diagnostic, not in the default list): 8 stable and 8 unstable
  orbits from 0.08 to 1.15 of the gap, 20 s at 500 Hz: what is left when
  little has to be extrapolated.

For μ0 and the fold it records the 90% interval, whether it holds the truth, and
the interval score ``(hi − lo) + 20·dist(truth, [lo, hi])`` (Gneiting & Raftery
2007; the proper score of a central 90% interval). One JSON line per (seed,
design, model) is appended to ``benchmarks/results/discrepancy_coverage.jsonl``;
a rerun skips what is there (with each fit's divergent transitions and leapfrog
steps). ``BENCH_PROGRESS=1`` shows each fit's stages as they run.
"""

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _common import RESULTS_DIR  # noqa: E402

OUT = RESULTS_DIR / "discrepancy_coverage.jsonl"
DESIGNS = {
    "paired": dict(stable=(0.24, 0.51, 0.85, 1.15), unstable=(0.24, 0.54, 0.85),
                   duration_s=20.0, rate_hz=500.0),
    "short": dict(stable=(0.24, 0.51, 0.85, 1.15), unstable=(0.24, 0.54, 0.85),
                  duration_s=2.0, rate_hz=1000.0),
    "sweep": dict(stable=(0.15, 0.4, 0.65, 0.9, 1.15), unstable=(0.2, 0.45),
                  duration_s=20.0, rate_hz=500.0),
    "dense": dict(stable=(0.1, 0.25, 0.4, 0.55, 0.7, 0.85, 1.0, 1.15),
                  unstable=(0.08, 0.2, 0.32, 0.44, 0.56, 0.68, 0.8, 0.92),
                  duration_s=20.0, rate_hz=500.0),
}
#: The designs run when ``--designs`` is not given.
DEFAULT_DESIGNS = ("paired", "short", "sweep")
#: The settings each model changes from the defaults (every model under NUTS unless it
#: says otherwise; "plain" is the model that was the default before session 78).
MODELS = {"plain": dict(discrepancy=False, nn_width=16),
          "discrepancy": dict(discrepancy=True, nn_width=16),
          "kernel": dict(discrepancy=True, nn_width=None),
          "kernel_plain": dict(discrepancy=False, nn_width=None),
          "kernel_scale": dict(discrepancy=True, nn_width=None, nn_mu_scale=None),
          "kernel_nu3": dict(discrepancy=True, nn_width=None, nn_mu_scale=3.0),
          "kernel_h": dict(discrepancy=True, nn_width=None, unfolding="horizontal"),
          "kernel_w": dict(discrepancy=True, nn_width=None, unfolding="window"),
          "kernel_f": dict(discrepancy=True, nn_width=None, discrepancy_floor=1.0),
          "kernel_s": dict(discrepancy=True, nn_width=None),
          "kernel_s_is": dict(discrepancy=True, nn_width=None, inference="importance")}
#: The sizes ``κ`` of the discrepancy in μ at the Hopf point and the fold
#: (:mod:`bayeshopf.model.bifurcation_shift`) whose intervals a ``kernel_s`` row holds;
#: ``--summary --models kernel_s@2`` reads them as a model of their own.
KAPPAS = (1.0, 2.0, 4.0, 8.0)
#: Floors ``φ`` of the scale in μ: ``κ√(η² + φ²)G h`` instead of ``κηG h`` (the error of
#: an extrapolation that the recordings' own misfit ``η`` does not show), at ``κ`` =
#: :data:`FLOOR_KAPPA`, on both points (``kernel_s@2f0.05``) or on the Hopf point only
#: (``kernel_s@2h0.05``); post hoc, from the same draws and normal pairs as ``kernel_s@2``.
FLOORS = (0.025, 0.05, 0.1)
FLOOR_KAPPA = 2.0
NOISE = 0.015
ALPHA = 0.1


def interval_score(lo, hi, x, alpha=ALPHA) -> float:
    """``(hi − lo) + (2/α)[(lo − x)⁺ + (x − hi)⁺]``."""
    return float((hi - lo) + 2 / alpha * (max(lo - x, 0.0) + max(x - hi, 0.0)))


def recordings(system, diagram, design: str, seed: int):
    from bayeshopf.simulators import simulate_recordings

    d = DESIGNS[design]
    fold, hopf = diagram.folds[0].mu, diagram.hopf.mu
    plan = [(fold + x * (hopf - fold), "stable") for x in d["stable"]] + \
           [(fold + x * (hopf - fold), "unstable") for x in d["unstable"]]
    return simulate_recordings(system, [m for m, _ in plan], [b for _, b in plan], noise=NOISE,
                               duration_s=d["duration_s"], sample_rate_hz=d["rate_hz"],
                               seed=seed, diagram=diagram)


def fit_one(rs, model: str) -> dict:
    from dataclasses import replace

    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.posterior import fit_hybrid

    # the normal form's own Hopf point and fold (kernel_s's rows add the moved ones)
    settings = replace(CollapsedSettings(), **{"mu_discrepancy": 0.0, "inference": "nuts",
                                               **MODELS[model]})
    t0 = time.perf_counter()
    post = fit_hybrid(rs, "subcritical", seed=0, settings=settings,
                      progress=bool(os.environ.get("BENCH_PROGRESS")))
    out = {"wall_s": time.perf_counter() - t0, "warnings": post.diagnostics["warnings"],
           "divergences": int(post.run.divergences), "sampler": post.run.sampler,
           "method": post.run.method}
    for k in ("mu0", "mu_fold", "eta", "sigma_rel", "eta_h", "ell_h", "depth_h", "width_h"):
        iv = post.interval(k)
        if iv is not None:
            out[k] = {"median": iv.median, "lo": iv.lo, "hi": iv.hi}
    if model.startswith("kernel_s"):
        out["shift"] = shifted_intervals(post)
    return out


def shifted_intervals(post) -> dict:
    """90% intervals of μ0 and the fold under the discrepancy in μ, per κ of :data:`KAPPAS`."""
    import jax

    from bayeshopf.diagnostics.summaries import interval
    from bayeshopf.model.bifurcation_shift import shift_draws

    f = post.features
    sign = np.where(f.unstable, -1.0, 1.0)
    out = {}
    draws = {}
    for kappa in KAPPAS:
        draws[str(kappa)] = shift_draws(post.spec, post.theta, f.mu, sign, kappa,
                                        jax.random.PRNGKey(0))
    plain = draws[str(FLOOR_KAPPA)]            # the same normal pairs as every variant
    for phi in FLOORS:
        d = shift_draws(post.spec, post.theta, f.mu, sign, FLOOR_KAPPA, jax.random.PRNGKey(0),
                        floor=phi)
        draws[f"{FLOOR_KAPPA:g}f{phi:g}"] = d
        draws[f"{FLOOR_KAPPA:g}h{phi:g}"] = {**plain, "mu0": d["mu0"]}
    for key, d in draws.items():
        out[key] = {}
        for k, v in d.items():
            iv = interval(v, 1 - ALPHA)
            out[key][k] = {"median": iv.median, "lo": iv.lo, "hi": iv.hi}
    return out


def expand_shifts(rows) -> list:
    """Each ``kernel_s`` (``kernel_s_is``) row also as ``kernel_s@κ`` (``@0``: the model's own)."""
    out = list(rows)
    for r in rows:
        model = r.get("model", "")
        if not model.startswith("kernel_s") or "shift" not in r:
            continue
        out.append({**r, "model": f"{model}@0"})
        for kappa, ivs in r["shift"].items():
            name = f"{float(kappa):g}" if kappa.replace(".", "").isdigit() else kappa
            row = {**r, "model": f"{model}@{name}"}
            for k, iv in ivs.items():
                t = r["truth"][k]
                row[k] = {**iv, "inside": bool(iv["lo"] <= t <= iv["hi"]),
                          "score": interval_score(iv["lo"], iv["hi"], t)}
            out.append(row)
    return out


def run(seeds, designs, models) -> None:
    from bench_loo_reference_class import draw_system

    OUT.parent.mkdir(parents=True, exist_ok=True)
    done = set()
    if OUT.exists():
        for line in OUT.read_text().splitlines():
            r = json.loads(line)
            done.add((r["seed"], r["design"], r["model"]))
    for seed in seeds:
        todo = [(d, m) for d in designs for m in models if (seed, d, m) not in done]
        if not todo:
            continue
        system, diagram, values, why = draw_system(seed, effects=True)
        if diagram is None:
            print(seed, "skipped:", why, flush=True)
            continue
        truth = {"mu0": diagram.hopf.mu, "mu_fold": diagram.folds[0].mu}
        by_design = {}
        for design, model in todo:
            if design not in by_design:
                try:
                    by_design[design] = recordings(system, diagram, design, seed)
                except Exception as e:            # a design's orbit this system lacks
                    by_design[design] = f"{type(e).__name__}: {e}"
            if isinstance(by_design[design], str):
                print(seed, design, "skipped:", by_design[design], flush=True)
                continue
            try:
                res = fit_one(by_design[design], model)
            except Exception as e:                                     # record, go on
                res = {"error": f"{type(e).__name__}: {e}"}
            row = {"seed": seed, "design": design, "model": model, "truth": truth,
                   "effect": values.get("effect"), **res}
            for k in ("mu0", "mu_fold"):
                if k in res:
                    lo, hi = res[k]["lo"], res[k]["hi"]
                    row[k]["inside"] = bool(lo <= truth[k] <= hi)
                    row[k]["score"] = interval_score(lo, hi, truth[k])
            with OUT.open("a") as f:
                f.write(json.dumps(row, default=float) + "\n")
            print(seed, design, model, {k: row[k].get("inside") for k in ("mu0", "mu_fold")
                                        if k in row}, f"{res.get('wall_s', 0):.0f} s", flush=True)


def clopper_pearson(k: int, n: int, level: float = 0.9) -> tuple[float, float]:
    """The central ``level`` Clopper–Pearson interval of a binomial proportion ``k/n``."""
    from scipy.stats import beta

    a = (1 - level) / 2
    return (float(beta.ppf(a, k, n - k + 1)) if k > 0 else 0.0,
            float(beta.ppf(1 - a, k + 1, n - k)) if k < n else 1.0)


def _fitted_by_all(rows, design: str, models) -> tuple[dict, list]:
    """``design``'s rows by ``(seed, model)``, and the seeds every one of ``models`` fitted."""
    at = {(r["seed"], r["model"]): r for r in rows if r["design"] == design}
    return at, sorted({s for s, _ in at if all((s, m) in at for m in models)})


def summary(seeds=None, models=None, warned_by=None) -> None:
    """The table of what finished: per design, the sets every listed model fitted."""
    rows = [json.loads(x) for x in OUT.read_text().splitlines()] if OUT.exists() else []
    rows = expand_shifts([r for r in rows if "mu0" in r and (seeds is None or r["seed"] in seeds)])
    models = models or list(MODELS)
    print("| design | model | sets | μ0 inside (90% CP) | μ0 width | μ0 score | "
          "fold inside (90% CP) | fold width | fold score |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for design in DESIGNS:
        by, common = _fitted_by_all(rows, design, models)
        for model in models:
            sub = [by[(s, model)] for s in common]
            if not sub:
                continue
            cells = []
            for k in ("mu0", "mu_fold"):
                inside = sum(r[k]["inside"] for r in sub)
                lo, hi = clopper_pearson(inside, len(sub))
                width = np.mean([r[k]["hi"] - r[k]["lo"] for r in sub])
                score = np.mean([r[k]["score"] for r in sub])
                cells += [f"{inside}/{len(sub)} ({lo:.2f}–{hi:.2f})", f"{width:.3f}",
                          f"{score:.3f}"]
            print(f"| {design} | {model} | {len(sub)} | " + " | ".join(cells) + " |")
    flagged_misses(rows, models)
    warned_split(rows, models, warned_by)
    effect_split(rows, models)


#: The fit check's warning that the model misses the orbits (relative model error above
#: the limit, :mod:`bayeshopf.diagnostics.fit_checks`), as it begins in every model.
WARNING = "relative model error"


def warned_split(rows, models, by: str | None = None) -> None:
    """Coverage among the fits the relative-model-error warning names, and among the rest.

    Per design and model, over the sets every listed model fitted: how many
    fits carry the warning (:data:`WARNING`), and, in each group, how many of
    the 90% intervals of μ0 and the fold hold the truth, their mean width and
    mean interval score. ``by``: group every model's sets by that model's
    warning (the same sets for all), instead of each model's own.
    """
    grouped = f"the warning of {by}" if by else "each fit's own warning"
    _two_groups(rows, models, grouped, ("warned", "not warned"),
                lambda at, s, model: any(WARNING in w for w in at[(s, by or model)]["warnings"]))


#: The effects of dry friction (a Stribeck law on heave or pitch), whose regularised
#: damping at rest moves the Hopf point above where the orbits' sizes head to zero.
DRY_FRICTION = ("heave_stribeck_friction", "pitch_stribeck_friction")


def effect_split(rows, models) -> None:
    """Coverage among the sets whose effect is dry friction (:data:`DRY_FRICTION`) and
    among the rest, per design and model, over the sets every listed model fitted."""
    _two_groups(rows, models, "the effect", ("dry friction", "other effects"),
                lambda at, s, model: at[(s, model)]["effect"] in DRY_FRICTION)


def _two_groups(rows, models, title: str, names: tuple[str, str], first) -> None:
    """Per design and model, :func:`_cell` of the sets where ``first(at, seed, model)``
    holds and of the rest, over the sets every listed model fitted."""
    print(f"\nGrouped by {title} (sets; μ0 inside, mean width, mean score; the fold's "
          f"the same):\n\n| design | model | {names[0]} | {names[1]} |\n|---|---|---|---|")
    for design in DESIGNS:
        at, common = _fitted_by_all(rows, design, models)
        for model in models:
            if not common:
                continue
            cells = [_cell([at[(s, model)] for s in common if first(at, s, model) == group])
                     for group in (True, False)]
            print(f"| {design} | {model} | {cells[0]} | {cells[1]} |")


def _cell(sub) -> str:
    """A group's size and, per point, how many hold the truth, the mean width and score."""
    if not sub:
        return "0"
    parts = [f"{sum(r[k]['inside'] for r in sub)}, "
             f"{np.mean([r[k]['hi'] - r[k]['lo'] for r in sub]):.3f}, "
             f"{np.mean([r[k]['score'] for r in sub]):.3f}" for k in ("mu0", "mu_fold")]
    return f"{len(sub)}; μ0 {parts[0]}; fold {parts[1]}"


#: The largest gap between two methods' interval ends, as a fraction of the reference's
#: width, at which they agree (the package's rule for SVI against NUTS).
AGREE = 0.25


def agreement(rows, ref: str, other: str) -> None:
    """Per design, how often ``other``'s 90% intervals agree with ``ref``'s, set by set.

    Agree: both ends within :data:`AGREE` of ``ref``'s width. Also the largest
    gap, and for ``other`` how many fits its posterior method ran (importance
    sampling, or NUTS after a failed check).
    """
    print(f"\nAgreement of {other} with {ref} (ends within {AGREE:.0%} of {ref}'s width):\n\n"
          "| design | sets | μ0 agree | μ0 largest gap | fold agree | fold largest gap | "
          "method of " + other + " |\n|---|---:|---:|---:|---:|---:|---|")
    for design in DESIGNS:
        at, common = _fitted_by_all(rows, design, (ref, other))
        if not common:
            continue
        cells = []
        for k in ("mu0", "mu_fold"):
            gaps = [max(abs(at[(s, other)][k]["lo"] - at[(s, ref)][k]["lo"]),
                        abs(at[(s, other)][k]["hi"] - at[(s, ref)][k]["hi"]))
                    / (at[(s, ref)][k]["hi"] - at[(s, ref)][k]["lo"]) for s in common]
            cells += [f"{sum(g <= AGREE for g in gaps)}/{len(gaps)}", f"{max(gaps):.0%}"]
        methods = [at[(s, other)].get("method", "?") for s in common]
        counts = ", ".join(f"{m} {methods.count(m)}" for m in sorted(set(methods)))
        print(f"| {design} | {len(common)} | " + " | ".join(cells) + f" | {counts} |")


def flagged_misses(rows, models) -> None:
    """Misses among the window's fits the fit's check flags and among the rest.

    The check: ``|median A|`` above
    :data:`~bayeshopf.diagnostics.fit_checks.WINDOW_DEPTH_SDS_MAX` prior SDs
    (:func:`~bayeshopf.diagnostics.fit_checks.fold_window_check`), read from
    each row's ``depth_h``; over the sets every listed model fitted.
    """
    from bayeshopf.diagnostics.fit_checks import WINDOW_DEPTH_SDS_MAX
    from bayeshopf.model.horizontal import WINDOW_DEPTH_PRIOR

    if "kernel_w" not in models:
        return
    by = {(r["seed"], r["design"], r["model"]): r for r in rows}
    sets = [k[:2] for k in by if k[2] == "kernel_w" and all(k[:2] + (m,) in by for m in models)]
    for flag in (True, False):
        sub = [by[s + ("kernel_w",)] for s in sorted(sets)
               if (abs(by[s + ("kernel_w",)]["depth_h"]["median"])
                   > WINDOW_DEPTH_SDS_MAX * WINDOW_DEPTH_PRIOR) == flag]
        miss = {k: sum(not r[k]["inside"] for r in sub) for k in ("mu0", "mu_fold")}
        names = ", ".join(f"{r['seed']}/{r['design']}" for r in sub) if flag else ""
        print(f"kernel_w {'flagged' if flag else 'not flagged'}: {len(sub)} sets {names}; "
              f"misses: μ0 {miss['mu0']}, fold {miss['mu_fold']}")


def main(argv):
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu()
    seeds = None
    if "--seeds" in argv:
        i = argv.index("--seeds")
        seeds = [int(a) for a in argv[i + 1].split(",")]
        argv = argv[:i] + argv[i + 2:]
    bounds = [int(a) for a in argv[:2] if a.isdigit()]
    if seeds is None and len(bounds) == 2:
        seeds = list(range(bounds[0], bounds[1] + 1))
    designs = (argv[argv.index("--designs") + 1].split(",") if "--designs" in argv
               else list(DEFAULT_DESIGNS))
    models = (argv[argv.index("--models") + 1].split(",") if "--models" in argv
              else None)
    unknown = [m for m in models or () if m.split("@")[0] not in MODELS]
    if unknown:
        sys.exit(f"--models: expected some of {', '.join(MODELS)}; got {', '.join(unknown)}")
    by = argv[argv.index("--warned-by") + 1] if "--warned-by" in argv else None
    if by is not None and by not in (models or ()):
        sys.exit(f"--warned-by: one of the --models expected; got {by}")
    if "--summary" in argv:
        summary(None if seeds is None else set(seeds), models, by)
        if "--agree" in argv:
            ref, other = argv[argv.index("--agree") + 1].split(",")
            rows = [json.loads(x) for x in OUT.read_text().splitlines()]
            agreement(expand_shifts([r for r in rows if "mu0" in r and (
                seeds is None or r["seed"] in seeds)]), ref, other)
        return
    run(seeds, designs, models or ["plain", "discrepancy"])


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    main(sys.argv[1:])
