r"""Validation of the speed stage Ω: frequencies and phase errors against the truth.

Three data sets, each fitted blind with default settings (map, then speed):

* **Van der Pol**, the paper's range μ = 0.1 … 1.0 (relaxation-like at μ = 1,
  period 7.7 against 2π at the Hopf point; the paper's hardest case), supercritical;
* the **3-DOF aerofoil** (:func:`~bayeshopf.simulators.truth.flutter_experiment`),
  4 stable and 4 unstable LCOs, subcritical;
* the **wind-tunnel** recordings (``../shared/data/flutter_cbc``), where the
  truth is the measured mean frequency of each whole 20 s record.

For the simulated systems the true frequency ``1/T`` comes from the continued
periodic orbit (shooting, Newton-corrected) at every training and held-out μ;
for every recording (training, and for the simulators held-out recordings
simulated with fresh noise) the phase error after 10 periods is the RMS wrapped
angle error over the 10th period, predicted from the record's first point
(:meth:`~bayeshopf.inference.speed.SpeedFit.phase_error`).

``python benchmarks/validate_speed.py`` writes ``benchmarks/speed_validation.json``
and ``benchmarks/speed_validation.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
from bench_calibration import _atomic_write  # benchmarks/ is on the path as a script

REPO = Path(__file__).resolve().parent.parent
CBC_DIR = (REPO / ".." / "shared" / "data" / "flutter_cbc").resolve()


def _band_row(sf, mu, branch, true, kind):
    cv = sf.frequency_interval(mu, branch)
    pv = sf.frequency_interval(mu, branch, predictive=True)
    return {"mu": float(mu), "branch": branch, "kind": kind, "true_hz": float(true),
            "median": cv.median, "curve": [cv.lo, cv.hi], "predictive": [pv.lo, pv.hi],
            "in_curve": bool(cv.contains(true)), "in_predictive": bool(pv.contains(true)),
            "rel_error": float(cv.median / true - 1.0)}


def simulated(name: str, seed: int = 0) -> dict:
    """Fit map and speed to a simulated experiment; bands against the continuation's truth."""
    from bayeshopf.inference.speed import fit_speed
    from bayeshopf.pipeline import fit
    from bayeshopf.simulators.truth import (
        VANDERPOL_PAPER_PLAN,
        flutter_experiment,
        held_out_recordings,
        vanderpol_experiment,
    )

    if name == "vanderpol":
        held = ((0.15, "stable"), (0.45, "stable"), (0.75, "stable"), (0.95, "stable"))
        rs, truth = vanderpol_experiment(seed, plan=VANDERPOL_PAPER_PLAN, held_out=held)
        crit = "supercritical"
    else:
        rs, truth = flutter_experiment(seed)
        crit = "subcritical"
    t0 = time.perf_counter()
    hf = fit(rs, crit, seed=seed, progress=False)
    sf = fit_speed(hf, rs, seed=seed, progress=False)
    elapsed = time.perf_counter() - t0
    rows = []
    for kind, pts in (("training", truth.plan), ("held out", truth.held_out)):
        for mu, branch in pts:
            period = truth.diagram.orbit_at(mu, branch).period
            rows.append(_band_row(sf, mu, branch, 1.0 / period, kind))
    held_rs = held_out_recordings(truth)
    err_train = sf.phase_error(rs, n_periods=10.0)
    err_held = sf.phase_error(held_rs, n_periods=10.0)
    phase = ([{"recording": r.name, "kind": "training", "phase_error_rad": float(e)}
              for r, e in zip(rs, err_train, strict=True)]
             + [{"recording": r.name, "kind": "held out", "phase_error_rad": float(e)}
                for r, e in zip(held_rs, err_held, strict=True)])
    tau = np.asarray(sf.samples["tau_f"])
    return {"system": name, "seed": seed, "fit_s": elapsed, "rows": rows, "phase": phase,
            "tau": np.quantile(tau, [0.5, 0.05, 0.95]).tolist(),
            "mu0": hf.interval("mu0").to_json()}


