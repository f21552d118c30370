"""Simulation-based calibration of the collapsed model with the discrepancy (issue 51, item 3).

    python benchmarks/bench_sbc.py --design paired --seeds 0-199
    python benchmarks/bench_sbc.py --design sweep --seeds 0-199
    python benchmarks/bench_sbc.py --design paired --seeds 0-199 --pipeline
    python benchmarks/bench_sbc.py --summary        # table and rank histograms
    python benchmarks/bench_sbc.py --design paired --seeds 2000-2199 --pipeline --nn-width inf
    python benchmarks/bench_sbc.py --summary --seeds 2000-2199 --nn-width inf
    python benchmarks/bench_sbc.py --design paired --seeds 2200-2399 --pipeline --nn-width inf \
        --inference importance

Each simulation draws a data set from the model's prior
(:func:`bayeshopf.model.prior_predictive.draw_data`) at one design, fits it with
NUTS on the collapsed model (the map and the discrepancy's latents integrated
out), and ranks the truth of μ0, the fold, η (and the other sampled sites)
among ``L = 99`` thinned posterior draws (Talts et al. 2018): exact inference
gives uniform ranks.

Designs (the demo's recordings, ``flutter_experiment(seed=0)``, give μ, the
branches, the standard errors and the model's data constants ρ, q, the frame):

* ``paired``: all 8 recordings, 4 stable and 4 unstable (up to 18.0 m/s, the
  Hopf point's side);
* ``sweep``: the 4 stable recordings and the 2 lowest unstable ones (15.1 and
  16.2 m/s): no unstable recording near the Hopf point.

The model is the default's structure with the discrepancy, the curved
unfolding and the frequency model, no control term; with ``--nn-width inf`` the
map's network is at infinite width (``Settings(nn_width=None)``, the network's
kernel built on the design's recordings), as ``--nn-width inf --discrepancy``
fits. NUTS is NumPyro's kernel
(``numpyro.infer.hmc.hmc``), with the data as traced arguments (one
compilation per design): 2 chains of
``--warmup`` + ``--samples`` steps from the package's deterministic start, a
dense mass matrix, target acceptance 0.8, as the package's default.

**Through the pipeline** (``--pipeline``): the same draw with the
measurement noise left out gives each recording's true coefficients; from
them a time series is written (the design's sampling times, a random time
origin, the design's frame back to the sensors' units) with white noise of 1%
of each channel's RMS, and :func:`~bayeshopf.features.harmonics.extract_harmonics`
(in the design's frame) reads the coefficients, their standard errors, the
frequencies and theirs from it, as from a recording. The fit then sees what it
sees from a rig: aligned segment means and estimated errors, which the model
takes as given. ``--duration D`` keeps the first ``D`` seconds of each record
(short records: the errors from the noise spectrum). ``--aligned`` (a
diagnosis) takes the same noise-free coefficients, only moves each
recording's time origin to its crest as the features do, and adds the
design's measurement noise to the coefficients: what the alignment alone does.

**Importance sampling** (``--inference importance``): the package's
importance sampling from the MAP's Laplace approximation instead of the
benchmark's NUTS (:func:`make_importance_runner`), NUTS where its check fails.

Writes one JSON line per simulation to
``benchmarks/results/sbc_<design>[_inf][_pipeline[_D s]][_is].jsonl`` (appended, so
that a run can be stopped and resumed); ``--summary`` reads them, updates their
rows of ``benchmarks/sbc.json`` (the tables ``docs/inference.md`` quotes;
rows of runs whose results are not here are kept) and draws
``docs/sbc_ranks.png`` (``docs/sbc_ranks_inf.png`` with ``--nn-width inf``, with
``_is`` before ``.png`` where every run shown is importance sampling's).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from _common import RESULTS_DIR, atomic_write, exit_on_help

exit_on_help(__doc__)

import numpy as np  # noqa: E402

#: Thinned posterior draws per simulation (ranks 0..L, L + 1 = 100 values).
L_DRAWS = 99
#: Histogram bins of the ranks (5 rank values each).
BINS = 20
#: Relative RMS of the white measurement noise written into the time series (``--pipeline``).
NOISE = 0.01
#: Sites whose ranks are recorded.
SITES = ("mu0", "mu_fold", "eta", "ell", "gap_hopf", "gap_fold", "w_unfold", "sigma_rel",
         "tau_mu", "tau_shape")
ROOT = Path(__file__).resolve().parents[1]


def design(name: str, nn_width: int | None = 16):
    """``(spec, features, recordings)`` of a design (module docstring)."""
    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference.settings import build_spec
    from bayeshopf.simulators.truth import flutter_experiment

    rs, _ = flutter_experiment(seed=0)
    f = extract_harmonics(rs)
    if name == "paired":
        keep = np.ones(f.mu.shape, bool)
    elif name == "sweep":
        keep = ~f.unstable | (f.mu < 16.5)
    else:
        raise SystemExit(f"--design: 'paired' or 'sweep' expected; got {name!r}")
    idx = np.flatnonzero(keep)
    f = f.subset(idx)
    spec = build_spec(f, "subcritical", control=False, discrepancy=True, nn_width=nn_width)
    return spec, f, rs.subset(idx)


def synthesize(rs, frame, coeffs, omega, rng, noise: float = NOISE,
               duration: float | None = None):
    """Recordings whose planar channels hold the orbits ``coeffs`` at ``omega`` (docstring).

    Each recording keeps its μ, branch and sampling times (the first
    ``duration`` seconds); its time origin is a uniform random phase; the
    noise is white, ``noise`` times the RMS of each channel about its mean.
    """
    from dataclasses import replace

    from bayeshopf.data.recording import Recording
    from bayeshopf.features.harmonics import time_design

    out = []
    for r, c, om in zip(rs, coeffs, omega, strict=True):
        t = r.t if duration is None else r.t[r.t - r.t[0] < duration]
        t0 = rng.uniform(0.0, 2.0 * np.pi / om)
        w = time_design(t + t0, float(om), c.shape[-1] // 2) @ c.T      # (n_t, 2)
        z = frame.from_frame(w)
        z = z + noise * z.std(axis=0) * rng.standard_normal(z.shape)
        names = rs.planar
        out.append(Recording(t=t, channels={names[0]: z[:, 0], names[1]: z[:, 1]},
                             units={k: r.units[k] for k in names}, mu=r.mu, branch=r.branch,
                             name=r.name, source="bench_sbc --pipeline"))
    return replace(rs, recordings=tuple(out), control=None)


def model_info(spec, mu, sign, se, omega_se):
    """NumPyro's model information of the collapsed model, the data as dynamic arguments.

    Returns ``(info, post)``: ``initialize_model``'s record (from the package's
    deterministic start values) and the sites' transforms, which do not read
    the data.
    """
    import jax
    import jax.numpy as jnp
    from numpyro.infer import init_to_value
    from numpyro.infer.util import initialize_model

    from bayeshopf.inference.programs import _initial_values
    from bayeshopf.model import collapsed as cm

    def model(mu, sign, coeffs, coeffs_se, omega, omega_se):
        cm.collapsed_model(spec, mu, sign, coeffs, coeffs_se, omega, omega_se)

    shape = (len(mu), 2, 2 * spec.n_harmonics + 1)
    example = (jnp.asarray(mu), jnp.asarray(sign), jnp.zeros(shape), jnp.asarray(se),
               jnp.full(len(mu), spec.omega_centre), jnp.asarray(omega_se))
    info = initialize_model(jax.random.PRNGKey(0), model, model_args=example,
                            init_strategy=init_to_value(values=_initial_values(spec)),
                            dynamic_args=True, validate_grad=False)
    return info, info.postprocess_fn(*example)


def make_runner(spec, mu, sign, se, omega_se, warmup: int, samples: int):
    """NUTS on new data of the design's shape, compiled once (data as traced arguments).

    NumPyro's functional NUTS (``numpyro.infer.hmc.hmc``): the kernel the
    ``MCMC`` class runs, with its step-size and dense mass-matrix adaptation,
    from the package's deterministic start; each chain one compiled call
    (``MCMC.run`` compiles its loop anew on every call, and a process that
    fitted some sixty data sets that way ran out of memory maps).
    """
    import jax
    import jax.numpy as jnp
    from numpyro.infer.hmc import hmc

    info, post = model_info(spec, mu, sign, se, omega_se)
    z0 = info.param_info.z
    init_kernel, sample_kernel = hmc(potential_fn_gen=info.potential_fn, algo="NUTS")

    @jax.jit
    def chain(key, data):
        state = init_kernel(z0, warmup, dense_mass=True, target_accept_prob=0.8,
                            model_args=data, rng_key=key)

        def step(s, _):
            s = sample_kernel(s, model_args=data)
            return s, (s.z, s.diverging)

        _, (zs, div) = jax.lax.scan(step, state, None, length=warmup + samples)
        zs = jax.tree.map(lambda a: a[warmup:], zs)
        return jax.vmap(post)(zs), jnp.sum(div[warmup:])

    def run(key, *data):
        data = tuple(jnp.asarray(a) for a in data)
        outs = [chain(k, data) for k in jax.random.split(key, 2)]
        chains = {k: np.stack([np.asarray(o[0][k]) for o in outs]) for k in outs[0][0]}
        return chains, int(sum(int(o[1]) for o in outs))

    return run


def make_importance_runner(spec, mu, sign, se, omega_se, warmup: int, samples: int):
    """The package's importance sampling on new data of the design's shape (``--inference``).

    As :func:`~bayeshopf.inference.importance.run_importance` does it, with the
    data as traced arguments (one compilation per design): the MAP by SciPy's
    L-BFGS-B from the package's deterministic start values, its Laplace
    covariance (:func:`~bayeshopf.inference.optimum.laplace_covariance`), then
    :func:`~bayeshopf.inference.importance.importance_draws` (2,000 draws
    resampled, stored as two chains of 1,000 for the file's shape); where its
    check fails, :func:`make_runner`'s NUTS. The record's ``method`` says
    which, ``pareto_k`` and ``ess`` the check.
    """
    import jax
    import jax.numpy as jnp
    from jax.flatten_util import ravel_pytree
    from scipy.optimize import minimize

    from bayeshopf.inference import importance
    from bayeshopf.inference.optimum import laplace_covariance

    info, post = model_info(spec, mu, sign, se, omega_se)
    x_start, unravel = ravel_pytree(info.param_info.z)

    def potential(x, data):
        return info.potential_fn(*data)(unravel(x))

    vg = jax.jit(jax.value_and_grad(potential))
    batch = jax.jit(lambda xs, data: jax.lax.map(lambda x: potential(x, data), xs))
    sites = jax.jit(lambda xs: jax.lax.map(lambda x: post(unravel(x)), xs))
    nuts_run = make_runner(spec, mu, sign, se, omega_se, warmup, samples)

    def run(key, *data):
        data = tuple(jnp.asarray(a) for a in data)

        def fun(x):
            v, g = vg(jnp.asarray(x), data)
            return float(v), np.asarray(g, dtype=float)

        res = minimize(fun, np.asarray(x_start), jac=True, method="L-BFGS-B",
                       options={"maxiter": 300})
        cov, ok = laplace_covariance(lambda x: vg(x, data), res.x)
        seed = np.asarray(key, dtype=np.uint32).ravel().tolist()
        check = {"fallback": "the MAP's Hessian is not positive definite"}
        if ok:
            x, check = importance.importance_draws(lambda xs: batch(xs, data), res.x, cov, 2000,
                                                   np.random.default_rng(seed))
            if x is not None:
                out = sites(jnp.asarray(x))
                chains = {k: np.asarray(v).reshape((2, 1000) + v.shape[1:])
                          for k, v in out.items()}
                return chains, 0, {"method": "importance", **check}
        chains, div = nuts_run(key, *data)
        return chains, div, {"method": "nuts", **check}

    return run


def one(seed: int, spec, features, recordings, run, pipeline: bool = False,
        duration: float | None = None, aligned: bool = False) -> dict:
    """One simulation: draw, (through the pipeline, or only aligned,) fit, rank."""
    import jax

    from bayeshopf.features.harmonics import align, extract_harmonics
    from bayeshopf.inference.nuts import rhat_ess
    from bayeshopf.model.prior_predictive import draw_data

    mu, sign = features.mu, np.where(features.unstable, -1.0, 1.0)
    se, omega_se = features.coeffs_se, features.omega_se
    key = jax.random.PRNGKey(seed)
    if pipeline or aligned:         # the draw without measurement noise, then measured
        d = draw_data(spec, mu, sign, np.zeros_like(se), key, omega_se=np.zeros_like(omega_se))
        rng = np.random.default_rng(seed)
    if pipeline:
        rs = synthesize(recordings, features.frame, d.coeffs, d.omega, rng, duration=duration)
        f = extract_harmonics(rs, n_harmonics=spec.n_harmonics, frame=features.frame)
        data = (f.coeffs, f.coeffs_se, f.omega, f.omega_se)
    elif aligned:
        data = (align(d.coeffs) + se * rng.standard_normal(se.shape), se,
                d.omega + omega_se * rng.standard_normal(omega_se.shape), omega_se)
    else:
        d = draw_data(spec, mu, sign, se, key, omega_se=omega_se)
        data = (d.coeffs, se, d.omega, omega_se)
    t0 = time.perf_counter()
    out = run(jax.random.PRNGKey(10**6 + seed), mu, sign, *data)
    chains, div, how = out if len(out) == 3 else (*out, {"method": "nuts"})
    wall = time.perf_counter() - t0
    pooled = {k: np.asarray(v).reshape(-1) for k, v in chains.items() if k in SITES}
    n = next(iter(pooled.values())).size
    pick = np.linspace(0, n - 1, L_DRAWS).round().astype(int)
    ranks = {k: int(np.sum(v[pick] < float(d.theta[k]))) for k, v in pooled.items()}
    conv = rhat_ess({k: np.asarray(v) for k, v in chains.items() if k in SITES})
    rhat = max(r for r, _ in conv.values())
    ess = min(e for _, e in conv.values())
    return {"seed": seed, "ranks": ranks, "truth": {k: float(d.theta[k]) for k in pooled},
            "divergences": div, "rhat_max": rhat, "ess_min": ess, "wall_s": wall, **how}


def results_path(name: str, pipeline: bool, duration: float | None, aligned: bool = False,
                 nn_width: int | None = 16, inference: str = "nuts") -> Path:
    """``benchmarks/results/sbc_<design>[_inf][_pipeline[_<D>s] | _aligned][_is].jsonl``."""
    tag = ("_aligned" if aligned else "" if not pipeline
           else "_pipeline" + ("" if duration is None else f"_{duration:g}s"))
    tag += "_is" if inference == "importance" else ""
    return RESULTS_DIR / f"sbc_{name}{'_inf' if nn_width is None else ''}{tag}.jsonl"


def parse_seeds(s: str) -> list[int]:
    a, _, b = s.partition("-")
    return list(range(int(a), int(b or a) + 1))


def run_design(name: str, seeds: list[int], warmup: int, samples: int,
               pipeline: bool = False, duration: float | None = None,
               aligned: bool = False, nn_width: int | None = 16,
               inference: str = "nuts") -> None:
    from bayeshopf._x64 import ensure_x64

    ensure_x64()
    spec, f, rs = design(name, nn_width)
    sign = np.where(f.unstable, -1.0, 1.0)
    runner = make_importance_runner if inference == "importance" else make_runner
    run = runner(spec, f.mu, sign, f.coeffs_se, f.omega_se, warmup, samples)
    out = results_path(name, pipeline, duration, aligned, nn_width, inference)
    out.parent.mkdir(parents=True, exist_ok=True)
    done = set()
    if out.exists():
        done = {json.loads(line)["seed"] for line in out.read_text().splitlines() if line}
    for seed in seeds:
        if seed in done:
            continue
        rec = one(seed, spec, f, rs, run, pipeline, duration, aligned)
        rec.update(design=name, warmup=warmup, samples=samples, pipeline=pipeline,
                   duration=duration, aligned=aligned, nn_width=nn_width)
        rec.setdefault("method", "nuts")
        with out.open("a") as fh:
            fh.write(json.dumps(rec) + "\n")
        print(f"sbc {out.stem}: seed {seed}: ranks mu0 {rec['ranks']['mu0']} fold "
              f"{rec['ranks']['mu_fold']} eta {rec['ranks']['eta']}; R̂ {rec['rhat_max']:.3f}, "
              f"{rec['divergences']} divergent, {rec['method']}, {rec['wall_s']:.1f} s",
              file=sys.stderr, flush=True)


def summary(seeds: list[int], infinite: bool = False) -> None:
    """The rows of the runs of ``seeds`` (at infinite width with ``infinite``, else the
    16-unit network's): ``sbc.json`` updated, their rank histograms drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy import stats

    table = {}
    shown = ("mu0", "mu_fold", "eta")
    runs = []
    for name in ("paired", "sweep"):
        for path in sorted(RESULTS_DIR.glob(f"sbc_{name}*.jsonl")):
            recs = [json.loads(x) for x in path.read_text().splitlines() if x]
            recs = [x for x in recs if x["seed"] in set(seeds)]
            if recs and ("_inf" in path.stem) == infinite:
                runs.append((path.stem.removeprefix("sbc_"), recs))
    fig, axes = plt.subplots(len(runs), len(shown), figsize=(10, 2.75 * len(runs)),
                             sharey=True, squeeze=False)
    for r, (name, recs) in enumerate(runs):
        seen = [x["seed"] for x in recs]
        row = {"n": len(recs), "seeds": [min(seen), max(seen)],
               "rhat_above_1.01": sum(x["rhat_max"] > 1.01 for x in recs),
               "with_divergences": sum(x["divergences"] > 0 for x in recs),
               "median_wall_s": float(np.median([x["wall_s"] for x in recs])), "sites": {}}
        if name.endswith("_is"):        # importance sampling, or NUTS where its check failed
            row["importance_used"] = sum(x.get("method") == "importance" for x in recs)
            row["pareto_k_max"] = max(x.get("pareto_k", np.nan) for x in recs)
        for site in SITES:
            ranks = np.array([x["ranks"][site] for x in recs if site in x["ranks"]])
            counts = np.bincount(ranks * BINS // (L_DRAWS + 1), minlength=BINS)
            p = float(stats.chisquare(counts).pvalue)
            row["sites"][site] = {"chi2_p": p, "counts": counts.tolist(),
                                  "mean_rank_fraction": float(np.mean(ranks) / L_DRAWS)}
        table[name] = row
        for c, site in enumerate(shown):
            ax = axes[r, c]
            s = row["sites"][site]
            ax.bar(np.arange(BINS), s["counts"], width=1.0, align="edge", color="C0",
                   edgecolor="white")
            ax.set_xlim(0, BINS)
            lo, hi = stats.binom.ppf([0.005, 0.995], row["n"], 1.0 / BINS)
            ax.axhline(row["n"] / BINS, color="k", lw=0.8, zorder=3)
            for y in (lo, hi):
                ax.axhline(y, color="0.2", lw=0.8, ls="--", zorder=3)
            label = {"mu0": "μ0 (Hopf)", "mu_fold": "fold", "eta": "η"}[site]
            p_text = "< 0.001" if s["chi2_p"] < 1e-3 else f"= {s['chi2_p']:.3f}"
            ax.set_title(f"{label}  (χ² p {p_text})", fontsize=9)
            ax.set_xticks([0, BINS // 2, BINS])
            ax.set_xticklabels(["0", "0.5", "1"])
            if r == len(runs) - 1:
                ax.set_xlabel("rank of the truth among the draws")
        parts = (name.replace("_inf", ", infinite width").replace("_is", ", importance")
                 .replace("_", ", ")).split(", ")
        run = ", ".join(parts[:2]) + ("\n" + ", ".join(parts[2:]) if parts[2:] else "")
        axes[r, 0].set_ylabel(f"{run}\nsimulations (of {row['n']})", fontsize=8)
    fig.suptitle("Simulation-based calibration: ranks of the truth among 99 posterior draws "
                 "(solid: expected count; dashed: 99% range of a bin under uniform ranks)",
                 fontsize=9)
    fig.tight_layout()
    is_only = "_is" if all(n.endswith("_is") for n, _ in runs) else ""
    fig.savefig(ROOT / "docs" / f"sbc_ranks{'_inf' if infinite else ''}{is_only}.png", dpi=110)
    path = Path(__file__).with_name("sbc.json")
    kept = json.loads(path.read_text()) if path.exists() else {}
    atomic_write(path, json.dumps({**kept, **table}, indent=1) + "\n")
    for name, row in table.items():
        print(f"{name}: n {row['n']}, R̂ > 1.01 in {row['rhat_above_1.01']}, divergences in "
              f"{row['with_divergences']}, median {row['median_wall_s']:.1f} s")
        for site, s in row["sites"].items():
            print(f"  {site:10s} χ² p {s['chi2_p']:.3f}  mean rank {s['mean_rank_fraction']:.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--design", choices=("paired", "sweep"))
    ap.add_argument("--seeds", default="0-199")
    ap.add_argument("--warmup", type=int, default=300)
    ap.add_argument("--samples", type=int, default=300)
    ap.add_argument("--pipeline", action="store_true",
                    help="through time series and the feature extraction")
    ap.add_argument("--duration", type=float, default=None,
                    help="with --pipeline: keep the first D seconds of each record")
    ap.add_argument("--aligned", action="store_true",
                    help="coefficients only moved to the crest's time origin (no time series)")
    ap.add_argument("--nn-width", default="16",
                    help="hidden units of the map's network, or 'inf' for its infinite width")
    ap.add_argument("--inference", choices=("nuts", "importance"), default="nuts",
                    help="the posterior: the benchmark's NUTS, or the package's importance "
                    "sampling (NUTS where its check fails)")
    ap.add_argument("--summary", action="store_true")
    a = ap.parse_args()
    nn_width = None if a.nn_width == "inf" else int(a.nn_width)
    if a.summary:
        summary(parse_seeds(a.seeds), infinite=nn_width is None)
    elif a.design:
        if a.duration is not None and not a.pipeline:
            ap.error("--duration needs --pipeline")
        if a.aligned and a.pipeline:
            ap.error("--aligned and --pipeline are two different runs; give one")
        run_design(a.design, parse_seeds(a.seeds), a.warmup, a.samples, a.pipeline, a.duration,
                   a.aligned, nn_width, a.inference)
    else:
        ap.error("--design or --summary expected")


if __name__ == "__main__":
    main()
