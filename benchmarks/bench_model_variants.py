"""Model variants on the wind-tunnel rig: the full fit and the leave-one-out of each.

Run: ``python benchmarks/bench_model_variants.py LABEL [--harmonics K]`` with
``PYTHONPATH`` pointing at a copy of bayeshopf with one variant applied, or
``sh benchmarks/model_variants/run.sh`` for all of them (it applies each
``benchmarks/model_variants/<label>.diff`` to a worktree of HEAD; ``baseline``
is HEAD itself, ``fundamental_only`` is HEAD with ``--harmonics 1``).

For one variant, at default settings and seed 0 (2 cores):

* the fit of all 7 recordings: μ0, the fold and ``w`` (90% intervals), every
  recording's orbit error (``HybridPosterior.orbit_error``), and how many
  measured amplitudes lie in their 90% predictive intervals;
* the leave-one-out of ``bench_loo_collapsed.py``: each recording held out,
  the model refitted on the other six, the held-out amplitude against its 90%
  band of a new measurement.

Writes ``benchmarks/model_variants/<LABEL>.json``. These are probes of what the
two bars the rig missed in stop 43 (the leave-one-out and the unstable 16.5 m/s
orbit) respond to; no variant is in the package (``docs/validation.md``). All run
without the control term (``control=False``), as the package then had none.
"""

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from bench_loo_collapsed import held_out_rows

HERE = Path(__file__).parent


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("label")
    ap.add_argument("--harmonics", type=int, default=4)
    args = ap.parse_args()
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu()    # before any JAX work, as the CLI does
    import bayeshopf
    from bayeshopf.data import load_recordings
    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.posterior import fit_hybrid

    rs = load_recordings(HERE.parent.parent / "shared/data/flutter_cbc")
    settings = replace(CollapsedSettings(), n_harmonics=args.harmonics, control=False)
    f = extract_harmonics(rs, n_harmonics=args.harmonics)
    t0 = time.perf_counter()
    post = fit_hybrid(f, "subcritical", seed=0, settings=settings, progress=False)
    ppc = post.ppc()
    full = {
        "wall_s": time.perf_counter() - t0,
        **{k: post.interval(k).to_json() for k in ("mu0", "mu_fold", "w_unfold")},
        "orbit_error": post.orbit_error(),
        "amplitudes_inside": int(sum(iv.contains(a) for iv, a
                                     in zip(ppc.predictive, f.amplitude, strict=True))),
        "hyper": {k: float(np.median(np.asarray(post.samples[k])))
                  for k in ("tau_shape", "sigma_rel", "sigma_h") if k in post.samples},
    }
    print(f"{args.label}: mu0 {full['mu0']}, fold {full['mu_fold']}")
    for e in full["orbit_error"]:
        print(f"  {e['name']:24s} orbit error {100 * e['relative']:5.2f}% "
              f"(spread {100 * e['spread']:4.2f}%) {'ok' if e['ok'] else 'FAIL'}")
    rows = held_out_rows(f, settings)
    n_in = sum(r["inside"] for r in rows)
    width = float(np.mean([r["band"][2] - r["band"][0] for r in rows]))
    print(f"leave-one-out: {n_in}/{len(rows)} inside, mean band width {1e3 * width:.2f} mm")
    out = HERE / "model_variants" / f"{args.label}.json"
    out.write_text(json.dumps({
        "label": args.label, "harmonics": args.harmonics, "seed": 0,
        "bayeshopf": str(Path(bayeshopf.__file__).parent), "full_fit": full,
        "leave_one_out": {"inside": n_in, "of": len(rows), "mean_width": width, "rows": rows},
    }, indent=1))


if __name__ == "__main__":
    main()