def wind_tunnel(seed: int = 0) -> dict:
    """Fit map and speed to the 7 CBC recordings; measured frequencies against the bands."""
    from bayeshopf.data import load_recordings
    from bayeshopf.inference.speed import fit_speed
    from bayeshopf.pipeline import fit

    rs = load_recordings(CBC_DIR)
    t0 = time.perf_counter()
    hf = fit(rs, "subcritical", seed=seed, progress=False)
    sf = fit_speed(hf, rs, seed=seed, progress=False)
    elapsed = time.perf_counter() - t0
    err = sf.phase_error(rs, n_periods=10.0)
    rows, phase = [], []
    for i, r in enumerate(rs):
        row = _band_row(sf, r.mu, r.branch, abs(sf.data.measured_hz[i]), "training")
        row["recording"] = r.name
        row["measured_se_hz"] = float(sf.data.measured_se[i])
        rows.append(row)
        phase.append({"recording": r.name, "kind": "training", "phase_error_rad": float(err[i])})
    tau = np.asarray(sf.samples["tau_f"])
    return {"system": "wind tunnel", "seed": seed, "fit_s": elapsed, "rows": rows,
            "phase": phase, "tau": np.quantile(tau, [0.5, 0.05, 0.95]).tolist(),
            "mu0": hf.interval("mu0").to_json()}


def markdown(results: list[dict], meta: dict) -> str:
    """Tables: frequency bands per μ, and phase errors after 10 periods."""
    lines = ["# Speed stage Ω: frequencies and phase errors against the truth", "",
             f"- date: {meta['date']}; machine: {meta['machine']}",
             "- `python benchmarks/validate_speed.py`: map (`FitSettings()`) then speed "
             "(`SpeedSettings()`), seed 0, blind; the *curve* band is Ω's 90% band, the "
             "*predictive* band adds the frequency scatter τ between recordings (where a new "
             "recording's frequency is expected).", ""]
    for res in results:
        t = res["tau"]
        lines += [f"## {res['system']}", "",
                  f"Fit (map + speed) {res['fit_s']:.0f} s; scatter between recordings "
                  f"τ = {100 * t[0]:.2f}% [{100 * t[1]:.2f}, {100 * t[2]:.2f}].", "",
                  "| kind | branch | μ | true (Hz) | median (Hz) | error | 90% curve band "
                  "| inside | 90% predictive band | inside |",
                  "|---|---|---:|---:|---:|---:|---|---|---|---|"]
        for r in res["rows"]:
            lines.append(
                f"| {r['kind']} | {r['branch']} | {r['mu']:g} | {r['true_hz']:.4f} | "
                f"{r['median']:.4f} | {100 * r['rel_error']:+.2f}% | "
                f"[{r['curve'][0]:.4f}, {r['curve'][1]:.4f}] | "
                f"{'yes' if r['in_curve'] else 'no'} | "
                f"[{r['predictive'][0]:.4f}, {r['predictive'][1]:.4f}] | "
                f"{'yes' if r['in_predictive'] else 'no'} |")
        n = len(res["rows"])
        lines += ["", f"Inside: {sum(r['in_curve'] for r in res['rows'])}/{n} curve bands, "
                  f"{sum(r['in_predictive'] for r in res['rows'])}/{n} predictive bands.", "",
                  "| recording | kind | phase error after 10 periods (rad) |", "|---|---|---:|"]
        lines += [f"| {p['recording']} | {p['kind']} | {p['phase_error_rad']:.3f} |"
                  for p in res["phase"]]
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    """Run the three validations and write the JSON and the Markdown tables."""
    import datetime as dt

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=["vanderpol", "flutter3dof", "wind_tunnel"], nargs="*")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "speed_validation")
    args = ap.parse_args(argv)
    from bayeshopf.inference.cache import enable_compilation_cache

    enable_compilation_cache()
    which = args.only or ["vanderpol", "flutter3dof", "wind_tunnel"]
    results = []
    for name in which:
        res = wind_tunnel() if name == "wind_tunnel" else simulated(name)
        results.append(res)
        print(markdown([res], {"date": "", "machine": ""}), flush=True)
    meta = {"date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": f"{os.cpu_count()} CPU(s), {platform.system()}; "
                       f"Python {platform.python_version()}"}
    _atomic_write(args.out.with_suffix(".json"),
                  json.dumps({"meta": meta, "results": results}, indent=1) + "\n")
    _atomic_write(args.out.with_suffix(".md"), markdown(results, meta))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
