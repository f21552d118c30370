"""Would an error of the recorded airspeed explain the rig's held-out misses?

Run: ``python benchmarks/bench_loo_airspeed.py``. Writes ``benchmarks/results/loo_airspeed.json``
(7 fits, about 70 s on 2 cores).

The rig's airspeed comes from the wind tunnel's control system, rounded to 0.1 m/s
(``Wind_sped``), and the recordings were taken over three hours (the unstable
16.5 m/s one at 10:25, the others between 12:53 and 13:16, by the files'
``timestamp_created``). A new recording's true airspeed may then differ from the
recorded one by ``δ ~ N(0, σ²)``. Where the predicted amplitude changes fast with
μ, such an error widens the held-out band; all three misses of the rig's
leave-one-out are at the ends of their branches, one beside each fold and Hopf
point, where the normal form's amplitude is steepest.

**What it computes** (settings fixed before it was run). Each recording is held
out in turn and the model refitted on the other six (default settings, seed 0,
the full set's features), as ``bench_loo_collapsed.py`` does. The held-out
recording's predictive amplitude (the package's band: the model's coefficients,
the model error away from the data, the model error and the recording's own
standard errors and control) is drawn on a grid ``μ_i + δ``, ``δ`` in ±0.6 m/s by
0.01; each posterior draw takes one ``δ = σ z`` (``z ~ N(0, 1)``, one per draw,
seed 7, the nearest grid point), for ``σ`` in :data:`SIGMAS`: 0, the rounding's
own sd (0.1/√12 = 0.029 m/s), and 0.05–0.2 m/s (0.3–1.3% of the airspeed).
It reports, per fold, the 90% band and whether it holds the measured amplitude
at each ``σ``, the slope ``d log A / dμ`` of the predictive median at ``μ_i``, and
the shift ``δ`` (if any within ±0.6 m/s) at which that median equals the measured
amplitude. The band at ``σ = 0`` is the package's up to Monte Carlo error (its
noise is drawn on the whole grid here, not at one μ).

This is a prediction-only check: the fits keep the recorded airspeeds.
"""

import json
import time
import warnings
from pathlib import Path

import numpy as np
from _common import RESULTS_DIR, atomic_write, rig_recordings

HERE = Path(__file__).parent
OUT = RESULTS_DIR / "loo_airspeed.json"
CI = 0.9
#: Airspeed-error sds (m/s) of the held-out recording.
SIGMAS = (0.0, 0.1 / np.sqrt(12.0), 0.05, 0.1, 0.15, 0.2)
#: The grid of airspeed shifts (m/s).
GRID = np.round(np.linspace(-0.6, 0.6, 121), 10)
LEGACY_WIDTH_MM = 13.6      # the legacy core's mean band width (docs/changelog.md)


def main():
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu(host_devices=2)    # before any JAX work, as the CLI does on 2 cores
    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.posterior import fit_hybrid

    rs = rig_recordings()
    if rs is None:
        return 1
    f = extract_harmonics(rs)
    n, folds, t0 = f.n_recordings, [], time.perf_counter()
    step = GRID[1] - GRID[0]
    for i in range(n):
        post = fit_hybrid(f.subset([j for j in range(n) if j != i]), "subcritical", seed=0,
                          settings=CollapsedSettings(), progress=False)
        branch = "unstable" if f.unstable[i] else "stable"
        control = None if f.control is None else np.repeat(f.control[i][None], GRID.size, 0)
        amp = post.amplitude(f.mu[i] + GRID, branch, predictive=True,
                             coeffs_se=f.coeffs_se[i], control=control)      # (draws, grid)
        measured = float(f.amplitude[i])
        with warnings.catch_warnings():          # grid points where no draw has the branch
            warnings.simplefilter("ignore", RuntimeWarning)
            median = np.nanmedian(amp, axis=0)
        k0 = GRID.size // 2
        slope = float((np.log(median[k0 + 5]) - np.log(median[k0 - 5])) / (10 * step))
        gap = median - measured
        cross = np.flatnonzero(np.sign(gap[:-1]) * np.sign(gap[1:]) < 0)
        shift = (None if cross.size == 0 else
                 float(GRID[cross[np.argmin(np.abs(GRID[cross]))]]))
        z = np.random.default_rng(7).standard_normal(amp.shape[0])
        bands = {}
        for s in SIGMAS:
            k = np.clip(np.round((s * z - GRID[0]) / step).astype(int), 0, GRID.size - 1)
            a = amp[np.arange(amp.shape[0]), k]
            a = a[np.isfinite(a)]
            lo, med, hi = np.quantile(a, [0.5 - CI / 2, 0.5, 0.5 + CI / 2])
            bands[f"{s:.3f}"] = {"band": [float(lo), float(med), float(hi)],
                                 "inside": bool(lo <= measured <= hi)}
        folds.append({"name": f.names[i], "mu": float(f.mu[i]), "branch": branch,
                      "measured": measured, "dlogA_dmu": slope, "shift_to_measured": shift,
                      "bands": bands})
        print(f"{f.names[i]:24s} measured {1e3 * measured:5.1f} mm  dlogA/dμ {slope:+.3f}/(m/s)  "
              f"shift to it: {shift}  " + "  ".join(
                  f"σ={s}: {'in' if b['inside'] else 'OUT'}" for s, b in bands.items()),
              flush=True)
    pooled = {}
    for s in (f"{s:.3f}" for s in SIGMAS):
        w = np.mean([r["bands"][s]["band"][2] - r["bands"][s]["band"][0] for r in folds])
        pooled[s] = {"inside": int(sum(r["bands"][s]["inside"] for r in folds)), "n": n,
                     "mean_width_mm": float(1e3 * w),
                     "times_legacy": float(1e3 * w / LEGACY_WIDTH_MM)}
        print(f"σ = {s} m/s: {pooled[s]['inside']}/{n} inside, mean width "
              f"{pooled[s]['mean_width_mm']:.1f} mm ({pooled[s]['times_legacy']:.2f}× legacy)")
    atomic_write(OUT, json.dumps({"folds": folds, "pooled": pooled, "sigmas": list(SIGMAS),
                                  "wall_s": time.perf_counter() - t0}, indent=1))
    return 0


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    raise SystemExit(main())
