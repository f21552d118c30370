"""Leave-one-out on the wind-tunnel rig with the collapsed core.

Run: ``python benchmarks/bench_loo_collapsed.py [linear|curved]``. Features of the 7
recordings are taken once, in the full data's frame; each recording is held out
in turn, the model is refitted on the other six (default settings, seed 0), and
the held-out amplitude is compared with its 90% posterior predictive band (the
model's coefficients, the model error away from the data, the model error and
the held-out recording's own standard errors), and with the same band without
the model error away from the data (``CollapsedSettings.extrapolation=False``).
Writes ``benchmarks/loo_collapsed.json`` (the default unfolding, which the
docs and tests quote); another unfolding goes to
``benchmarks/results/loo_collapsed_<unfolding>.json`` (an ignored folder).
"""

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from _common import RESULTS_DIR

HERE = Path(__file__).parent


def _maps():
    """Memory mappings of this process (Linux; grows per fit unless compiled code is released)."""
    p = Path("/proc/self/maps")
    return len(p.read_text().splitlines()) if p.exists() else None


def held_out_rows(f, settings) -> list[dict]:
    """Hold out each recording of features ``f`` in turn, refit, and band it (module docstring)."""
    from bayeshopf.diagnostics.summaries import interval
    from bayeshopf.posterior import fit_hybrid

    rows = []
    for i in range(f.n_recordings):
        keep = [j for j in range(f.n_recordings) if j != i]
        t0 = time.perf_counter()
        post = fit_hybrid(f.subset(keep), "subcritical", seed=0, settings=settings,
                          progress=False)
        wall = time.perf_counter() - t0
        branch = "unstable" if f.unstable[i] else "stable"
        bands = {}
        for on in (True, False):     # with and without the model error away from the data
            p = replace(post, settings=replace(post.settings, extrapolation=on))
            amp = p.amplitude([f.mu[i]], branch, predictive=True, coeffs_se=f.coeffs_se[i],
                              control=None if f.control is None else f.control[i][None])[:, 0]
            ok = np.isfinite(amp)
            bands[on] = (interval(amp[ok]) if ok.any() else None), float(ok.mean())
        (iv, p_exists), (iv0, _) = bands[True], bands[False]
        rows.append({"name": f.names[i], "mu": float(f.mu[i]), "branch": branch,
                     "measured": float(f.amplitude[i]),
                     "band": None if iv is None else [iv.lo, iv.median, iv.hi],
                     "inside": bool(iv is not None and iv.contains(f.amplitude[i])),
                     "band_without_extrapolation": None if iv0 is None
                     else [iv0.lo, iv0.median, iv0.hi],
                     "inside_without_extrapolation": bool(iv0 is not None
                                                          and iv0.contains(f.amplitude[i])),
                     "p_exists": p_exists, "wall_s": wall, "memory_maps": _maps(),
                     "mu0": post.interval("mu0").to_json(),
                     "mu_fold": post.interval("mu_fold").to_json()})
        r = rows[-1]
        print(f"{r['name']:24s} measured {1e3 * r['measured']:6.2f} mm  band "
              f"{np.round(1e3 * np.array(r['band']), 2).tolist() if r['band'] else None} "
              f"{'inside' if r['inside'] else 'OUTSIDE'}", flush=True)
    return rows


def main(unfolding="curved"):
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu()    # before any JAX work, as the CLI does
    from bayeshopf.data import load_recordings
    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference.collapsed import CollapsedSettings

    rs = load_recordings(HERE.parent.parent / "shared/data/flutter_cbc")
    f = extract_harmonics(rs)
    rows = held_out_rows(f, replace(CollapsedSettings(), unfolding=unfolding))
    for key, what in (("", "with the model error away from the data (default)"),
                      ("_without_extrapolation", "without it")):
        n_in = sum(r["inside" + key] for r in rows)
        widths = [r["band" + key][2] - r["band" + key][0] for r in rows if r["band" + key]]
        print(f"{what}: {n_in}/{len(rows)} held-out amplitudes inside their 90% predictive "
              f"bands; mean band width {1e3 * np.mean(widths):.2f} mm")
    path = (HERE / "loo_collapsed.json" if unfolding == "curved"
            else RESULTS_DIR / f"loo_collapsed_{unfolding}.json")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    main(sys.argv[1] if len(sys.argv) > 1 else "curved")
