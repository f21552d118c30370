"""Where the rig's fit misses, and what drives its held-out failures.

Run: ``python benchmarks/bench_rig_anatomy.py`` (20 s on 2 cores with a warm cache).
Writes ``benchmarks/results/rig_anatomy.json``; ``docs/validation.md`` quotes what it measures. Five
parts, on the 7 recordings in ``../shared/data/flutter_cbc``, all without the
control term (``CollapsedSettings(control=False)``: the model of stop 43, whose
misses this benchmark takes apart; ``bench_rig_control.py`` adds the term):

1. **The curved unfolding through the three pairs.** The pair invariant
   ``x = (A_s A_u)²/(A_s² + A_u²)²`` (map-free, ``diagnostics.pair_invariant``)
   equals ``−β(μ)/a2²`` with ``β(μ) = (e^{b(μ−μ0)} − 1)/b``: three pairs, three
   unknowns ``(μ0, b, a2)``, solved exactly (SciPy's ``least_squares``) for the
   measured ``x`` and for each of 400 draws of ``x`` from the segments' spread;
   the fold is where ``x = 1/4``, and ``w = b(μ0 − μ_SN)``.
2. **Each orbit's error by harmonic.** The default fit (seed 0): the orbit
   error of ``HybridPosterior.orbit_error`` split into the centre and each
   harmonic (their squares add up to the square of the total), and the
   fundamental's ratio and phase of ``w2`` to ``w1``, measured and predicted.
3. **Second harmonics against the map's quadratic terms.** At one μ they make
   a second harmonic ∝ r² on the circle of radius r, so ``h2/h1`` of the
   smaller orbit of a pair would be ``r_u/r_s`` times the larger one's
   (``r_u/r_s`` from ``x``; ``smooth_map_bound`` in the file, a leading-order
   value: part 4 shows the network's features can give more); measured
   ``h2/h1`` of ``w1`` for both.
4. **The map without its prior.** At the fit's normal form (posterior medians
   of μ0, the fold and ``w``), the map's coefficients by weighted least
   squares (weights 1/se, no prior), with all 46 basis functions per channel
   (for 63 numbers) and with groups of them left out: how close the model
   class can come to each orbit with the Hopf point and the fold where they
   are.
5. **Profiles of the held-out failures.** The log joint density maximised over
   every other site with the fold's gap (or the Hopf point's gap) held at each
   value of a grid (NumPyro's ``condition``; L-BFGS-B from the deterministic
   start and two jittered ones), on the recordings without the unstable 14.9
   m/s one (the fold) and without the unstable 16.5 m/s one (the Hopf point),
   and on all seven; each model factor's share at each point.
"""

import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
from _common import RESULTS_DIR, atomic_write  # noqa: E402

DATA = HERE.parent.parent / "shared/data/flutter_cbc"


def curved_through_pairs(mu, x):
    """``(μ0, μ_SN, w, a2)`` of the curved unfolding through three ``x(μ)``, or ``None``."""
    from scipy.optimize import least_squares

    def resid(p):
        mu0, b, a2 = p
        return (1.0 - np.exp(b * (mu - mu0))) / (b * a2**2) - x

    best = None
    for b0 in (0.3, 1.0, 2.0):
        r = least_squares(resid, [mu.max() + 0.5, b0, 2.0])
        if best is None or r.cost < best.cost:
            best = r
    mu0, b, a2 = best.x
    if best.cost > 1e-12 or b * a2**2 / 4 >= 1 or b <= 0:
        return None
    fold = mu0 + np.log(1 - b * a2**2 / 4) / b
    return float(mu0), float(fold), float(b * (mu0 - fold)), float(a2)


def part_pairs(f):
    from bayeshopf.diagnostics.pair_invariant import pair_invariants
    from bayeshopf.diagnostics.summaries import interval

    pairs = pair_invariants(f, n_draws=400)
    mu = np.array([p.mu for p in pairs])
    x = np.array([p.x for p in pairs])
    point = curved_through_pairs(mu, x)
    draws = [curved_through_pairs(mu, np.array([p.draws[k] for p in pairs]))
             for k in range(len(pairs[0].draws))]
    ok = np.array([d for d in draws if d is not None])
    return {"mu": mu.tolist(), "x": x.tolist(),
            "point": dict(zip(("mu0", "mu_fold", "w", "a2"), point, strict=True)),
            "solved_fraction": len(ok) / len(draws),
            **{k: interval(ok[:, j]).to_json() for j, k in enumerate(("mu0", "mu_fold", "w"))}}


