"""Stage-by-stage timings of a bayeshopf fit, cold and warm.

For the wind-tunnel flutter recordings (``flutter_cbc``) and for the synthetic
demonstration set, each stage of a fit is timed in a fresh Python process:

* ``import``: ``import bayeshopf`` and the pipeline (JAX, NumPyro, ...);
* ``load``: read the ``.mat`` folder, or generate the synthetic recordings;
* ``features``, ``MAP``, ``SVI``: the stages of :func:`bayeshopf.pipeline.fit`
  (its own ``timings``);
* ``predictive``: the posterior predictive check and the bifurcation diagram;
* ``figures``: :func:`bayeshopf.plotting.plot_all` into a temporary folder
  (which draws its own check and diagram again).

*Cold* is a fresh process with an empty, new JAX compilation cache
(``BAYESHOPF_CACHE_DIR`` pointing at a new temporary folder); *warm* is a second
fresh process reusing that folder. The console script is timed the same way,
wall clock around ``bayeshopf fit DATA --out DIR --quiet`` and
``bayeshopf demo --out DIR --quiet``. Peak RSS is each child's
``ru_maxrss`` (``os.wait4``, the per-child form of
``resource.getrusage(RUSAGE_CHILDREN)``).

The table is printed and written atomically to ``benchmarks/results.md``::

    python benchmarks/bench_fit.py                 # default settings (minutes)
    python benchmarks/bench_fit.py --fast          # FitSettings.fast(), a quick check
    python benchmarks/bench_fit.py /path/to/flutter_cbc --out /tmp/results.md

Run it on an otherwise idle machine: every fit is run one after another, and the
load average before each run is recorded next to it.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DEFAULT_OUT = REPO / "benchmarks" / "results.md"
FLUTTER_ENV = "BAYESHOPF_FLUTTER_CBC"
MARK = "BENCH-RESULT "
STAGES = (
    ("import", "import"),
    ("load", "load"),
    ("features", "features"),
    ("map", "MAP"),
    ("svi", "SVI"),
    ("predictive", "predictive (ppc + diagram)"),
    ("ppc", "&nbsp;&nbsp;of which ppc"),
    ("diagram", "&nbsp;&nbsp;of which diagram"),
    ("figures", "figures (plot_all)"),
    ("total", "total in process"),
)


# -- the measured child process ---------------------------------------------------------


def peak_rss_mb() -> float:
    """Peak resident set size of this process so far (MB; ``ru_maxrss`` is KiB on Linux)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def worker(dataset: str, data: str | None, fast: bool, seed: int) -> dict:
    """Run one fit with every stage timed (in a fresh process); returns the timings."""
    t0 = time.perf_counter()
    from bayeshopf.data import load_recordings
    from bayeshopf.data.synthetic import demo_system
    from bayeshopf.pipeline import FitSettings, fit
    from bayeshopf.plotting import diagram_grid, plot_all

    t = {"import": time.perf_counter() - t0}
    rss = {"import": peak_rss_mb()}
    t1 = time.perf_counter()
    truth = None
    if dataset == "flutter_cbc":
        rs = load_recordings(data)
    else:
        rs, truth = demo_system(seed=seed, fast=fast)
    t["load"] = time.perf_counter() - t1
    rss["load"] = peak_rss_mb()

    settings = FitSettings.fast() if fast else FitSettings()
    result = fit(rs, "subcritical", seed=seed, settings=settings, progress=False)
    t.update({k: result.timings[k] for k in ("features", "map", "svi")})
    rss["svi"] = peak_rss_mb()

    t1 = time.perf_counter()
    ppc = result.ppc()
    t["ppc"] = time.perf_counter() - t1
    rss["ppc"] = peak_rss_mb()
    t2 = time.perf_counter()
    result.diagram(diagram_grid(result))
    t["diagram"] = time.perf_counter() - t2
    rss["diagram"] = peak_rss_mb()
    t["predictive"] = time.perf_counter() - t1

    t1 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench-fig-") as tmp:
        plot_all(result, rs, tmp, truth=truth)
    t["figures"] = time.perf_counter() - t1
    rss["figures"] = peak_rss_mb()
    t["total"] = time.perf_counter() - t0
    t["rss"] = rss
    iv = result.interval("mu0")
    t["check"] = {
        "n_recordings": len(rs),
        "mu0": [iv.median, iv.lo, iv.hi],
        "ppc_inside": int(ppc.covered.sum()),
    }
    return t


