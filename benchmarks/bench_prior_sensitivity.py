"""Prior sensitivity of the Hopf point and the fold: refits with one hyperprior changed.

Run: ``python benchmarks/bench_prior_sensitivity.py [rig|demo] [--only TEXT]`` (default
``rig``; ``--only``: refit the variants whose label holds ``TEXT``, keep the stored others;
``--table``: rewrite the table from the stored rows).
Each variant scales one prior's scale by 0.5 or 2 (the unfolding's curvature:
sd 3, as a user might widen it) or draws the map's fixed hidden layer with
another seed, refits (seed 0, default settings, the persistent
compilation cache off so that no program of another prior is reused) with the
model discrepancy (``CollapsedSettings(discrepancy=True)``) and records
the median and 90% interval of μ0 and the fold. ``rig``: the wind-tunnel
recordings (``../shared/data/flutter_cbc``); ``demo``: ``flutter_experiment(seed=0)``.
Regenerates ``benchmarks/prior_sensitivity_<data>.md``, the table
``docs/model_discrepancy.md`` quotes; the raw rows go to
``benchmarks/results/prior_sensitivity_<data>.json``.
"""

import json
import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

os.environ["BAYESHOPF_CACHE_DIR"] = "off"      # priors are module constants, not in the key

HERE = Path(__file__).resolve().parent
RIG = HERE.parents[1] / "shared" / "data" / "flutter_cbc"

#: (label, module, constant, value as a function of the default)
VARIANTS = [
    ("default", None, None, None),
    ("η scale × 0.5", "discrepancy", "ETA_PRIOR", lambda v: 0.5 * v),
    ("η scale × 2", "discrepancy", "ETA_PRIOR", lambda v: 2 * v),
    ("ℓ median × 0.5", "discrepancy", "LENGTH_PRIOR", lambda v: (0.5 * v[0], v[1])),
    ("ℓ median × 2", "discrepancy", "LENGTH_PRIOR", lambda v: (2 * v[0], v[1])),
    ("σ_rel scale × 0.5", "collapsed", "SIGMA_REL_PRIOR", lambda v: 0.5 * v),
    ("σ_rel scale × 2", "collapsed", "SIGMA_REL_PRIOR", lambda v: 2 * v),
    ("w sd 3", "collapsed", "UNFOLDING_PRIOR_SD", lambda v: 3.0),
    ("gaps × 0.5", "collapsed", "GAP_PRIOR", lambda v: 0.5 * v),
    ("gaps × 2", "collapsed", "GAP_PRIOR", lambda v: 2 * v),
    ("τ_μ median × 0.5", "collapsed", "TAU_MU_PRIOR", lambda v: (0.5 * v[0], v[1])),
    ("τ_μ median × 2", "collapsed", "TAU_MU_PRIOR", lambda v: (2 * v[0], v[1])),
    ("hidden layer seed 1", "settings", "nn_seed", lambda v: 1),
    ("hidden layer seed 2", "settings", "nn_seed", lambda v: 2),
]


def main(argv):
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu()
    import bayeshopf.model.collapsed as cm
    import bayeshopf.model.discrepancy as dm
    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.posterior import fit_hybrid

    if "--table" in argv:
        data = next((a for a in argv if a in ("rig", "demo")), "rig")
        table(data, json.loads((HERE / "results" / f"prior_sensitivity_{data}.json").read_text()))
        return
    only = argv[argv.index("--only") + 1] if "--only" in argv else None
    argv = [a for i, a in enumerate(argv) if a != "--only" and (i == 0 or argv[i - 1] != "--only")]
    data = argv[0] if argv else "rig"
    if data == "rig":
        from bayeshopf.data import load_recordings

        rs = load_recordings(RIG)
    else:
        from bayeshopf.simulators.truth import flutter_experiment

        rs, _ = flutter_experiment(seed=0)
    modules = {"discrepancy": dm, "collapsed": cm}
    raw = HERE / "results" / f"prior_sensitivity_{data}.json"
    kept = {r["variant"]: r for r in json.loads(raw.read_text())} if only and raw.exists() else {}
    rows = []
    for label, mod, name, change in VARIANTS:
        if only is not None and only not in label and label in kept:
            rows.append(kept[label])
            continue
        old = None
        settings = CollapsedSettings(discrepancy=True)
        if mod == "settings":
            settings = replace(settings, **{name: change(getattr(settings, name))})
        elif mod is not None:
            old = getattr(modules[mod], name)
            setattr(modules[mod], name, change(old))
        try:
            post = fit_hybrid(rs, "subcritical", seed=0, progress=False, settings=settings)
        finally:
            if mod is not None and mod != "settings":
                setattr(modules[mod], name, old)
        row = {"variant": label}
        for k in ("mu0", "mu_fold", "eta"):
            iv = post.interval(k)
            row[k] = [iv.median, iv.lo, iv.hi]
        rows.append(row)
        print(label, row, flush=True)
    (HERE / "results").mkdir(exist_ok=True)
    raw.write_text(json.dumps(rows, indent=1))
    table(data, rows)


def _fmt(iv) -> str:
    """``median [lo, hi]`` with enough decimals to show the interval's width."""
    decimals = max(2, int(np.ceil(-np.log10(max(iv[2] - iv[1], 1e-9)))) + 1)
    return f"{iv[0]:.{decimals}f} [{iv[1]:.{decimals}f}, {iv[2]:.{decimals}f}]"


def table(data: str, rows: list) -> None:
    """Write ``prior_sensitivity_<data>.md`` from the rows."""
    lines = [f"# Prior sensitivity ({data}, seed 0)", "",
             "Regenerated by `python benchmarks/bench_prior_sensitivity.py "
             f"{data}`: one prior changed at a time, medians and 90% intervals.", "",
             "| variant | μ0 | fold | η |", "|---|---|---|---|"]
    for r in rows:
        cells = [_fmt(r[k]) for k in ("mu0", "mu_fold")]
        eta = r["eta"]
        cells.append(f"{100 * eta[0]:.2g}% [{100 * eta[1]:.2g}, {100 * eta[2]:.2g}]")
        lines.append(f"| {r['variant']} | " + " | ".join(cells) + " |")
    (HERE / f"prior_sensitivity_{data}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    main(sys.argv[1:])
