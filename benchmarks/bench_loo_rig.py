"""Leave-one-out on the wind-tunnel rig: coverage, width and log predictive density.

Run: ``python benchmarks/bench_loo_rig.py LABEL [--extrapolation-scale S] [--no-discrepancy]
[--inference M] [--floor K] [--nn-width H|inf] [--learn-mu-scale] [--unfolding U]
[--own-too] [--common-frame]``.
Each of the rig's 7 recordings is held out in turn, the model refitted on the
others (seed 0; each refit's frame, the orbits' centre and scale, built without
the held-out recording; with ``--common-frame`` one frame of all 7, as every
result before session 79) and the held-out amplitude predicted with its 90% band
(``bayeshopf.validation.leave_one_out``, the refits kept). The log predictive
density of each held-out amplitude is a Gaussian kernel density of the refit's
predictive draws (``amplitude(predictive=True)`` with the recording's standard
errors and control) at the measured amplitude, times the share of draws in which
the branch exists. It uses only names every bayeshopf since 0.1 has, so
``PYTHONPATH`` may point at an older checkout to score its bands the same way.
Writes ``benchmarks/results/loo_rig_LABEL.json``; with ``--own-too`` also
``loo_rig_LABEL_own.json``, the same refits scored with the normal form's own
branches (the rig's Hopf point and fold dropped, :func:`own_branches`).
"""

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.stats import gaussian_kde

OUT = Path(__file__).resolve().parent / "results"
RIG = Path(__file__).resolve().parents[2] / "shared" / "data" / "flutter_cbc"


def main(argv):
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu()
    from bayeshopf.data import load_recordings
    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.validation import leave_one_out

    label = argv[0]
    settings = CollapsedSettings()
    if "--extrapolation-scale" in argv:
        settings = replace(settings,
                           extrapolation_scale=float(argv[argv.index("--extrapolation-scale") + 1]))
    if "--no-discrepancy" in argv:
        settings = replace(settings, discrepancy=False)
    if "--inference" in argv:
        settings = replace(settings, inference=argv[argv.index("--inference") + 1])
    if "--nn-width" in argv:
        w = argv[argv.index("--nn-width") + 1]
        settings = replace(settings, nn_width=None if w == "inf" else int(w))
    if "--learn-mu-scale" in argv:
        settings = replace(settings, nn_mu_scale=None)
    if "--unfolding" in argv:
        settings = replace(settings, unfolding=argv[argv.index("--unfolding") + 1])
    if "--floor" in argv:
        settings = replace(settings, discrepancy_floor=float(argv[argv.index("--floor") + 1]))
    rs = load_recordings(RIG)
    f = extract_harmonics(rs, n_harmonics=settings.n_harmonics,
                          segment_periods=settings.segment_periods)
    loo = leave_one_out(f if "--common-frame" in argv else rs, "subcritical",
                        methods=("bayes",), seed=0, settings=settings, keep_fits=True,
                        progress=True)
    OUT.mkdir(exist_ok=True)
    both = [(label, False)] + ([(label + "_own", True)] if "--own-too" in argv else [])
    for name, own in both:
        res = {"label": name, **score(loo, f, own)}
        (OUT / f"loo_rig_{name}.json").write_text(json.dumps(res, indent=1, default=float))
        print(name, res["inside"], "/", res["n"], "width", res["mean_width"], "lpd",
              res["log_predictive_density"])


def own_branches(fit):
    """``fit`` without the rig's points (``*_rig`` draws): the normal form's own branches."""
    chains = {k: v for k, v in fit.run.chains.items() if not k.endswith("_rig")}
    return replace(fit, run=replace(fit.run, chains=chains))


def score(loo, f, own: bool = False) -> dict:
    """Inside count, mean width and summed log predictive density of held-out amplitudes.

    ``loo``: :func:`bayeshopf.validation.leave_one_out`'s result with its refits
    kept; ``f``: the features it was made from; ``own``: score each refit with
    the normal form's own branches (:func:`own_branches`). The 90% band is the
    5%–95% quantiles of the predictive draws where the branch exists, as
    ``leave_one_out``'s own prediction.
    """
    rows = []
    for i, fold in enumerate(loo.folds):
        p = fold.predictions["bayes"]
        fit = own_branches(fold.fit) if own else fold.fit
        control = None if f.control is None else f.control[i][None]
        amp = fit.amplitude([fold.mu], fold.branch, predictive=True,
                            coeffs_se=f.coeffs_se[i], control=control)[:, 0]
        ok = np.isfinite(amp)
        lpd = (float(np.log(ok.mean()) + gaussian_kde(amp[ok]).logpdf(fold.measured)[0])
               if ok.sum() > 1 else -np.inf)
        lo, hi = np.quantile(amp[ok], [0.05, 0.95]) if ok.any() else (np.nan, np.nan)
        rows.append({"name": fold.name, "mu": fold.mu, "branch": fold.branch,
                     "measured": fold.measured, "median": float(np.median(amp[ok])),
                     "lo": float(lo), "hi": float(hi),
                     "inside": bool(lo <= fold.measured <= hi), "log_density": lpd,
                     "mu0": list(p.mu0), "mu_fold": list(p.mu_fold)})
    return {"inside": sum(r["inside"] for r in rows), "n": len(rows),
            "mean_width": float(np.mean([r["hi"] - r["lo"] for r in rows])),
            "log_predictive_density": float(sum(r["log_density"] for r in rows)),
            "folds": rows}


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    main(sys.argv[1:])
