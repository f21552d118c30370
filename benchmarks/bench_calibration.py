r"""Calibration of the 90% intervals on the 3-DOF aerofoil, over noise seeds.

The same experiment (:func:`bayeshopf.simulators.truth.flutter_experiment`:
the μ plan :data:`~bayeshopf.simulators.truth.FLUTTER_PLAN`, 1 % noise, sensor
offsets) is simulated with ``n`` seeds, each seed drawing new noise, phases and
offsets, and each set is fitted blind (data-driven start, subcritical). For
:math:`\theta \in \{\mu_0, a_2, \mu_{SN}\}` it reports

* the **coverage**: the share of seeds whose 90% interval contains the truth
  (:math:`\mu_0 = 18.2747`, :math:`\mu_{SN} = 14.9362` m/s from the
  continuation, :math:`a_2 = 2\sqrt{\mu_0 - \mu_{SN}} = 3.654`), with a 90%
  Clopper–Pearson interval for the coverage itself;
* the **widths**: mean and median 90% interval width, against the spread of
  the posterior medians across seeds. For an unbiased, calibrated posterior
  whose width does not vary much between seeds, the 90% width is about
  :math:`2 \times 1.645 = 3.29` times the standard deviation of the medians, so
  the ratio ``width / (3.29 sd)`` is near 1; much above 1 means intervals wider
  than the data warrant, much below 1 intervals too narrow;
* the bias and RMS error of the medians, and the coverage of the held-out
  orbits by the 90% predictive bands
  (:data:`~bayeshopf.simulators.truth.FLUTTER_HELD_OUT`).

Results go to ``benchmarks/calibration.json`` (rewritten after every seed, so an
interrupted run keeps what it finished; ``--resume`` continues it) and the
table to ``benchmarks/calibration.md``::

    python benchmarks/bench_calibration.py                # 20 seeds, default settings
    python benchmarks/bench_calibration.py --fast -n 5    # FitSettings.fast(), a quick check
    nohup python benchmarks/bench_calibration.py --resume > calibration.log 2>&1 &

Fits run one after another.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.stats import beta

REPO = Path(__file__).resolve().parent.parent
DEFAULT_JSON = REPO / "benchmarks" / "calibration.json"
DEFAULT_MD = REPO / "benchmarks" / "calibration.md"
QUANTITIES = ("mu0", "a2", "mu_fold")
LABELS = {"mu0": "μ0 (m/s)", "a2": "a2", "mu_fold": "μ_SN (m/s)"}
#: 90% width of a normal distribution in standard deviations, 2 × 1.645.
Z90_WIDTH = 3.29


def _atomic_write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(text)
    os.replace(tmp, path)


def clopper_pearson(k: int, n: int, mass: float = 0.9) -> tuple[float, float]:
    """Exact ``mass`` interval of a binomial proportion ``k/n``."""
    a = (1.0 - mass) / 2.0
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1.0 - a, k + 1, n - k))
    return lo, hi


def run_seed(seed: int, fast: bool) -> dict:
    """Simulate, fit and check one seed; a JSON-serialisable record."""
    from bayeshopf.pipeline import FitSettings, fit
    from bayeshopf.simulators.truth import flutter_experiment, held_out_check

    rs, truth = flutter_experiment(seed)
    settings = FitSettings.fast() if fast else FitSettings()
    t0 = time.perf_counter()
    result = fit(rs, "subcritical", seed=seed, settings=settings, progress=False)
    fit_s = time.perf_counter() - t0
    true = truth.values()
    rec = {"seed": seed, "fit_s": fit_s, "timings": dict(result.timings),
           "offsets": truth.offsets,
           "starts": [{"map_loss": s.map_loss, "weight": s.weight, "lpd": s.lpd,
                       **s.map_values} for s in result.starts]}
    for q in QUANTITIES:
        iv = result.interval(q)
        rec[q] = {"median": iv.median, "lo": iv.lo, "hi": iv.hi, "true": true[q],
                  "inside": bool(iv.lo <= true[q] <= iv.hi), "map": float(
                      result.map.params[q]) if q in result.map.params else None}
    rows = held_out_check(result, truth)
    rec["held_out"] = rows
    rec["held_out_inside"] = int(sum(r["inside"] for r in rows))
    return rec


def summarise(records: list[dict]) -> dict:
    """Coverage, widths and errors per quantity over the seeds."""
    out = {}
    n = len(records)
    for q in QUANTITIES:
        med = np.array([r[q]["median"] for r in records])
        lo = np.array([r[q]["lo"] for r in records])
        hi = np.array([r[q]["hi"] for r in records])
        true = records[0][q]["true"]
        k = int(sum(r[q]["inside"] for r in records))
        width = hi - lo
        sd = float(np.std(med, ddof=1)) if n > 1 else float("nan")
        out[q] = {
            "true": true, "n": n, "inside": k, "coverage": k / n,
            "coverage_ci90": clopper_pearson(k, n),
            "width_mean": float(width.mean()), "width_median": float(np.median(width)),
            "median_sd": sd, "bias": float(med.mean() - true),
            "rmse": float(np.sqrt(np.mean((med - true) ** 2))),
            "width_over_spread": float(np.median(width) / (Z90_WIDTH * sd)) if sd > 0 else None,
            "below": int(np.sum(hi < true)), "above": int(np.sum(lo > true)),
        }
    n_ho = sum(len(r["held_out"]) for r in records)
    k_ho = sum(r["held_out_inside"] for r in records)
    out["held_out"] = {"inside": k_ho, "n": n_ho, "coverage": k_ho / max(n_ho, 1),
                       "coverage_ci90": clopper_pearson(k_ho, n_ho) if n_ho else None}
    return out


def markdown(meta: dict, records: list[dict], summary: dict) -> str:
    """The report: settings, the coverage/width table and every seed."""
    lines = [
        "# Calibration of the 90% intervals: 3-DOF aerofoil, blind fits over noise seeds",
        "",
        f"- date: {meta['date']}",
        f"- machine: {meta['machine']}",
        f"- settings: {meta['settings']}; {len(records)} seeds "
        f"({', '.join(str(r['seed']) for r in records)})",
        f"- experiment: `flutter_experiment(seed)`: plan {meta['plan']}, "
        "1% relative RMS noise, sensor offsets N(0, 1 mm) on heave and N(0, 0.005 rad) on "
        "pitch drawn per seed, 20 s at 500 Hz; subcritical fit from data-driven "
        "starting values",
        f"- truth (continuation): μ0 = {summary['mu0']['true']:.4f} m/s, "
        f"μ_SN = {summary['mu_fold']['true']:.4f} m/s, a2 = 2√(μ0 − μ_SN) = "
        f"{summary['a2']['true']:.4f}",
        f"- runtime: {meta['runtime_s'] / 60:.0f} min in all, {meta['fit_s_median']:.0f} s "
        "median per fit (the machine was shared with other fits; see the load average "
        "below)",
        f"- command: `{meta['command']}`",
        "",
        "Coverage is the share of seeds whose 90% interval holds the truth (target 90%; "
        "80–97% is the aim), with its 90% Clopper–Pearson interval. *width/spread* is the "
        "median interval width over 3.29 × the standard deviation of the posterior medians "
        "across seeds: near 1 for intervals as wide as the seed-to-seed scatter of the "
        "estimate, well above 1 for intervals wider than needed. *below/above*: seeds whose "
        "interval lies wholly below/above the truth.",
        "",
        "| quantity | truth | coverage | coverage 90% CI | mean width | median width "
        "| sd of medians | width/spread | bias of medians | RMSE | below/above |",
        "|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for q in QUANTITIES:
        s = summary[q]
        lo, hi = s["coverage_ci90"]
        wos = s["width_over_spread"]
        lines.append(
            f"| {LABELS[q]} | {s['true']:.4f} | {s['inside']}/{s['n']} "
            f"({100 * s['coverage']:.0f}%) | [{100 * lo:.0f}%, {100 * hi:.0f}%] | "
            f"{s['width_mean']:.4f} | {s['width_median']:.4f} | {s['median_sd']:.4f} | "
            f"{'' if wos is None else f'{wos:.2f}'} | {s['bias']:+.4f} | {s['rmse']:.4f} | "
            f"{s['below']}/{s['above']} |"
        )
    ho = summary["held_out"]
    lines += [
        "",
        f"Held-out orbits ({len(records[0]['held_out'])} per seed: "
        + ", ".join(f"{r['branch']} {r['mu']:g}" for r in records[0]["held_out"])
        + f") inside their 90% posterior predictive intervals: {ho['inside']}/{ho['n']} "
        f"({100 * ho['coverage']:.0f}%).",
        "",
        "## Every seed",
        "",
        "| seed | μ0 median [90% CI] | a2 median [90% CI] | μ_SN median [90% CI] "
        "| held-out inside | fit (s) | load avg |",
        "|---:|---|---|---|---:|---:|---:|",
    ]

    def cell(r, q, d):
        v = r[q]
        mark = "" if v["inside"] else " **miss**"
        return f"{v['median']:.{d}f} [{v['lo']:.{d}f}, {v['hi']:.{d}f}]{mark}"

    for r in records:
        lines.append(
            f"| {r['seed']} | {cell(r, 'mu0', 3)} | {cell(r, 'a2', 3)} | {cell(r, 'mu_fold', 3)} "
            f"| {r['held_out_inside']}/{len(r['held_out'])} | {r['fit_s']:.0f} "
            f"| {r.get('load_avg', float('nan')):.1f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run the seeds (or resume), then write the JSON and the Markdown table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-n", "--seeds", type=int, default=20, help="number of seeds (default 20)")
    ap.add_argument("--first-seed", type=int, default=0, help="first seed (default 0)")
    ap.add_argument("--fast", action="store_true", help="FitSettings.fast() instead of defaults")
    ap.add_argument("--resume", action="store_true",
                    help="keep the seeds already in the JSON (same settings) and run the rest")
    ap.add_argument("--json", type=Path, default=DEFAULT_JSON, help="results JSON")
    ap.add_argument("--md", type=Path, default=DEFAULT_MD, help="Markdown table")
    args = ap.parse_args(argv)

    import bayeshopf
    from bayeshopf.inference.cache import enable_compilation_cache
    from bayeshopf.simulators.truth import FLUTTER_PLAN

    enable_compilation_cache()
    settings = "FitSettings.fast()" if args.fast else "FitSettings() defaults"
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    records: list[dict] = []
    runtime_before = 0.0
    if args.resume and args.json.exists():
        old = json.loads(args.json.read_text())
        if old["meta"]["settings"] == settings:
            records = [r for r in old["records"] if r["seed"] in seeds]
            runtime_before = float(old["meta"].get("runtime_s", 0.0))
    done = {r["seed"] for r in records}
    t_start = time.perf_counter()
    meta = {
        "date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": f"{os.cpu_count()} CPU(s), {platform.system()} {platform.release()}; "
        f"Python {platform.python_version()}, bayeshopf {bayeshopf.__version__}",
        "settings": settings,
        "plan": ", ".join(f"{b} {m:g}" for m, b in FLUTTER_PLAN),
        "command": "python benchmarks/bench_calibration.py" + (" --fast" if args.fast else "")
        + (f" -n {args.seeds}" if args.seeds != 20 else ""),
    }

    def write() -> None:
        records.sort(key=lambda r: r["seed"])
        meta["runtime_s"] = runtime_before + time.perf_counter() - t_start
        meta["fit_s_median"] = float(np.median([r["fit_s"] for r in records]))
        summary = summarise(records)
        _atomic_write(args.json, json.dumps({"meta": meta, "summary": summary,
                                             "records": records}, indent=1) + "\n")
        _atomic_write(args.md, markdown(meta, records, summary))

    for seed in seeds:
        if seed in done:
            continue
        load = os.getloadavg()[0]
        rec = run_seed(seed, args.fast)
        rec["load_avg"] = load
        records.append(rec)
        print(f"seed {seed}: " + ", ".join(
            f"{q} {rec[q]['median']:.3f} [{rec[q]['lo']:.3f}, {rec[q]['hi']:.3f}]"
            f"{'' if rec[q]['inside'] else ' MISS'}" for q in QUANTITIES)
            + f"; held-out {rec['held_out_inside']}/{len(rec['held_out'])}; "
            f"{rec['fit_s']:.0f} s", flush=True)
        write()
    if records:
        write()
        print(args.md.read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
