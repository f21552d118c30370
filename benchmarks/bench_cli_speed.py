"""Wall time of the CLI as a user meets it: ``bayeshopf fit`` on the rig cold and warm, demo cold.

Run: ``python benchmarks/bench_cli_speed.py [--repeat N] [--fusion-emitters] [--label L]
[--out FILE] [--fit-args "--no-discrepancy --nn-width 16 --inference nuts"]``
on an otherwise idle machine. Each run is a fresh process; "cold" uses an empty compilation cache
(``BAYESHOPF_CACHE_DIR`` set to a new temporary folder), "warm" runs again on the
cache the cold run filled. Prints a Markdown table and writes
``benchmarks/cli_speed.json`` with the stage timings from each ``summary.json``
and the machine's CPU count and load before each run. ``--fusion-emitters`` runs
with XLA's CPU fusion emitters, which ``inference.cache.configure_xla_cpu`` turns
off by default (``XLA_FLAGS=--xla_cpu_use_fusion_emitters=true``), and writes
``benchmarks/results/cli_speed_fusion_emitters.json``. ``--label L`` writes
``benchmarks/results/cli_speed_L.json`` instead (an ignored folder: labelled rounds
are per-run copies; ``--out FILE`` names the file, e.g. one that a document
quotes): with ``PYTHONPATH`` naming a checkout of
another commit (``git worktree add``), the CLI runs that commit's code, so two
versions can be timed in turns on the same machine (``BAYESHOPF_EXE`` names the
console script to run, where that commit's entry point is not the installed one).
``--fit-args`` adds options to every ``fit`` and ``demo`` (a model other than the
default's; use it with ``--label``).
"""

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import RESULTS_DIR

HERE = Path(__file__).parent
RIG = HERE.parent.parent / "shared/data/flutter_cbc"
# the console script beside this Python; BAYESHOPF_EXE names another (a commit
# whose entry point differs from the installed one's, timed through PYTHONPATH)
EXE = os.environ.get("BAYESHOPF_EXE") or str(Path(sys.executable).with_name("bayeshopf"))


def timed(args, cache, xla_flags):
    out = Path(tempfile.mkdtemp()) / "fit"
    env = {**os.environ, "BAYESHOPF_CACHE_DIR": str(cache), "MPLBACKEND": "Agg",
           "XLA_FLAGS": xla_flags}
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    subprocess.run([EXE, *args, "--out", str(out), "--quiet"], env=env, check=True,
                   stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    summary = json.loads((out / "summary.json").read_text())
    return {"command": " ".join(["bayeshopf", *args]), "wall_s": wall, "load_before": load,
            "stages_s": summary.get("timings_s", {})}


def main(repeat=1, fusion_emitters=False, label=None, out=None, fit_args=()):
    flags = os.environ.get("XLA_FLAGS", "")
    if fusion_emitters:
        flags = f"{flags} --xla_cpu_use_fusion_emitters=true".strip()
    rows = []
    for _ in range(repeat):
        cache = Path(tempfile.mkdtemp())
        rig = ["fit", str(RIG), *fit_args]
        rows.append({"case": "fit rig, cold", **timed(rig, cache, flags)})
        rows.append({"case": "fit rig, warm", **timed(rig, cache, flags)})
        rows.append({"case": "demo, cold", **timed(["demo", *fit_args], Path(tempfile.mkdtemp()),
                                                    flags)})
    path = (RESULTS_DIR / f"cli_speed_{label}.json" if label else
            RESULTS_DIR / "cli_speed_fusion_emitters.json" if fusion_emitters else
            HERE / "cli_speed.json")
    path = Path(out) if out else path
    path.parent.mkdir(parents=True, exist_ok=True)
    code = os.environ.get("PYTHONPATH") or str(HERE.parent)
    path.write_text(json.dumps(
        {"cpu_count": os.cpu_count(), "xla_flags": flags, "code": code, "runs": rows}, indent=1))
    print("| case | wall (s) | load before | stages (s) |\n|---|---:|---:|---|")
    for r in rows:
        st = ", ".join(f"{k} {v:.1f}" for k, v in r["stages_s"].items())
        print(f"| {r['case']} | {r['wall_s']:.1f} | {r['load_before']:.1f} | {st} |")


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    main(int(sys.argv[sys.argv.index("--repeat") + 1]) if "--repeat" in sys.argv else 1,
         fusion_emitters="--fusion-emitters" in sys.argv,
         label=sys.argv[sys.argv.index("--label") + 1] if "--label" in sys.argv else None,
         out=sys.argv[sys.argv.index("--out") + 1] if "--out" in sys.argv else None,
         fit_args=(sys.argv[sys.argv.index("--fit-args") + 1].split()
                   if "--fit-args" in sys.argv else ()))
