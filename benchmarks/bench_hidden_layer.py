"""What the map's fixed hidden layer decides: the demo refitted with other draws and widths.

Run: ``python benchmarks/bench_hidden_layer.py BLOCK [--widths 16,64,inf] [--discrepancy]``
(``--table``: print the stored rows' tables without fitting).

The map's network has a hidden layer ``(W_1, b_1) ~ N(0, 1)`` drawn once
(:func:`bayeshopf.model.spec.hidden_layer`, ``Settings(nn_width=H, nn_seed=s)``);
only its output layer, prior sd ``ρ τ_s / √H`` per unit, is integrated out. As
``H`` grows the network's prior tends to a Gaussian process whose kernel is the
expectation over the hidden prior (Neal 1996, *Bayesian Learning for Neural
Networks*, ch. 2; Williams 1998, *Computing with infinite networks*), so the
draw ``s`` should matter less, at the cost of ``H`` columns in the collapsed
marginal.

Width ``inf`` is that limit itself (``Settings(nn_width=None)``,
:mod:`bayeshopf.model.network_kernel`): it has no draw, so it is fitted once
per block (at the block's first ``nn_seed``, which it does not read).

Each row (but the ``rig`` block's) is one fit of the demo's recordings
(``flutter_experiment(seed=0)``, what ``bayeshopf demo`` fits) with
``bayeshopf.fit(..., settings=Settings(nn_width=H, nn_seed=s, inference="nuts",
discrepancy=False), seed=0)``, every other setting the default (``--discrepancy``:
``discrepancy=True``), one fit
after another in one process. It records the median and 90% interval of μ0
and the fold, their widths, whether each holds the simulator's value, the wall
time, NUTS's draws per chain, mean leapfrog steps, divergences, the sites
failing R̂/ESS, the log joint density at the MAP (the map integrated out) and
199 posterior quantiles of μ0 and the fold.

Blocks (named before any of their fits ran):

* ``select``: ``nn_seed`` 1–4, ``H`` ∈ {16, 64, 128}. The recommended ``H``
  is the smallest whose ratio max/min over the seeds of the interval width is
  below :data:`RATIO_LIMIT` for μ0 and for the fold.
* ``fresh``: ``nn_seed`` 5–8, at ``H = 16`` and the ``H`` chosen on ``select``
  (``--widths 16,H``), to report the same ratios on draws nobody chose on.
* ``wide``: ``nn_seed`` 9–12 at ``--widths`` (a width beyond ``select``'s, run
  after the fresh block, so that it informs a later registered choice, not
  this one).
* ``rig``: the wind-tunnel recordings (``../shared/data/flutter_cbc``, no
  truth), ``nn_seed`` 1–4 at ``--widths``: the same ratios and the time on a rig.
* ``nuts``: one hidden layer (``nn_seed`` 1, ``--widths H``) fitted with the
  sampler's seeds 1–4: the spread of the widths that the finite NUTS run alone
  gives, against which the ratios above are read.

Rows go to ``benchmarks/results/hidden_layer.json`` (ignored by git), keyed by
block, model and ``(H, s)``; a row already there is not refitted.
"""

import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
OUT = HERE / "results" / "hidden_layer.json"

#: Seeds and widths of each block (fixed before any fit of the block ran).
BLOCKS = {"select": ((1, 2, 3, 4), (16, 64, 128)),
          "fresh": ((5, 6, 7, 8), None),        # widths: 16 and the chosen H (--widths)
          "nuts": ((1,), None),                 # widths: --widths; fit seeds NUTS_SEEDS
          "wide": ((9, 10, 11, 12), None),      # widths: --widths
          "rig": ((1, 2, 3, 4), None)}          # the rig's recordings; widths: --widths
#: The sampler's seeds of the ``nuts`` block (every other block: 0).
NUTS_SEEDS = (1, 2, 3, 4)
#: The selection rule: max/min of the 90% interval's width over the seeds, per H.
RATIO_LIMIT = 1.5
#: Levels of the posterior quantiles stored per row (for pooling draws afterwards).
LEVELS = np.linspace(0.005, 0.995, 199)
QUANTITIES = ("mu0", "mu_fold")


def _read() -> list:
    return json.loads(OUT.read_text()) if OUT.exists() else []


def _write(rows: list) -> None:
    from _common import atomic_write

    atomic_write(OUT, json.dumps(rows, indent=1))


def fit_row(rs, truth: dict, block: str, width: int, seed: int, discrepancy: bool,
            fit_seed: int = 0) -> dict:
    """One fit and its record."""
    import bayeshopf as bh

    settings = bh.Settings(nn_width=None if width == "inf" else width, nn_seed=seed,
                           discrepancy=discrepancy, inference="nuts")
    t0 = time.perf_counter()
    fit = bh.fit(rs, settings=settings, seed=fit_seed, progress=False)
    wall = time.perf_counter() - t0
    post = fit.diagnostics.details["posterior"]
    sites = post.get("sites", {})
    row = {"block": block, "model": "discrepancy" if discrepancy else "default",
           "width": width, "seed": seed, "fit_seed": fit_seed, "wall_s": round(wall, 2),
           "timings": {k: round(float(v), 2) for k, v in fit.posterior.timings.items()
                       if isinstance(v, (int, float))},
           "divergences": int(post.get("divergences", 0)),
           "failing_sites": sorted(k for k, v in sites.items() if not v["ok"]),
           "max_r_hat": max((v["r_hat"] for v in sites.values()), default=float("nan")),
           "min_ess_bulk": min((v["ess_bulk"] for v in sites.values()), default=float("nan")),
           "sampler": {k: v for k, v in post.items()
                       if k in ("draws_per_chain", "leapfrog_steps_draws",
                                "leapfrog_steps_warmup")}}
    row["map_log_joint"] = float(fit.posterior.map_point.log_joint)
    for k in QUANTITIES:
        row[f"{k}_quantiles"] = np.quantile(fit.posterior.samples[k], LEVELS).tolist()
        iv = fit.interval(k)
        row[k] = [iv.median, iv.lo, iv.hi]
        row[f"{k}_width"] = iv.hi - iv.lo
        if truth is not None:
            row[f"{k}_true"] = truth[k]
            row[f"{k}_holds"] = bool(iv.lo <= truth[k] <= iv.hi)
    return row