def part_orbits(post):
    """``HybridPosterior.orbit_error`` with the predicted amplitude and the pitch–heave shape."""
    f = post.features
    K = post.spec.n_harmonics
    ppc = post.ppc()

    def shape(c):
        z1, z2 = c[0, 1] + 1j * c[0, K + 1], c[1, 1] + 1j * c[1, K + 1]
        return {"ratio": float(abs(z2 / z1)), "phase_deg": float(np.angle(z2 / z1, deg=True))}

    rows = []
    for i, (e, c) in enumerate(zip(post.orbit_error(), post.training_coefficients, strict=True)):
        model = np.median(c[np.all(np.isfinite(c), axis=(1, 2))], axis=0)
        rows.append({"name": e["name"], "mu": float(f.mu[i]), "unstable": bool(f.unstable[i]),
                     "total": e["relative"], "by_harmonic": e["by_harmonic"],
                     "amplitude_measured": float(f.amplitude[i]),
                     "amplitude_predicted": ppc.predictive[i].to_json(),
                     "w2_over_w1_measured": shape(f.coeffs[i]), "w2_over_w1_model": shape(model)})
    return rows


def part_harmonics(f):
    from bayeshopf.diagnostics.pair_invariant import pair_invariants

    K = f.coeffs.shape[-1] // 2
    rows = []

    def h21(i):
        c = f.coeffs[i, 0]
        return float(abs(c[2] + 1j * c[K + 2]) / abs(c[1] + 1j * c[K + 1]))

    for p in pair_invariants(f, n_draws=10):
        u = list(f.names).index(p.unstable)
        stables = [list(f.names).index(s) for s in np.atleast_1d(p.stable)]
        s = min(stables, key=lambda j: abs(f.mu[j] - p.mu))
        root = np.sqrt(1 - 4 * p.x)
        ratio = float(np.sqrt((1 - root) / (1 + root)))
        rows.append({"mu": p.mu, "unstable": p.unstable, "stable": f.names[s],
                     "r_u_over_r_s": ratio, "h2_h1_stable": h21(s), "h2_h1_unstable": h21(u),
                     "smooth_map_bound": ratio * h21(s)})
    return rows


def part_least_squares(post):
    import jax.numpy as jnp

    import bayeshopf.model.collapsed as cm
    from bayeshopf.features.harmonics import reconstruct
    from bayeshopf.posterior import orbit_error_parts

    f = post.features
    theta = {k: jnp.asarray(np.median(np.asarray(post.samples[k])))
             for k in ("mu0", "mu_fold", "w_unfold", "a2")}
    sign = np.where(f.unstable, -1.0, 1.0)
    Phi = np.asarray(cm.design(post.spec, jnp.asarray(f.mu), jnp.asarray(sign), theta))
    n, m, J = Phi.shape
    names = cm.basis_names(post.spec)
    net = np.array([nm.startswith("nn") for nm in names])
    mu2 = np.array(["m^2" in nm for nm in names])
    groups = {"all": ~np.zeros(J, bool), "polynomial only": ~net,
              "without the mu^2 terms": ~mu2, "polynomial without the mu^2 terms": ~net & ~mu2}
    phi = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    radius = [np.sqrt(np.mean(np.sum((o - o.mean(0)) ** 2, -1)))
              for o in (reconstruct(c, phi) for c in f.coeffs)]
    out = {}
    for label, keep in groups.items():
        P = Phi[:, :, keep].reshape(n * m, -1)
        pred = np.empty_like(f.coeffs)
        for c in range(2):
            w = 1.0 / f.coeffs_se[:, c].reshape(-1)
            beta = np.linalg.lstsq(P * w[:, None], f.coeffs[:, c].reshape(-1) * w, rcond=None)[0]
            pred[:, c] = (P @ beta).reshape(n, m)
        parts = [orbit_error_parts(pred[i], f.coeffs[i]) / radius[i] for i in range(n)]
        out[label] = {"n_basis": int(keep.sum()),
                      "orbit_error": {f.names[i]: float(np.sqrt(np.sum(p**2)))
                                      for i, p in enumerate(parts)},
                      "by_harmonic": {f.names[i]: p.tolist() for i, p in enumerate(parts)}}
    return {"theta": {k: float(v) for k, v in theta.items()}, "groups": out}


