"""Two explanations of the rig's held-out unstable misses, checked against its own CBC data.

Run: ``python benchmarks/bench_rig_cbc_search.py`` (a few seconds, no fit). Writes
``benchmarks/results/rig_cbc_search.json``; ``docs/validation.md`` quotes what it measures.

Held out, the unstable 14.9 and 16.5 m/s amplitudes lie below their bands, by
log residuals of −0.21 and −0.42 (``loo_reference_class.json``, ``rig``). Two
properties of control-based continuation could put a held orbit off the
uncontrolled branch by that much; the files hold what is needed to size both.

1. **The CBC search's precision.** Each unstable file stores its search
   (``search_point``: target amplitude in V and the scalar residual the search
   nulls, one row per step). A straight line through them gives the residual's
   slope and its scatter about the line; ``scatter / |slope|`` is how well the
   search locates the amplitude where the residual vanishes, relative to the
   final target: the size of the amplitude error a held orbit can carry.
2. **The control's work on the orbit.** The residual fundamental of the actuator
   in quadrature with the heave (``u_b`` of the features' ``control``, at the
   heave's crest as time origin) feeds or drains energy like a change of
   damping, so it would move a held orbit along the branch as a shift of μ in
   proportion to ``u_b / A`` (A the heave amplitude). Only differences of that
   ratio between recordings can move one recording against the others; a
   common value moves μ0 and the fold together.
"""

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _common import CBC_DIR, RESULTS_DIR, atomic_write, rig_recordings  # noqa: E402

HERE = Path(__file__).parent


def main():
    import scipy.io

    from bayeshopf.features.harmonics import extract_harmonics

    rs = rig_recordings()
    if rs is None:
        return
    f = extract_harmonics(rs)
    search = []
    for path in sorted(CBC_DIR.glob("*.mat")):
        m = scipy.io.loadmat(path)
        if "search_point" not in m:
            continue
        x, y = m["search_point"][:, 0], m["search_point"][:, 1]
        slope, icpt = np.polyfit(x, y, 1)
        scatter = float(np.sqrt(np.sum((y - (slope * x + icpt)) ** 2) / (x.size - 2)))
        row = {"file": path.name, "airspeed": float(m["Wind_sped"].ravel()[0]),
               "steps": int(x.size), "final_target_V": float(x[-1]),
               "slope": float(slope), "root_of_line_V": float(-icpt / slope),
               "residual_scatter": scatter,
               "amplitude_sd_relative": float(scatter / abs(slope) / x[-1])}
        search.append(row)
        print(f"{path.name:24s} {x.size:2d} steps, final target {x[-1]:.4f} V, "
              f"root of the line {row['root_of_line_V']:.4f} V, amplitude sd "
              f"{100 * row['amplitude_sd_relative']:.1f}% of the target", flush=True)
    work = []
    for i in range(f.n_recordings):
        ua, ub = f.control[i]
        work.append({"name": f.names[i], "mu": float(f.mu[i]),
                     "branch": "unstable" if f.unstable[i] else "stable",
                     "amplitude_m": float(f.amplitude[i]), "u_a_V": float(ua), "u_b_V": float(ub),
                     "u_b_over_A": float(ub / f.amplitude[i])})
        print(f"{f.names[i]:24s} u_b/A = {ub / f.amplitude[i]:+.4f} V/m", flush=True)
    ratio = np.array([w["u_b_over_A"] for w in work])
    out = {"search": search, "control_work": work,
           "u_b_over_A_mean": float(ratio.mean()), "u_b_over_A_sd": float(ratio.std(ddof=1))}
    atomic_write(RESULTS_DIR / "rig_cbc_search.json", json.dumps(out, indent=1))
    print(f"u_b/A: {ratio.mean():.4f} ± {ratio.std(ddof=1):.4f} V/m over the 7 recordings")


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    main()
