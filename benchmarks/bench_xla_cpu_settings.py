"""What two CPU settings cost and save: compile and run time of the rig's fit.

Run: ``python benchmarks/bench_xla_cpu_settings.py [--rounds N]`` on an otherwise
idle machine. Each row is a fresh process that fits the 7 rig recordings
(features, MAP, NUTS at default settings, seed 0) twice on an empty
compilation cache: the first fit compiles ("cold"), the second loads the
compiled programs ("warm"). For the MAP and the posterior stage it records the
wall time and the process's CPU time (every thread, ``time.process_time``):
CPU time above wall time is work on a second core, and busy-waiting threads
show there. The configurations set LLVM's optimisation level on CPU
(``--xla_backend_optimization_level``, XLA's default 3) and OpenBLAS's threads
(``OPENBLAS_NUM_THREADS``, by default one per core) on top of
``configure_xla_cpu()``'s other flags; they run in turns within each round so
that the machine's drift falls on all of them alike:

- ``opt1_blas1``: level 1, one BLAS thread;
- ``opt3_blas1``: level 3, one BLAS thread (what ``configure_xla_cpu`` sets);
- ``opt1_blas_default``: level 1, OpenBLAS's default threads.

Writes ``benchmarks/results/xla_cpu_settings.json`` (each row with the ``XLA_FLAGS``
and ``OPENBLAS_NUM_THREADS`` it ran with) and prints a Markdown table of the
medians over rounds.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))
from _common import RESULTS_DIR, atomic_write  # noqa: E402

OPT1, OPT3 = "--xla_backend_optimization_level=1", "--xla_backend_optimization_level=3"
CONFIGS = {             # "" → OpenBLAS's variable unset before scipy loads it
    "opt1_blas1": {"XLA_FLAGS": OPT1, "OPENBLAS_NUM_THREADS": "1"},
    "opt3_blas1": {"XLA_FLAGS": OPT3, "OPENBLAS_NUM_THREADS": "1"},
    "opt1_blas_default": {"XLA_FLAGS": OPT1, "OPENBLAS_NUM_THREADS": ""},
}


def child() -> None:
    """One configuration: two fits in this process, stage times to stdout as JSON."""
    from bayeshopf._x64 import ensure_x64
    from bayeshopf.inference.cache import configure_xla_cpu, enable_compilation_cache

    configure_xla_cpu()
    ensure_x64()                 # as the CLI: the data go to JAX in float64
    if os.environ.get("OPENBLAS_NUM_THREADS") == "unset":
        del os.environ["OPENBLAS_NUM_THREADS"]
    enable_compilation_cache()
    from _common import rig_recordings

    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference import collapsed as ci
    from bayeshopf.inference.cache import release_compiled

    features = extract_harmonics(rig_recordings())
    settings = ci.CollapsedSettings()
    out = {"OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
           "XLA_FLAGS": os.environ.get("XLA_FLAGS")}
    for run in ("cold", "warm"):
        release_compiled()
        spec = ci.build_spec(features, "subcritical")
        kwargs = ci.model_arguments(spec, features)
        stages = {}
        w, c = time.perf_counter(), time.process_time()
        point = ci.fit_map(kwargs)
        stages["map"] = {"wall_s": time.perf_counter() - w, "cpu_s": time.process_time() - c}
        w, c = time.perf_counter(), time.process_time()
        post = ci.sample_posterior(kwargs, point, settings, seed=0, progress=False)
        stages["posterior"] = {"wall_s": time.perf_counter() - w,
                               "cpu_s": time.process_time() - c}
        stages["leapfrog_steps"] = post.sampler["leapfrog_steps_warmup"] + \
            post.sampler["leapfrog_steps_draws"]
        out[run] = stages
    print(json.dumps(out))


def main(rounds: int = 2) -> None:
    rows = []
    for r in range(rounds):
        for name, env in CONFIGS.items():
            e = {**os.environ, "BAYESHOPF_CACHE_DIR": tempfile.mkdtemp(), "MPLBACKEND": "Agg"}
            e.pop("XLA_FLAGS", None)
            e.pop("OPENBLAS_NUM_THREADS", None)
            for k, v in env.items():
                e[k] = v if v else "unset"
            load = os.getloadavg()[0]
            res = subprocess.run([sys.executable, __file__, "--child"], env=e, check=True,
                                 capture_output=True, text=True)
            rows.append({"round": r, "config": name, "load_before": load,
                         **json.loads(res.stdout.strip().splitlines()[-1])})
            print(f"round {r} {name}: done", file=sys.stderr)
    atomic_write(RESULTS_DIR / "xla_cpu_settings.json", json.dumps(
        {"cpu_count": os.cpu_count(), "rows": rows}, indent=1))
    import numpy as np

    print("| configuration | stage | cold wall (s) | cold CPU (s) | warm wall (s) | warm CPU (s) |")
    print("|---|---|---:|---:|---:|---:|")
    for name in CONFIGS:
        sel = [r for r in rows if r["config"] == name]
        for st in ("map", "posterior"):
            cells = [float(np.median([r[run][st][k] for r in sel]))
                     for run in ("cold", "warm") for k in ("wall_s", "cpu_s")]
            print(f"| {name} | {st} | " + " | ".join(f"{x:.1f}" for x in cells) + " |")


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    if "--child" in sys.argv:
        child()
    else:
        main(int(sys.argv[sys.argv.index("--rounds") + 1]) if "--rounds" in sys.argv else 2)