def profile(f, site, values, drop):
    """The profile over the fold (``site="gap_fold"``) or μ0 (``"gap_hopf"``) at ``values``."""
    import jax
    import jax.numpy as jnp
    from jax.flatten_util import ravel_pytree
    from numpyro import handlers
    from numpyro.infer.util import constrain_fn, init_to_value, initialize_model, potential_energy
    from scipy.optimize import minimize

    import bayeshopf.inference.collapsed as ci
    import bayeshopf.model.collapsed as cm

    keep = [j for j in range(f.n_recordings) if f.names[j] != drop]
    sub = f.subset(keep)
    spec = ci.build_spec(sub, "subcritical", control=False)
    kw = ci.model_arguments(spec, sub)
    start = {k: v for k, v in ci._initial_values(spec).items() if k != site}
    # μ_SN = μ_min − gap_fold; μ0 = μ_u,max + gap_hopf (the fold lies below every recording)
    grid = [spec.mu_min - v if site == "gap_fold" else v - spec.mu_unstable_max for v in values]
    factors = ("marginal_0", "marginal_1", "marginal_omega", "w_unfold", "gap_fold", "gap_hopf",
               "tau_mu", "tau_shape", "sigma", "sigma_rel", "sigma_omega")
    info = initialize_model(jax.random.PRNGKey(0),
                            handlers.condition(cm.collapsed_model, {site: jnp.asarray(grid[0])}),
                            model_kwargs=kw, init_strategy=init_to_value(values=start),
                            validate_grad=False)
    x0, unravel = ravel_pytree(info.param_info.z)

    def potential(x, g):       # one program for the whole grid: the held value is an argument
        model = handlers.condition(cm.collapsed_model, {site: g})
        return potential_energy(model, (), kw, unravel(x))

    vg = jax.jit(jax.value_and_grad(potential))
    rows = []
    for g in grid:
        best = None
        for k in range(3):
            xs = np.asarray(x0) + (0.0 if k == 0 else
                                   0.3 * np.random.default_rng(k).standard_normal(x0.shape))
            r = minimize(lambda x, g=g: tuple(np.asarray(a, float)
                                              for a in vg(jnp.asarray(x), jnp.asarray(g))),
                         xs, jac=True, method="L-BFGS-B", options={"maxiter": 2000})
            if best is None or r.fun < best.fun:
                best = r
        model = handlers.condition(cm.collapsed_model, {site: jnp.asarray(g)})
        cons = constrain_fn(model, (), kw, unravel(jnp.asarray(best.x)), return_deterministic=True)
        tr = handlers.trace(handlers.substitute(model, data=cons)).get_trace(**kw)
        parts = {n: float(jnp.sum(s["fn"].log_prob(s["value"]))) for n, s in tr.items()
                 if s["type"] == "sample" and n in factors}
        rows.append({site: float(g), "log_joint": float(-best.fun), "factors": parts,
                     **{k: float(cons[k]) for k in ("mu0", "mu_fold", "w_unfold", "a2")}})
        print(f"  {site} {g:4.2f}: log joint {-best.fun:8.2f}, mu0 {float(cons['mu0']):.3f}, "
              f"fold {float(cons['mu_fold']):.3f}", flush=True)
    return {"site": site, "dropped": drop, "rows": rows}


def main():
    from bayeshopf.inference.cache import configure_xla_cpu

    configure_xla_cpu()
    from bayeshopf.data import load_recordings
    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.posterior import fit_hybrid

    f = extract_harmonics(load_recordings(DATA))
    out = {"pairs": part_pairs(f)}
    print("curved unfolding through the pairs:", out["pairs"]["point"])
    post = fit_hybrid(f, "subcritical", seed=0, progress=False,
                      settings=CollapsedSettings(control=False))
    out["orbits"] = part_orbits(post)
    out["second_harmonics"] = part_harmonics(f)
    out["least_squares"] = part_least_squares(post)
    folds = (14.85, 14.7, 14.5, 14.3, 14.1, 13.9, 13.6)
    hopfs = (16.6, 16.9, 17.2, 17.7, 18.2, 18.7, 19.2)
    out["profiles"] = [profile(f, "gap_fold", folds, "CBC_unstable_v14_9.mat"),
                       profile(f, "gap_fold", folds, None),
                       profile(f, "gap_hopf", hopfs, "CBC_unstable_v16_5.mat"),
                       profile(f, "gap_hopf", hopfs, None)]
    atomic_write(RESULTS_DIR / "rig_anatomy.json", json.dumps(out, indent=1))


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    sys.exit(main())