def _key(r: dict) -> tuple:
    return r["block"], r["model"], r["width"], r["seed"], r.get("fit_seed", 0)


def _width_order(h) -> tuple:
    """Finite widths in order, then ``"inf"`` (the network's limit)."""
    return (h == "inf", 0 if h == "inf" else h)


def ratios(rows: list, block: str, model: str) -> dict:
    """Per H: max/min over the seeds of each quantity's interval width, and the mean wall time."""
    out = {}
    for h in sorted({r["width"] for r in rows if r["block"] == block and r["model"] == model},
                    key=_width_order):
        sel = [r for r in rows if r["block"] == block and r["model"] == model
               and r["width"] == h]
        out[h] = {"seeds": sorted(r["seed"] if block != "nuts" else r["fit_seed"] for r in sel),
                  "wall_s_mean": float(np.mean([r["wall_s"] for r in sel]))}
        for k in QUANTITIES:
            w = np.array([r[f"{k}_width"] for r in sel])
            out[h][f"{k}_ratio"] = float(w.max() / w.min())
    return out


def table(rows: list) -> str:
    """Markdown tables of every block and model present."""
    lines = []
    for block in BLOCKS:
        for model in ("default", "discrepancy"):
            sel = [r for r in rows if r["block"] == block and r["model"] == model]
            if not sel:
                continue
            lines += [f"### block {block}, model {model}", "",
                      "| H | nn_seed | fit seed | μ0 median [90%] | width | fold median [90%] "
                      "| width | wall s | draws/chain | leapfrog | NUTS |", "|" + "---|" * 11]
            for r in sorted(sel, key=lambda r: (_width_order(r["width"]), r["seed"],
                                                r.get("fit_seed", 0))):
                cells = [str(r["width"]), str(r["seed"]), str(r.get("fit_seed", 0))]
                for k in QUANTITIES:
                    m, lo, hi = r[k]
                    miss = "" if r.get(f"{k}_holds", True) else " (misses)"
                    cells += [f"{m:.4f} [{lo:.4f}, {hi:.4f}]{miss}", f"{hi - lo:.4f}"]
                s = r["sampler"]
                cells += [f"{r['wall_s']:.0f}", str(s.get("draws_per_chain", "")),
                          f"{s.get('leapfrog_steps_draws', float('nan')):.0f}",
                          "ok" if not r["failing_sites"] and not r["divergences"]
                          else " ".join(r["failing_sites"] + [f"{r['divergences']} div"])]
                lines.append("| " + " | ".join(cells) + " |")
            seeds = "fit seeds" if block == "nuts" else "nn_seeds"
            lines += ["", f"| H | {seeds} | μ0 width max/min | fold width max/min | mean wall s |",
                      "|---|---|---|---|---|"]
            for h, v in ratios(rows, block, model).items():
                lines.append(f"| {h} | {v['seeds']} | {v['mu0_ratio']:.2f} | "
                             f"{v['mu_fold_ratio']:.2f} | {v['wall_s_mean']:.0f} |")
            lines.append("")
    return "\n".join(lines)


def main(argv: list[str]) -> None:
    if "--table" in argv:
        print(table(_read()))
        return
    if not argv or argv[0] not in BLOCKS:
        raise SystemExit(f"bench_hidden_layer: BLOCK expected, one of {', '.join(BLOCKS)}; "
                         f"got {argv[:1]!r}")
    block = argv[0]
    seeds, widths = BLOCKS[block]
    if "--widths" in argv:
        widths = tuple(v if v == "inf" else int(v)
                       for v in argv[argv.index("--widths") + 1].split(","))
    if widths is None:
        raise SystemExit(f"bench_hidden_layer: --widths expected for the {block} block "
                         "(H chosen on the select block); got none")
    fit_seeds = NUTS_SEEDS if block == "nuts" else (0,)
    discrepancy = "--discrepancy" in argv
    model = "discrepancy" if discrepancy else "default"
    if block == "rig":
        from _common import rig_recordings

        rs, truth = rig_recordings(), None
        if rs is None:
            raise SystemExit(1)
    else:
        from bayeshopf.simulators.truth import flutter_experiment

        rs, truth = flutter_experiment(seed=0)
        truth = truth.values()
        print(f"truth: {truth}", flush=True)
    for h in widths:
        for s in (seeds[:1] if h == "inf" else seeds):      # the limit has no draw
            for f in fit_seeds:
                if any(_key(r) == (block, model, h, s, f) for r in _read()):
                    continue
                row = fit_row(rs, truth, block, h, s, discrepancy, f)
                print(json.dumps(row), flush=True)
                _write(_read() + [row])
    print(table(_read()))


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    main(sys.argv[1:])
