"""The rig's CBC control: what its residual fundamental is, and what the control term buys.

Run: ``python benchmarks/bench_rig_control.py`` (about 1 min on 2 cores with a warm
cache). Writes ``benchmarks/rig_control.json``; ``docs/validation.md`` cites it.
On the 7 recordings in ``../shared/data/flutter_cbc``:

1. **The actuator command** (row 2 of ``data``, the rig description's control
   channel). Over each whole record, at the record's frequency: its fundamental
   (V), its phase against the heave's crest, the heave's fundamental (mm), and
   its harmonics 2–4 relative to its fundamental; the features' ``control``
   (the same fundamental, fitted on their segments and time origin).
2. **The fit with and without the control term** (default settings, seed 0;
   ``CollapsedSettings.control``): μ0, the fold and ``w``, every orbit error
   (with its parts by harmonic), the amplitudes inside their 90% bands, the
   NUTS checks, and PSIS-LOO over the recordings (``arviz.loo`` on each fit's
   ``log p(y_i | y_−i, θ)``, ``arviz.compare`` for the difference and its
   standard error). With seven recordings each one moves the posterior, so the
   Pareto k exceed 0.7 and the ELPD is approximate (stored with it).
3. **The gain** ``H`` of the second frame axis (90% intervals of its real and
   imaginary parts) and, per recording, the size of ``H U_i`` against the
   measured fundamental of ``w2``.
4. **Other seeds** (1–4, with the term): every orbit error, whether all seven
   meet the bar, μ0 and the fold; the chains differ, the model does not.
"""

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
DATA = HERE.parent.parent / "shared/data/flutter_cbc"


def part_actuator(rs, f):
    from bayeshopf.features.harmonics import time_design

    K = 4
    rows = []
    for i, rec in enumerate(rs):
        t = rec.t - rec.t[0]
        A = time_design(t, f.omega[i], K)
        c = np.linalg.lstsq(A, np.column_stack([rec.channel("h"), rec.channel("actuator")]),
                            rcond=None)[0].T                              # (2, 2K+1)
        amp = np.hypot(c[:, 1:K + 1], c[:, K + 1:])                         # (2, K)
        phase = np.degrees(np.arctan2(-c[:, K + 1], c[:, 1]))              # of a − ib
        rows.append({
            "name": f.names[i], "mu": float(f.mu[i]),
            "branch": "unstable" if f.unstable[i] else "stable",
            "actuator_fundamental_V": float(amp[1, 0]),
            "actuator_phase_to_heave_deg": float((phase[1] - phase[0] + 180) % 360 - 180),
            "heave_fundamental_mm": float(1e3 * amp[0, 0]),
            "actuator_harmonics_2_4_over_fundamental": (amp[1, 1:] / amp[1, 0]).tolist(),
            "features_control": np.asarray(f.control[i]).tolist(),
        })
    return rows


def part_fit(f, control: bool):
    import arviz as az

    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.posterior import fit_hybrid

    t0 = time.perf_counter()
    post = fit_hybrid(f, "subcritical", seed=0, progress=False,
                      settings=replace(CollapsedSettings(), control=control))
    wall = time.perf_counter() - t0
    ppc = post.ppc()
    loo = az.loo(post.to_inference_data(), pointwise=True)
    d = post.diagnostics["posterior"]
    out = {
        "wall_s": wall,
        **{k: post.interval(k).to_json() for k in ("mu0", "mu_fold", "w_unfold")},
        "orbit_error": post.orbit_error(),
        "amplitudes_inside": int(ppc.covered.sum()),
        "nuts": {"draws_per_chain": d["draws_per_chain"], "divergences": d["divergences"],
                 "leapfrog_steps_draws": d["leapfrog_steps_draws"], "sites": d["sites"]},
        "sigma_rel": float(np.median(post.samples["sigma_rel"])),
        "elpd_loo": float(loo.elpd_loo), "elpd_se": float(loo.se), "p_loo": float(loo.p_loo),
        "elpd_pointwise": dict(zip(f.names, np.asarray(loo.loo_i).tolist(), strict=True)),
        "pareto_k": dict(zip(f.names, np.asarray(loo.pareto_k).tolist(), strict=True)),
        "control": post.control_gain(),
    }
    return out, loo


def main():
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu()    # before any JAX work, as the CLI does
    import arviz as az

    from bayeshopf.data import load_recordings
    from bayeshopf.features.harmonics import extract_harmonics

    rs = load_recordings(DATA)
    f = extract_harmonics(rs)
    out = {"actuator": part_actuator(rs, f)}
    for r in out["actuator"]:
        print(f"{r['name']:24s} actuator {1e3 * r['actuator_fundamental_V']:.2f} mV at "
              f"{r['actuator_phase_to_heave_deg']:6.1f} deg; "
              f"heave {r['heave_fundamental_mm']:.1f} mm")
    loos = {}
    for control in (False, True):
        label = "with_control" if control else "without_control"
        out[label], loos[label] = part_fit(f, control)
        e = {x["name"]: x for x in out[label]["orbit_error"]}
        print(f"{label}: mu0 {out[label]['mu0']}, fold {out[label]['mu_fold']}, "
              f"ELPD {out[label]['elpd_loo']:.1f} ± {out[label]['elpd_se']:.1f}")
        print("  orbit errors", {k[:-4]: round(100 * v["relative"], 2) for k, v in e.items()})
    out["other_seeds"] = []
    for seed in (1, 2, 3, 4):
        from bayeshopf.posterior import fit_hybrid

        post = fit_hybrid(f, "subcritical", seed=seed, progress=False)
        errs = post.orbit_error()
        out["other_seeds"].append({
            "seed": seed, "orbit_error": {e["name"]: e["relative"] for e in errs},
            "all_ok": all(e["ok"] for e in errs),
            **{k: post.interval(k).to_json() for k in ("mu0", "mu_fold")}})
        print(f"seed {seed}: orbit errors "
              f"{[round(100 * e['relative'], 2) for e in errs]}, all ok "
              f"{out['other_seeds'][-1]['all_ok']}")
    cmp = az.compare(loos)
    out["compare"] = {str(k): {c: float(cmp.loc[k, c]) for c in ("elpd_loo", "elpd_diff", "dse")}
                      for k in cmp.index}
    print(cmp[["elpd_loo", "elpd_diff", "dse"]])
    (HERE / "rig_control.json").write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    sys.exit(main())
