r"""Integrating θ alone vs the Cartesian normal form, with the same speed model Ω.

Both integrate the hybrid model's orbits for the speed stage:

* **polar** (bayeshopf): ``θ̇ = Ω(r(μ), θ, μ)`` with r fixed at the closed-form LCO
  radius (eq. NF-model-polar, second line);
* **Cartesian** (the paper's eq. NF-model, as the authors' Van der Pol script):
  ``u̇1 = (μ−μ0) u1 − u2 Ω + a2 u1 ρ² − u1 ρ⁴``,
  ``u̇2 = (μ−μ0) u2 + u1 Ω + a2 u2 ρ² − u2 ρ⁴``, ``ρ² = u1² + u2²``, with
  ``Ω(ρ, atan2(u2, u1), μ)``, started on the LCO.

Measured, for a synthetic map and speed (:func:`_setup`, the shapes of a fit:
7 recordings, 10 periods at 30 samples per period), after compilation:

1. seconds per loss + gradient evaluation (the cost that the MAP and SVI stages
   repeat), with Tsit5 at rtol = atol = 1e-6, and the accepted ODE steps;
2. the **time to fit**: the same optax Adam run (``--fit-steps`` steps, step
   size 1e-2) on both losses from the same start, towards trajectories made
   with a 1% faster ω0; wall time after compilation, the final loss relative
   to the first, and the error of the recovered ω0;
3. the drift ``|ρ(t) − r_u| / r_u`` of the Cartesian solution on an unstable
   LCO after N periods (the polar one has none by construction). The unstable
   LCO's Floquet exponent is ``dṙ/dr = 2√(a2² + 4(μ−μ0)) r_u² > 0``, so any
   solver error grows like ``e^{λ t}``.

The normal form's time is the speed model's (seconds), as in the authors' code.
Run ``python benchmarks/bench_speed.py``; it prints a markdown table and writes
it to ``benchmarks/speed.md``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import optax

from bayeshopf.features.frame import PlanarFrame
from bayeshopf.model import normal_form
from bayeshopf.model import speed as sp
from bayeshopf.model.coordinate_map import U12, MLPParams, linear_map, lower_triangular
from bayeshopf.model.hybrid import HopfParams, ModelSpec, orbit_at

MU = np.array([15.3, 16.7, 18.1, 19.5, 15.6, 16.5, 17.4])
SIGN = np.array([1.0, 1.0, 1.0, 1.0, -1.0, -1.0, -1.0])


def _mlp(key, shapes, scale):
    ks = jax.random.split(key, 2 * len(shapes))
    W = tuple(scale * jax.random.normal(ks[2 * i], s) for i, s in enumerate(shapes))
    b = tuple(scale * jax.random.normal(ks[2 * i + 1], (s[1],)) for i, s in enumerate(shapes))
    return MLPParams(W, b)


def _setup(n_h: int = 1):
    mspec = ModelSpec(criticality="subcritical", frame=PlanarFrame(np.zeros(2), np.eye(2)),
                      n_h=4, mu_centre=17.0, mu_span=1.5, mu_min=15.0, mu_unstable_max=17.4,
                      orbit_scale=1.0)
    mp = HopfParams(
        mu0=jnp.asarray(18.0), a2=jnp.asarray(3.4),
        T_L=linear_map(jnp.array([0.8, 0.5]), jnp.asarray(0.3), jnp.array([0.05, -0.02])),
        T_L1=lower_triangular(jnp.array([0.05, 0.02]), jnp.asarray(0.01)),
        T_s=jnp.array([0.03, -0.02]), nn=_mlp(jax.random.PRNGKey(0), mspec.nn_shapes, 1.0),
        nn_scale=jnp.asarray(0.05),
    )
    spec = sp.SpeedSpec(n_h=n_h, nn_width=8, nn_depth=1, omega_ref=15.7)
    p = sp.SpeedParams(jnp.asarray(15.7), _mlp(jax.random.PRNGKey(1), spec.nn_shapes, 0.5),
                       jnp.asarray(0.5))
    t = jnp.tile(jnp.linspace(0.0, 10 / 2.5, 301), (len(MU), 1))
    return mspec, mp, spec, p, t


def cartesian_solve(p, mp, mu, sign, theta0, t, spec, mspec, rtol=1e-6):
    """``(u1, u2)`` of eq. NF-model from the LCO point at θ0; returns (u, steps)."""
    r = normal_form.lco_radius(mu, mp.mu0, mp.a2, sign)
    mt = mspec.mu_tilde(mu)

    def field(s, u, args):
        rho2 = u[0] ** 2 + u[1] ** 2
        om = sp.speed(p, jnp.sqrt(rho2), jnp.arctan2(u[1], u[0]), mt, spec)
        rad = (mu - mp.mu0) + mp.a2 * rho2 - rho2**2
        return jnp.stack([rad * u[0] - om * u[1], rad * u[1] + om * u[0]])

    u0 = r * jnp.stack([jnp.cos(theta0), jnp.sin(theta0)])
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field), diffrax.Tsit5(), t0=t[0], t1=t[-1], dt0=None, y0=u0,
        saveat=diffrax.SaveAt(ts=t), stepsize_controller=diffrax.PIDController(rtol=rtol,
                                                                               atol=rtol),
        max_steps=16384, throw=False,
    )
    return sol.ys, sol.stats["num_accepted_steps"]


def _losses(mspec, mp, spec, t, target_polar):
    mu, sign = jnp.asarray(MU), jnp.asarray(SIGN)
    th0 = jnp.zeros(len(MU))

    def polar(p):
        def one(m, s, a, tt):
            r = normal_form.lco_radius(m, mp.mu0, mp.a2, s)
            th, n = sp.integrate_phase(p, r, mspec.mu_tilde(m), a, tt, spec, return_steps=True)
            return orbit_at(mp, m, s, th, mspec), n

        w, n = jax.vmap(one)(mu, sign, th0, t)
        return jnp.sum((w - target_polar) ** 2), n

    def cart(p):
        def one(m, s, a, tt):
            u, n = cartesian_solve(p, mp, m, s, a, tt, spec, mspec)
            mt = mspec.mu_tilde(m)
            return U12(u, mt, mp.T_L, mp.T_L1, mp.T_s, mp.nn, mp.nn_scale), n

        w, n = jax.vmap(one)(mu, sign, th0, t)
        return jnp.sum((w - target_polar) ** 2), n

    return polar, cart


def _time(f, p, repeat):
    out = f(p)
    jax.block_until_ready(out)
    t0 = time.perf_counter()
    for _ in range(repeat):
        out = f(p)
        jax.block_until_ready(out)
    return (time.perf_counter() - t0) / repeat, out


VALIDATION_NOTE = (
    "Frequencies and phase errors of fitted speed models against the truth (Van der Pol, "
    "the 3-DOF aerofoil, the wind-tunnel rig): `benchmarks/speed_validation.md` "
    "(`python benchmarks/validate_speed.py`)."
)


def fit_time(loss, p0, steps: int, learning_rate: float = 1e-2):
    """Adam on ``loss`` from ``p0``: (compile s, fit s, first loss, last loss, fitted params)."""
    opt = optax.adam(learning_rate)

    @jax.jit
    def step(p, state):
        value, grad = jax.value_and_grad(loss)(p)
        updates, state = opt.update(grad, state, p)
        return optax.apply_updates(p, updates), state, value

    state = opt.init(p0)
    t0 = time.perf_counter()
    jax.block_until_ready(step(p0, state))
    compile_s = time.perf_counter() - t0
    p, values = p0, []
    t0 = time.perf_counter()
    for _ in range(steps):
        p, state, value = step(p, state)
        values.append(value)
    jax.block_until_ready(p)
    fit_s = time.perf_counter() - t0
    return compile_s, fit_s, float(values[0]), float(loss(p)), p


def main(argv=None) -> int:
    """Run the benchmark and write the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--fit-steps", type=int, default=300)
    ap.add_argument("--out", default=str(Path(__file__).with_name("speed.md")))
    args = ap.parse_args(argv)
    mspec, mp, spec, p, t = _setup()
    # target: the polar model's own trajectories with a perturbed speed (a non-zero loss)
    p_true = p._replace(omega0=p.omega0 * 1.01)
    target = jax.vmap(lambda m, s, tt: sp.trajectory_in_frame(p_true, mp, m, s, 0.0, tt, spec,
                                                              mspec))(MU, SIGN, t)
    polar, cart = _losses(mspec, mp, spec, t, target)
    rows = []
    for name, f in (("polar θ̇ = Ω", polar), ("Cartesian (u1, u2)", cart)):
        vg = jax.jit(jax.value_and_grad(lambda q, f=f: f(q)[0]))
        steps = jax.jit(lambda q, f=f: f(q)[1])
        t_c0 = time.perf_counter()
        jax.block_until_ready(vg(p))
        compile_s = time.perf_counter() - t_c0
        sec, _ = _time(vg, p, args.repeat)
        n = np.asarray(steps(p))
        rows.append((name, compile_s, sec, int(n.sum()), int(n[SIGN < 0].max())))
    fits = []
    for name, f in (("polar θ̇ = Ω", polar), ("Cartesian (u1, u2)", cart)):
        c, sec, first, last, q = fit_time(lambda x, f=f: f(x)[0], p, args.fit_steps)
        fits.append((name, c, sec, first, last,
                     abs(float(q.omega0) / float(p_true.omega0) - 1.0)))
    # radius drift of the Cartesian solution on an unstable LCO
    drift = []
    for m in (15.6, 16.5, 17.4):
        r_u = float(normal_form.lco_radius(m, mp.mu0, mp.a2, -1.0))
        T = float(sp.period(p, r_u, mspec.mu_tilde(m), spec))
        periods = np.array([1, 5, 10, 20, 40])
        tt = jnp.asarray(np.concatenate([[0.0], periods * T]))
        lam = 2.0 * np.sqrt(float(mp.a2) ** 2 + 4.0 * (m - float(mp.mu0))) * r_u**2
        row = [m, r_u, lam]
        for rtol in (1e-6, 1e-10):
            u, _ = cartesian_solve(p, mp, m, -1.0, 0.3, tt, spec, mspec, rtol=rtol)
            rho = np.sqrt(np.sum(np.asarray(u) ** 2, axis=-1))[1:]
            row.append((rtol, np.abs(rho - r_u) / r_u))
        th = sp.integrate_phase(p, r_u, mspec.mu_tilde(m), 0.3, tt, spec)
        row.append(bool(np.all(np.isfinite(np.asarray(th)))))
        drift.append(row)
    lines = [
        "# Speed stage: integrating θ alone vs the Cartesian normal form",
        "",
        f"`python benchmarks/bench_speed.py` on {platform.machine()}, "
        f"{os.cpu_count()} CPUs (shared; load average {os.getloadavg()[0]:.1f} at the end), "
        f"JAX {jax.__version__}, float64; "
        "7 recordings (4 stable, 3 unstable), 10 periods, 301 saved samples each, "
        "Tsit5 with rtol = atol = 1e-6, n_h = 1, an 8-neuron speed MLP.",
        "",
        "| integration | compile (s) | loss + gradient (ms) | accepted steps (all 7) "
        "| max steps (unstable) |",
        "|---|---|---|---|---|",
    ]
    for name, c, s, n, nu in rows:
        lines.append(f"| {name} | {c:.1f} | {1e3 * s:.1f} | {n} | {nu} |")
    lines += [
        "",
        f"Time to fit: {args.fit_steps} optax Adam steps (step size 1e-2) on each loss from "
        "the same start, towards trajectories made with a 1% faster ω0 (the speed MLP is "
        "free too).",
        "",
        "| integration | compile (s) | fit (s) | loss: first → last | ω0 error after the fit |",
        "|---|---|---|---|---|",
    ]
    for name, c, sec, first, last, err in fits:
        lines.append(f"| {name} | {c:.1f} | {sec:.1f} | {first:.3g} → {last:.3g} "
                     f"| {100 * err:.2f}% |")
    lines += [
        "",
        "Relative radius drift `|ρ − r_u|/r_u` of the Cartesian solution started on an "
        "unstable LCO (Floquet exponent λ = 2√(a2² + 4(μ−μ0)) r_u², in 1/s); the polar "
        "integration stays on r_u exactly (r is not integrated).",
        "",
        "| μ | r_u | λ (1/s) | rtol | after 1 | 5 | 10 | 20 | 40 periods |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for m, r_u, lam, (tol1, d1), (tol2, d2), _ in drift:
        for tol, d in ((tol1, d1), (tol2, d2)):
            cells = " | ".join(f"{x:.1e}" for x in d)
            lines.append(f"| {m:g} | {r_u:.3f} | {lam:.2f} | {tol:g} | {cells} |")
    lines += ["", VALIDATION_NOTE]
    text = "\n".join(lines) + "\n"
    print(text)
    tmp = Path(args.out).with_suffix(".tmp")
    tmp.write_text(text)
    tmp.replace(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
