"""How far is a simulated rig's amplitude curve from the quintic normal form's?

    python benchmarks/bench_normal_form_order.py --seeds 1513,1546,… [--pairs-only]

For each seed's system (``bench_loo_reference_class.draw_system(seed, effects=True)``,
the systems of ``bench_discrepancy_coverage.py``) the paired design's orbits are
recorded without noise (10 s at 500 Hz), and ``A²``, the squared fundamental summed
over both frame axes, is fitted by least squares with

* ``μ = μ0 + p A² + q A⁴`` (order 2): the normal form ``ṙ = β r + a2 r³ − r⁵`` with
  ``β = μ − μ0`` seen through a map that only scales the radius (``A ∝ r``);
* ``μ = μ0 + p A² + q A⁴ + s A⁶`` (order 3): one more order, ``+ a3 r⁷``;
* ``β(μ) = p A² + q A⁴`` with the curved unfolding ``β = (e^{b(μ−μ0)} − 1)/b`` of
  :func:`bayeshopf.model.spec.unfolding` (``curved``): the model's own normal form,
  ``μ = μ0 + log(1 + b(p A² + q A⁴))/b``, fitted by SciPy's ``least_squares``.

It reports each fit's rms misfit in μ and its μ0 and fold (the smallest μ of the
fitted curve) minus the truth's. And where the design's **pairs** put the fold: at
each unstable recording's μ the ratio ``ρ = A_u/A_s`` of the two branches'
peak-to-peak (the continuation's, no noise) fixes ``−β(μ)/a2² = ρ²/(1 + ρ²)²``
for any map that only scales the radius (the branches' ``r²`` are the roots of
``r⁴ − a2 r² − β = 0``); the curved unfolding through the three pairs (μ0, the
fold and ``b``, by ``least_squares``) extrapolates to the fold, where ``ρ = 1``.

What the order-2 fit misses, the model's map (its μ-dependent gain, its network)
must absorb, and its prior then decides how μ0 and the fold are extrapolated.
``--pairs-only`` skips the recordings and the fits of ``A²`` (the pairs need only
the continuation). Writes ``benchmarks/results/normal_form_order.jsonl``.
"""

from __future__ import annotations

import json
import sys

from _common import RESULTS_DIR, exit_on_help

exit_on_help(__doc__)

import numpy as np  # noqa: E402


def one(seed: int, pairs_only: bool = False) -> dict:
    from bench_discrepancy_coverage import DESIGNS
    from bench_loo_reference_class import draw_system

    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.simulators import simulate_recordings

    system, diagram, values, why = draw_system(seed, effects=True)
    if diagram is None:
        return {"seed": seed, "skipped": str(why)}
    fold, hopf = diagram.folds[0].mu, diagram.hopf.mu
    d = DESIGNS["paired"]
    at = np.array([fold + x * (hopf - fold) for x in d["unstable"]])
    if pairs_only:      # the continuation's branches only, no recordings
        return {"seed": seed, "effect": values.get("effect"), "hopf": hopf, "fold": fold,
                "pairs": pairs(diagram, system.observed[0], at)}
    plan = [(fold + x * (hopf - fold), "stable") for x in d["stable"]] + \
           [(fold + x * (hopf - fold), "unstable") for x in d["unstable"]]
    rs = simulate_recordings(system, [m for m, _ in plan], [b for _, b in plan], noise=0.0,
                             duration_s=10.0, sample_rate_hz=500.0, seed=seed, diagram=diagram)
    f = extract_harmonics(rs)
    K = f.n_harmonics
    a2 = np.sum(f.coeffs[:, :, 1] ** 2 + f.coeffs[:, :, K + 1] ** 2, axis=1)
    out = {"seed": seed, "effect": values.get("effect"), "hopf": hopf, "fold": fold}
    grid = np.linspace(0.0, 1.5 * a2.max(), 20001)
    for order in (2, 3):
        X = np.stack([a2**k for k in range(order + 1)], axis=1)
        c, *_ = np.linalg.lstsq(X, f.mu, rcond=None)
        curve = sum(c[k] * grid**k for k in range(order + 1))
        if order == 2:
            out["_c2"] = c
        out[f"order{order}"] = {"mu0_error": float(c[0] - hopf),
                                "fold_error": float(curve.min() - fold),
                                "rms": float(np.sqrt(np.mean((X @ c - f.mu) ** 2)))}
    from scipy.optimize import least_squares

    c2 = out.pop("_c2")

    def curved(x, s):
        mu0, b, p, q = x
        return mu0 + np.log1p(b * (p * s + q * s**2)) / b

    fit = least_squares(lambda x: curved(x, a2) - f.mu, [c2[0], 1e-3, c2[1], c2[2]],
                        x_scale="jac", max_nfev=20000)
    with np.errstate(invalid="ignore"):
        curve = curved(fit.x, grid)
    out["curved"] = {"mu0_error": float(fit.x[0] - hopf),
                     "fold_error": float(np.nanmin(curve) - fold),
                     "rms": float(np.sqrt(np.mean(fit.fun**2))), "b_dmu": float(fit.x[1])}
    out["pairs"] = pairs(diagram, system.observed[0], at)
    return out


def pairs(diagram, name: str, mu: np.ndarray) -> dict:
    """The curved unfolding through the branches' amplitude ratios at ``mu`` (module docstring)."""
    from scipy.optimize import least_squares

    def amplitude(kind):
        b = diagram.branch(kind)
        m, a = np.asarray(b.mu), np.asarray(b.amplitude[name])
        order = np.argsort(m)
        return np.interp(mu, m[order], a[order])

    rho = amplitude("unstable") / amplitude("stable")
    target = rho**2 / (1 + rho**2) ** 2            # −β(μ)/a2², 1/4 at the fold

    def ratio(x):
        mu0, fold, b = x
        return np.expm1(b * (mu - mu0)) / (4 * np.expm1(b * (fold - mu0)))

    fold, hopf = diagram.folds[0].mu, diagram.hopf.mu
    fit = least_squares(lambda x: ratio(x) - target, [hopf, fold, 1e-3])
    return {"fold_error": float(fit.x[1] - fold), "mu0_error": float(fit.x[0] - hopf),
            "b": float(fit.x[2]), "residual": float(np.max(np.abs(fit.fun)))}


def main(argv) -> None:
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu()
    if "--seeds" not in argv:
        sys.exit("--seeds: a comma-separated list of seeds expected")
    seeds = [int(s) for s in argv[argv.index("--seeds") + 1].split(",")]
    path = RESULTS_DIR / "normal_form_order.jsonl"
    path.parent.mkdir(parents=True, exist_ok=True)
    for seed in seeds:
        row = one(seed, pairs_only="--pairs-only" in argv)
        with path.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
