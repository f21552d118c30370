"""Short records: are the Hopf and fold intervals calibrated when each record holds a few periods?

Run: ``python benchmarks/bench_short_records.py LABEL FIRST LAST [--duration S]
[--noise white|ar1]``
and ``python benchmarks/bench_short_records.py --summary LABEL...``.

Recordings of a subcritical normal form written here, apart from the package:
μ0 = 17, fold 16 (a2 = 2), 5 stable orbits (μ = 16.2, 16.5, 16.8, 17.2, 17.6) and 3
unstable ones (μ = 16.3, 16.6, 16.9), each the circle ``r(cos φ, sin φ)`` with
``φ`` advancing at 3 Hz plus 0.1 Hz per unit r², through a fixed smooth map to
two channels (h, alpha), sampled at 1 kHz for ``--duration`` seconds (4 by
default: two segments of five periods), with 1% noise per channel that is white
or AR(1) with ρ = 0.95 (a 20 ms memory). Each seed in FIRST..LAST is fitted at
default settings (seed 0) and scored: whether the 90% interval of μ0 and of the
fold holds the truth, their widths, and their interval scores (the width plus
20 times the distance by which a miss falls outside). It uses only names every
bayeshopf since 0.1 has, so ``PYTHONPATH`` may point at an older checkout.
Writes ``benchmarks/results/short_records_LABEL.jsonl`` (one line per seed).
"""

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import exit_on_help  # noqa: E402

OUT = Path(__file__).resolve().parent / "results"
MU0, A2 = 17.0, 2.0
MU_FOLD = MU0 - A2**2 / 4
STABLE = (16.2, 16.5, 16.8, 17.2, 17.6)
UNSTABLE = (16.3, 16.6, 16.9)


def radius(mu: float, branch: str) -> float:
    root = np.sqrt(A2**2 + 4 * (mu - MU0))
    return float(np.sqrt((A2 + root) / 2 if branch == "stable" else (A2 - root) / 2))


def noise(rng, n: int, kind: str) -> np.ndarray:
    e = rng.standard_normal(n)
    if kind == "white":
        return e
    rho, x = 0.95, np.empty(n)
    x[0] = e[0]
    for i in range(1, n):
        x[i] = rho * x[i - 1] + np.sqrt(1 - rho**2) * e[i]
    return x


def recordings(seed: int, duration: float, kind: str):
    from bayeshopf.data.recording import Recording, RecordingSet

    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1e-3)
    recs = []
    for branch, mus in (("stable", STABLE), ("unstable", UNSTABLE)):
        for mu in mus:
            r = radius(mu, branch)
            phase = 2 * np.pi * (3.0 + 0.1 * r**2) * t + rng.uniform(0, 2 * np.pi)
            u1, u2 = r * np.cos(phase), r * np.sin(phase)
            chans = {"h": 0.01 * u1 + 0.002 * u2 + 0.001 * u1 * u2 + 0.0005 * u1**2,
                     "alpha": 0.05 * u2 - 0.01 * u1 + 0.004 * u1**2 * u2}
            chans = {k: x + 0.005 * np.ptp(x) * noise(rng, t.size, kind)
                     for k, x in chans.items()}
            recs.append(Recording(t=t, channels=chans, units={"h": "m", "alpha": "rad"}, mu=mu,
                                  branch=branch, name=f"{branch}_{mu:g}"))
    return RecordingSet(tuple(recs), planar=("h", "alpha"), mu_label="airspeed",
                        mu_units="m/s")


def score(iv, truth: float) -> dict:
    lo, hi = iv.lo, iv.hi
    miss = max(lo - truth, 0.0) + max(truth - hi, 0.0)
    return {"median": iv.median, "lo": lo, "hi": hi, "inside": bool(miss == 0.0),
            "width": hi - lo, "interval_score": (hi - lo) + 20.0 * miss}


def run(label: str, first: int, last: int, duration: float, kind: str) -> None:
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu()
    from bayeshopf.posterior import fit_hybrid

    OUT.mkdir(exist_ok=True)
    path = OUT / f"short_records_{label}.jsonl"
    for seed in range(first, last + 1):
        post = fit_hybrid(recordings(seed, duration, kind), "subcritical", seed=0,
                          progress=False)
        row = {"seed": seed, "duration": duration, "noise": kind,
               "mu0": score(post.interval("mu0"), MU0),
               "mu_fold": score(post.interval("mu_fold"), MU_FOLD),
               "warnings": len(post.diagnostics["warnings"])}
        with path.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
        print(f"{label} seed {seed}: mu0 {row['mu0']['inside']} fold {row['mu_fold']['inside']}",
              file=sys.stderr)


def summary(labels: list[str]) -> None:
    from scipy.stats import beta

    for label in labels:
        rows = [json.loads(x) for x in (OUT / f"short_records_{label}.jsonl").read_text()
                .splitlines()]
        for q in ("mu0", "mu_fold"):
            k, n = sum(r[q]["inside"] for r in rows), len(rows)
            lo = beta.ppf(0.05, k, n - k + 1) if k else 0.0
            hi = beta.ppf(0.95, k + 1, n - k) if k < n else 1.0
            print(f"{label:>16} {q:>8}: {k}/{n} inside (90% CI {lo:.2f}-{hi:.2f}), "
                  f"mean width {np.mean([r[q]['width'] for r in rows]):.4f}, "
                  f"mean interval score {np.mean([r[q]['interval_score'] for r in rows]):.4f}")


if __name__ == "__main__":
    exit_on_help(__doc__)
    args = sys.argv[1:]
    if args[0] == "--summary":
        summary(args[1:])
    else:
        duration = float(args[args.index("--duration") + 1]) if "--duration" in args else 4.0
        kind = args[args.index("--noise") + 1] if "--noise" in args else "white"
        run(args[0], int(args[1]), int(args[2]), duration, kind)
