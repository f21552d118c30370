"""How correlated are a recording's segment coefficients? (issue 51, item 2: the segment covariance)

    python benchmarks/bench_segment_correlation.py

The likelihood treats the standard errors of a recording's 2(2K+1) aligned
coefficients as independent. This measures, for the rig's 7 CBC recordings and
the demo's 8 simulated ones, the correlation matrix of the coefficients over a
recording's segments (as ``extract_harmonics`` aligns them, recorded by
wrapping ``shift_origin``): the median and largest |r| off the diagonal and the
share above 0.6, against the median |r| of independent coefficients,
``√(2/(π(n−1)))`` for ``n`` segments.

Then what the segment covariance would change on the rig: the default model is
fitted (seed 0), and for each recording the errors' covariance with the
segments' correlation, ``S = diag(se) R diag(se) + diag(σ_c² + (σ_rel y)²)``
at the posterior medians of ``σ_c`` and ``σ_rel``, is compared with the
likelihood's diagonal one ``D``: the eigenvalues of ``D^{-1/2} S D^{-1/2}``
(1 everywhere when the correlation does not matter), with the sample
correlation and with it shrunk halfway to the identity, over both frame axes
and within each (the model's marginals are per axis); and the largest and
median share ``se²/D`` of the measurement error in a coefficient's variance.
Writes ``benchmarks/results/segment_correlation.json``.
"""

from __future__ import annotations

import json

from _common import RESULTS_DIR, atomic_write, exit_on_help, rig_recordings

exit_on_help(__doc__)

import numpy as np  # noqa: E402


def _segments(extract):
    """``extract()``'s result, and each recording's aligned segment coefficients.

    One array ``(n_seg, 2·(2K+1))`` per recording, in the order they are aligned.
    """
    import bayeshopf.features.harmonics as H

    seen = []
    original = H.shift_origin

    def spy(coeffs, phase):
        out = original(coeffs, phase)
        if out.ndim == 3 and out.shape[1] == 2:   # (n_seg, 2, 2K+1): a recording's segments
            seen.append(out.reshape(out.shape[0], -1).copy())
        return out

    H.shift_origin = spy
    try:
        result = extract()
    finally:
        H.shift_origin = original
    return result, seen


def _correlation(X: np.ndarray) -> np.ndarray:
    """Sample correlation of the columns of ``X``; a constant one (the crest's sine) independent."""
    keep = X.std(axis=0) > 0
    R = np.eye(X.shape[1])
    R[np.ix_(keep, keep)] = np.corrcoef(X[:, keep].T)
    return R


def segment_correlations(rs) -> list[dict]:
    from bayeshopf.features.harmonics import extract_harmonics

    f, seen = _segments(lambda: extract_harmonics(rs))
    rows = []
    for X, name in zip(seen, f.names, strict=True):
        n = X.shape[0]
        X = X[:, X.std(axis=0) > 0]            # the aligned crest's sine is zero
        R = np.corrcoef(X.T)
        off = np.abs(R[~np.eye(R.shape[0], dtype=bool)])
        rows.append({"recording": name, "segments": n, "median_abs_r": float(np.median(off)),
                     "independent_median_abs_r": float(np.sqrt(2 / np.pi / (n - 1))),
                     "max_abs_r": float(off.max()), "share_above_0.6": float(np.mean(off > 0.6))})
    return rows


def covariance_effect(rs, seed: int = 0) -> list[dict]:
    """Eigenvalues of ``D^{-1/2} S D^{-1/2}`` per recording, at the default fit's model error."""
    import bayeshopf as bh

    fit, seen = _segments(lambda: bh.fit(rs, seed=seed, progress=False))
    f = fit.features
    if len(seen) != f.n_recordings:
        raise RuntimeError(f"the fit aligned {len(seen)} recordings' segments; "
                           f"expected its {f.n_recordings}")
    sigma = np.median(np.asarray(fit.samples["sigma"]).reshape(-1, f.coeffs.shape[1]), axis=0)
    sigma_rel = float(np.median(fit.samples["sigma_rel"]))
    m = f.coeffs.shape[-1]
    rows = []
    for i, X in enumerate(seen):
        se, y = f.coeffs_se[i].reshape(-1), f.coeffs[i].reshape(-1)
        model = np.repeat(sigma**2, m) + (sigma_rel * y) ** 2
        D = se**2 + model
        row = {"recording": f.names[i], "max_share": float(np.max(se**2 / D)),
               "median_share": float(np.median(se**2 / D)),
               "sigma": sigma.tolist(), "sigma_rel": sigma_rel}
        for label, lam in (("sample", 0.0), ("shrunk", 0.5)):
            R = (1 - lam) * _correlation(X) + lam * np.eye(X.shape[1])
            M = (np.outer(se, se) * R + np.diag(model)) / np.sqrt(np.outer(D, D))
            ev = np.linalg.eigvalsh(M)
            ev_axis = np.concatenate([np.linalg.eigvalsh(M[c * m:(c + 1) * m, c * m:(c + 1) * m])
                                      for c in range(len(sigma))])
            row[label] = {"eig": [float(ev.min()), float(ev.max())],
                          "eig_per_axis": [float(ev_axis.min()), float(ev_axis.max())]}
        rows.append(row)
    return rows


def main() -> None:
    from bayeshopf.simulators.truth import flutter_experiment

    out = {"demo": segment_correlations(flutter_experiment(seed=0)[0])}
    rig = rig_recordings()
    if rig is not None:
        out["rig"] = segment_correlations(rig)
        out["rig_covariance_effect"] = covariance_effect(rig)
    for data in ("demo", "rig"):
        rows = out.get(data, [])
        for r in rows:
            print(f"{data:5s} {r['recording']:28s} {r['segments']:3d} segments: median |r| "
                  f"{r['median_abs_r']:.2f} (independent {r['independent_median_abs_r']:.2f}), "
                  f"max {r['max_abs_r']:.2f}, share > 0.6 {r['share_above_0.6']:.2f}")
    for r in out.get("rig_covariance_effect", []):
        print(f"rig   {r['recording']:28s} se²/D max {r['max_share']:.3f} median "
              f"{r['median_share']:.3f}; eigenvalues of D^-1/2 S D^-1/2: sample "
              f"[{r['sample']['eig'][0]:.2f}, {r['sample']['eig'][1]:.2f}] (per axis "
              f"[{r['sample']['eig_per_axis'][0]:.2f}, {r['sample']['eig_per_axis'][1]:.2f}]), "
              f"shrunk [{r['shrunk']['eig'][0]:.2f}, {r['shrunk']['eig'][1]:.2f}]")
    atomic_write(RESULTS_DIR / "segment_correlation.json", json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
