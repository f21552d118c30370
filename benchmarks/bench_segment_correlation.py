"""How correlated are a recording's segment coefficients? (issue 51, item 2: the segment covariance)

    python benchmarks/bench_segment_correlation.py

The likelihood treats the standard errors of a recording's 2(2K+1) aligned
coefficients as independent. This measures, for the rig's 7 CBC recordings and
the demo's 8 simulated ones, the correlation matrix of the coefficients over a
recording's segments (as ``extract_harmonics`` aligns them, recorded by
wrapping ``shift_origin``): the median and largest |r| off the diagonal and the
share above 0.6, against the median |r| of independent coefficients,
``√(2/(π(n−1)))`` for ``n`` segments. Writes ``benchmarks/results/segment_correlation.json``.
"""

from __future__ import annotations

import json

from _common import RESULTS_DIR, atomic_write, exit_on_help, rig_recordings

exit_on_help(__doc__)

import numpy as np  # noqa: E402


def segment_correlations(rs) -> list[dict]:
    import bayeshopf.features.harmonics as H

    seen = []
    original = H.shift_origin

    def spy(coeffs, phase):
        out = original(coeffs, phase)
        if out.ndim == 3 and out.shape[1] == 2:   # (n_seg, 2, 2K+1): a recording's segments
            seen.append(out.copy())
        return out

    H.shift_origin = spy
    try:
        f = H.extract_harmonics(rs)
    finally:
        H.shift_origin = original
    rows = []
    for seg, name in zip(seen, f.names, strict=True):
        n = seg.shape[0]
        X = seg.reshape(n, -1)
        X = X[:, X.std(axis=0) > 0]            # the aligned crest's sine is zero
        R = np.corrcoef(X.T)
        off = np.abs(R[~np.eye(R.shape[0], dtype=bool)])
        rows.append({"recording": name, "segments": n, "median_abs_r": float(np.median(off)),
                     "independent_median_abs_r": float(np.sqrt(2 / np.pi / (n - 1))),
                     "max_abs_r": float(off.max()), "share_above_0.6": float(np.mean(off > 0.6))})
    return rows


def main() -> None:
    from bayeshopf.simulators.truth import flutter_experiment

    out = {"demo": segment_correlations(flutter_experiment(seed=0)[0])}
    rig = rig_recordings()
    if rig is not None:
        out["rig"] = segment_correlations(rig)
    for data, rows in out.items():
        for r in rows:
            print(f"{data:5s} {r['recording']:28s} {r['segments']:3d} segments: median |r| "
                  f"{r['median_abs_r']:.2f} (independent {r['independent_median_abs_r']:.2f}), "
                  f"max {r['max_abs_r']:.2f}, share > 0.6 {r['share_above_0.6']:.2f}")
    atomic_write(RESULTS_DIR / "segment_correlation.json", json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