# -- the parent ---------------------------------------------------------------------------


def run_child(cmd: list[str], env: dict, cwd: Path) -> dict:
    """Run ``cmd`` to completion; wall clock, exit code, peak RSS and output."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        loadavg = os.getloadavg()[0]
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, env=env, cwd=cwd, stdout=out, stderr=err, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        return {
            "rc": proc.returncode,
            "wall": wall,
            "rss_mb": usage.ru_maxrss / 1024.0,  # KiB on Linux
            "loadavg": loadavg,
            "stdout": out.read(),
            "stderr": err.read(),
        }


def _fail(what: str, res: dict) -> None:
    tail = "\n".join((res["stdout"] + res["stderr"]).strip().splitlines()[-15:])
    raise SystemExit(f"bench_fit: {what} failed with exit code {res['rc']}:\n{tail}")


def child_env(cache: Path) -> dict:
    env = dict(os.environ)
    env["BAYESHOPF_CACHE_DIR"] = str(cache)
    env.setdefault("PYTHONUNBUFFERED", "1")
    env.setdefault("MPLBACKEND", "Agg")
    return env


def bench_stages(dataset: str, data: str | None, fast: bool, seed: int, scratch: Path) -> dict:
    """Cold and warm stage timings of one data set."""
    cache = Path(tempfile.mkdtemp(prefix=f"cache-{dataset}-", dir=scratch))
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", dataset, "--seed", str(seed)]
    if data is not None:
        cmd.append(str(data))
    if fast:
        cmd.append("--fast")
    out = {}
    for mode in ("cold", "warm"):
        print(f"  {dataset} {mode} ...", flush=True)
        res = run_child(cmd, child_env(cache), REPO)
        if res["rc"] != 0:
            _fail(f"{dataset} ({mode})", res)
        line = [ln for ln in res["stdout"].splitlines() if ln.startswith(MARK)][-1]
        out[mode] = {**json.loads(line[len(MARK):]), "wall": res["wall"],
                     "rss_mb": res["rss_mb"], "loadavg": res["loadavg"]}
        print(f"    {res['wall']:.1f} s wall, {res['rss_mb']:.0f} MB peak RSS", flush=True)
    out["cache_mb"] = sum(f.stat().st_size for f in cache.rglob("*") if f.is_file()) / 2**20
    return out


def cli_command() -> list[str]:
    """The ``bayeshopf`` console script of this interpreter (else ``-m``)."""
    script = Path(sys.executable).parent / "bayeshopf"
    if script.is_file():
        return [str(script)]
    found = shutil.which("bayeshopf")
    return [found] if found else [sys.executable, "-m", "bayeshopf.cli.main"]


def bench_cli(args_: list[str], label: str, fast: bool, scratch: Path) -> dict:
    """Cold and warm wall clock of one console-script command."""
    cache = Path(tempfile.mkdtemp(prefix="cache-cli-", dir=scratch))
    out = {}
    for mode in ("cold", "warm"):
        dest = Path(tempfile.mkdtemp(prefix="cli-out-", dir=scratch)) / "fit"
        cmd = [*cli_command(), *args_, "--out", str(dest), "--quiet"] + (["--fast"] if fast else [])
        print(f"  {label} {mode} ...", flush=True)
        res = run_child(cmd, child_env(cache), REPO)
        if res["rc"] != 0:
            _fail(f"{label} ({mode})", res)
        summary = json.loads((dest / "summary.json").read_text())
        out[mode] = {"wall": res["wall"], "rss_mb": res["rss_mb"], "loadavg": res["loadavg"],
                     "timings": summary.get("timings_s", {})}
        print(f"    {res['wall']:.1f} s wall, {res['rss_mb']:.0f} MB peak RSS", flush=True)
    return out


# -- report -------------------------------------------------------------------------------


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _fmt(x: float | None, digits: int = 1) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def render(stages: dict, cli: dict, meta: dict) -> str:
    lines = [
        "# bayeshopf fit benchmark",
        "",
        f"- date: {meta['date']}",
        f"- machine: {meta['nproc']} CPU(s) ({meta['cpu']}), {meta['os']}",
        f"- Python {meta['python']}, JAX {meta['jax']}, bayeshopf {meta['bayeshopf']}",
        f"- settings: {meta['settings']}; seed {meta['seed']}",
        f"- command: `{meta['command']}`",
        "",
        "Seconds per stage. *cold*: fresh process, empty new JAX compilation cache; "
        "*warm*: fresh process reusing that cache. `figures` runs `plot_all`, which "
        "computes its own predictive check and diagram again.",
        "",
    ]
    names = list(stages)
    hdr = "| stage | " + " | ".join(f"{n} cold | {n} warm" for n in names) + " |"
    lines += [hdr, "|---|" + "---:|" * (2 * len(names))]
    for key, label in STAGES:
        cells = [_fmt(stages[n][m].get(key), 2) for n in names for m in ("cold", "warm")]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    extra = [
        ("process wall clock", lambda r: _fmt(r["wall"], 2)),
        ("peak RSS (MB)", lambda r: _fmt(r["rss_mb"], 0)),
        ("1-min load average at start", lambda r: _fmt(r["loadavg"], 2)),
    ]
    for label, f in extra:
        cells = [f(stages[n][m]) for n in names for m in ("cold", "warm")]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Peak RSS of the process (MB) after each stage (`ru_maxrss`, so it only grows; "
        "`SVI` covers the whole of `fit`):",
        "",
        "| after | " + " | ".join(f"{n} cold | {n} warm" for n in names) + " |",
        "|---|" + "---:|" * (2 * len(names)),
    ]
    for key in ("import", "load", "svi", "ppc", "diagram", "figures"):
        cells = [_fmt(stages[n][m]["rss"].get(key), 0) for n in names for m in ("cold", "warm")]
        lines.append(f"| {dict(STAGES)[key]} | " + " | ".join(cells) + " |")
    lines.append("")
    for n in names:
        c = stages[n]["warm"]["check"]
        lines.append(
            f"- {n}: {c['n_recordings']} recordings, μ0 = {c['mu0'][0]:.4g} "
            f"[{c['mu0'][1]:.4g}, {c['mu0'][2]:.4g}], {c['ppc_inside']}/{c['n_recordings']} "
            f"amplitudes inside their 90% predictive intervals; compilation cache "
            f"{stages[n]['cache_mb']:.1f} MB"
        )
    if cli:
        lines += [
            "",
            "Console script, wall clock of the whole command (seconds), each in a fresh "
            "process; cold with an empty new cache, warm reusing it.",
            "",
            "| command | cold (s) | warm (s) | peak RSS cold (MB) | peak RSS warm (MB) "
            "| load avg cold / warm |",
            "|---|---:|---:|---:|---:|---:|",
        ]
        for label, r in cli.items():
            lines.append(
                f"| `{label}` | {_fmt(r['cold']['wall'], 2)} | {_fmt(r['warm']['wall'], 2)} | "
                f"{_fmt(r['cold']['rss_mb'], 0)} | {_fmt(r['warm']['rss_mb'], 0)} | "
                f"{_fmt(r['cold']['loadavg'], 2)} / {_fmt(r['warm']['loadavg'], 2)} |"
            )
        lines += ["", "Stage timings the console script recorded in `summary.json` "
                  "(s, cold / warm):", ""]
        for label, r in cli.items():
            keys = list(dict.fromkeys([*r["cold"]["timings"], *r["warm"]["timings"]]))
            parts = [f"{k} {_fmt(r['cold']['timings'].get(k), 2)} / "
                     f"{_fmt(r['warm']['timings'].get(k), 2)}" for k in keys]
            lines.append(f"- `{label}`: " + ", ".join(parts))
    for note in meta.get("notes", []):
        lines += ["", note]
    return "\n".join(lines) + "\n"


def write_atomic(text: str, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes it 0600
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def default_data() -> Path:
    env = os.environ.get(FLUTTER_ENV, "").strip()
    return Path(env) if env else (REPO / ".." / "shared" / "data" / "flutter_cbc").resolve()


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        description="Time every stage of a bayeshopf fit (load, features, MAP, SVI, predictive, "
        "figures) cold and warm for the wind-tunnel data and the synthetic demo, and the "
        "console script's fit and demo; print a markdown table and write it to "
        "benchmarks/results.md.",
    )
    ap.add_argument("data", nargs="?", default=None,
                    help=f"folder of the flutter_cbc .mat files (default ${FLUTTER_ENV}, else "
                    "../shared/data/flutter_cbc relative to the repository root)")
    ap.add_argument("--fast", action="store_true",
                    help="FitSettings.fast() and the short demo records (a quick check)")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT,
                    help="markdown file to write (default benchmarks/results.md)")
    ap.add_argument("--seed", type=int, default=0, help="seed of every fit (default 0)")
    ap.add_argument("--no-cli", action="store_true", help="skip the console-script timings")
    ap.add_argument("--only", choices=("flutter_cbc", "demo"), default=None,
                    help="time one data set only")
    ap.add_argument("--worker", choices=("flutter_cbc", "demo"), help=argparse.SUPPRESS)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.worker:
        res = worker(args.worker, args.data, args.fast, args.seed)
        print(MARK + json.dumps(res), flush=True)
        return 0

    data = Path(args.data) if args.data else default_data()
    notes = []
    datasets = {"flutter_cbc": str(data), "demo": None}
    if args.only:
        datasets = {args.only: datasets[args.only]}
    if "flutter_cbc" in datasets and not data.is_dir():
        notes.append(f"flutter_cbc skipped: {data} is not a folder "
                     f"(pass it or set ${FLUTTER_ENV}).")
        print(f"bench_fit: {notes[-1]}", file=sys.stderr)
        del datasets["flutter_cbc"]
    if not datasets:
        raise SystemExit("bench_fit: nothing to time")

    import jax

    import bayeshopf

    started = dt.datetime.now().astimezone()
    stages, cli = {}, {}
    with tempfile.TemporaryDirectory(prefix="bayeshopf-bench-") as tmp:
        scratch = Path(tmp)
        for name, path in datasets.items():
            print(f"stages: {name}", flush=True)
            stages[name] = bench_stages(name, path, args.fast, args.seed, scratch)
        if not args.no_cli:
            if "flutter_cbc" in datasets:
                print("console script: fit", flush=True)
                cli["bayeshopf fit DATA"] = bench_cli(["fit", str(data), "--seed", str(args.seed)],
                                                      "bayeshopf fit", args.fast, scratch)
            if "demo" in datasets:
                print("console script: demo", flush=True)
                cli["bayeshopf demo"] = bench_cli(["demo", "--seed", str(args.seed)],
                                                  "bayeshopf demo", args.fast, scratch)

    meta = {
        "date": f"{started:%Y-%m-%d %H:%M} to {dt.datetime.now().astimezone():%H:%M %Z}",
        "nproc": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
        else os.cpu_count(),
        "cpu": cpu_model(),
        "os": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "jax": jax.__version__,
        "bayeshopf": bayeshopf.__version__,
        "settings": "FitSettings.fast() (--fast)" if args.fast else "FitSettings() defaults",
        "seed": args.seed,
        "command": " ".join(["python", "benchmarks/bench_fit.py", *sys.argv[1:]]),
        "notes": notes,
    }
    text = render(stages, cli, meta)
    print()
    print(text)
    write_atomic(text, args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
