"""Wall time of ``bayeshopf discrepancy`` as a user meets it, on the whole machine.

Two data sets, each analysed in a fresh process with an empty compilation cache
("cold": a user's first run) and again on the cache that run filled ("warm"):

- ``rig``: the authors' 7 CBC recordings (``../shared/data/flutter_cbc``);
- ``simulated``: 4 stable + 4 unstable recordings of a flutter3dof whose base
  parameters are off (k_h +4%, c0 +3%, c_alpha −5%) and which has a concealed
  cubic heave damping of 20 N/(m/s)^3, at U = 15.5, 16, 16.5, 17 m/s, 2 s at
  1 kHz, 1.5% noise, sensor offsets h = 1 mm and alpha = −0.004 rad, written by
  ``bayeshopf simulate`` (seed 3; the truth is this module's :data:`TRUTH`).

Every analysis runs ``bayeshopf discrepancy DATA --simulator flutter3dof
--no-hybrid --quiet`` (figures drawn), the CLI's own environment
(``EQX_ON_ERROR``, XLA's flags) untouched. Run on an otherwise idle machine::

    python benchmarks/bench_discrepancy_speed.py [--repeat N] [--label L]

Writes ``benchmarks/discrepancy_speed.md`` (the table the documents quote) and
its rows to ``benchmarks/results/discrepancy_speed.json``, or with ``--label L``
``benchmarks/results/discrepancy_speed_L.json`` only (a per-run copy, e.g.
another commit's code through ``PYTHONPATH``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import CBC_DIR, RESULTS_DIR, atomic_write, exit_on_help

HERE = Path(__file__).parent
EXE = os.environ.get("BAYESHOPF_EXE") or str(Path(sys.executable).with_name("bayeshopf"))
PLAN_MU = ["15.5", "16", "16.5", "17"] * 2
PLAN_BRANCH = ["stable"] * 4 + ["unstable"] * 4


def _truth():
    from bayeshopf.simulators import FLUTTER3DOF

    p = FLUTTER3DOF.params
    truth = FLUTTER3DOF.with_params(k_h=p["k_h"] * 1.04, c0=p["c0"] * 1.03,
                                    c_alpha=p["c_alpha"] * 0.95)
    # the planting reads typical amplitudes over the default plan, which must exist
    return truth.replace(default_plan=tuple(zip(map(float, PLAN_MU), PLAN_BRANCH, strict=True)))


def __getattr__(name):
    if name == "TRUTH":             # read by ``bayeshopf simulate bench_discrepancy_speed:TRUTH``
        return _truth()
    raise AttributeError(name)


def simulated_set(folder: Path) -> Path:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(HERE), *filter(None, [os.environ.get("PYTHONPATH")])])}
    subprocess.run([EXE, "simulate", "bench_discrepancy_speed:TRUTH", "--out", str(folder),
                    "--mu", *PLAN_MU, "--branch", *PLAN_BRANCH, "--noise", "0.015",
                    "--offset", "h=0.001", "alpha=-0.004", "--duration", "2", "--rate", "1000",
                    "--seed", "3", "--effect", "h_cubic_damping", "--effect-value", "20",
                    "--truth-out", str(folder.parent / "truth.json")],
                   env=env, check=True, stdout=subprocess.DEVNULL)
    return folder


def timed(data: Path, cache: Path) -> dict:
    out = Path(tempfile.mkdtemp()) / "analysis"
    env = {**os.environ, "BAYESHOPF_CACHE_DIR": str(cache), "MPLBACKEND": "Agg"}
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    subprocess.run([EXE, "discrepancy", str(data), "--simulator", "flutter3dof", "--no-hybrid",
                    "--out", str(out), "--quiet"], env=env, check=True,
                   stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    report = json.loads((out / "report.json").read_text())
    cal = report.get("calibration") or {}
    return {"wall_s": wall, "load_before": load, "runtime_s": report.get("runtime_s"),
            "stages_s": cal.get("seconds", {}), "verdict": report.get("verdict", {}).get("kind")}


def main(repeat: int = 1, label: str | None = None) -> None:
    if not CBC_DIR.is_dir():
        raise SystemExit(f"benchmark: the recordings are not at {CBC_DIR}")
    sim = simulated_set(Path(tempfile.mkdtemp()) / "recordings")
    rows = []
    for _ in range(repeat):
        for name, data in (("rig", CBC_DIR), ("simulated", sim)):
            cache = Path(tempfile.mkdtemp())
            rows.append({"case": f"{name}, cold", **timed(data, cache)})
            rows.append({"case": f"{name}, warm", **timed(data, cache)})
    record = {"cpu_count": os.cpu_count(), "code": os.environ.get("PYTHONPATH") or str(HERE.parent),
              "runs": rows}
    text = json.dumps(record, indent=1)
    atomic_write(RESULTS_DIR / f"discrepancy_speed{'_' + label if label else ''}.json", text)
    if not label:
        atomic_write(HERE / "discrepancy_speed.md", table(record))
    print(table(record))


def table(record: dict) -> str:
    lines = ["# `bayeshopf discrepancy`: wall time", "",
             f"Measured with `benchmarks/bench_discrepancy_speed.py` on the whole machine "
             f"({record['cpu_count']} cores, otherwise idle): `bayeshopf discrepancy DATA "
             "--simulator flutter3dof --no-hybrid` in a fresh process, cold (an empty "
             "compilation cache) and warm (the cache the cold run filled). `simulated`: 4 stable "
             "+ 4 unstable recordings, 2 s at 1 kHz, of a flutter3dof with k_h +4%, c0 +3%, "
             "c_alpha −5% and a concealed cubic heave damping (the script's docstring). Wall: the "
             "whole command; analysis: the report's `runtime_s` (without Python's start and "
             "imports).", "",
             "| case | wall (s) | analysis (s) | calibration (s) | verdict | load before |",
             "|---|---:|---:|---:|---|---:|"]
    for r in record["runs"]:
        cal = r["stages_s"].get("total")
        lines.append(f"| {r['case']} | {r['wall_s']:.1f} | {r['runtime_s']:.1f} | "
                     f"{cal:.1f} | {r['verdict']} | {r['load_before']:.1f} |" if cal is not None
                     else f"| {r['case']} | {r['wall_s']:.1f} | {r['runtime_s']:.1f} | – | "
                     f"{r['verdict']} | {r['load_before']:.1f} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    exit_on_help(__doc__)
    main(int(sys.argv[sys.argv.index("--repeat") + 1]) if "--repeat" in sys.argv else 1,
         label=sys.argv[sys.argv.index("--label") + 1] if "--label" in sys.argv else None)
