r"""Periodic orbits of a system at many (μ, parameter) points at once, warm-started.

For recordings at :math:`\mu_1..\mu_R` the orbits are solved together: one
vectorised (``jax.vmap``) shooting solve per Newton iteration integrates the
orbits still iterating with their monodromy matrices. Newton's method solves, per
orbit, :math:`\varphi_T(x_0) - x_0 = 0` and :math:`(x_0 - \hat x)\cdot f(\hat x) = 0`
(:mod:`bayeshopf.simulators.periodic`) from a warm start
:math:`(\hat x, \hat T)`. Changing a coefficient of the system is a
*homotopy*: the orbits at the old value start the Newton solve at the new one,
and an orbit that does not converge is retried in 4, then 16 smaller steps.
An orbit is *lost* when it still does not converge, or when its Floquet
stability no longer matches its branch label (it crossed a fold onto the
other branch): that branch has no orbit at that μ for these parameters.
Newton's steps shrink quadratically near a solution, so an orbit whose step,
from the fifth iteration on, has not fallen by a tenth over two iterations
(:data:`STALL_FACTOR`) is taken as not converging and stopped there (it goes to
the smaller homotopy steps), rather than iterated to ``max_iter``.

The parameters are arguments of the compiled solver, so one compilation
serves every coefficient value.

**Exact sensitivities** (:func:`sensitivities`). At a converged orbit the
shooting system :math:`G(x_0, T; p) = 0` (the two equations above, with the
phase plane through :math:`x_0` itself) fixes the orbit as a function of the
parameters; by the implicit function theorem

.. math::

    \begin{pmatrix} Φ - I & f(x_1) \\ f(x_0)^T & 0 \end{pmatrix}
    \begin{pmatrix} ∂x_0/∂p \\ ∂T/∂p \end{pmatrix}
    = -\begin{pmatrix} ∂φ_T/∂p \\ 0 \end{pmatrix},

and the samples :math:`x(t_k) = φ_{t_k}(x_0; p)`, :math:`t_k = kT/N`, move by
:math:`∂φ_{t_k}/∂x_0 \, ∂x_0/∂p + (k/N) f(x(t_k)) \, ∂T/∂p + ∂φ_{t_k}/∂p`. The
flow's derivatives come from one forward-mode solve (``jax.jacfwd`` through
``diffrax.diffeqsolve`` with ``diffrax.ForwardMode``) per batch of orbits, and
the bordered matrix is the one Newton's method forms: no orbit is re-shot to
differentiate.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from bayeshopf._x64 import ensure_x64
from bayeshopf.simulators.base import System
from bayeshopf.simulators.compiled import program
from bayeshopf.simulators.periodic import floquet_stable, kernels, padded, split_shot

__all__ = ["OrbitBatch", "sensitivities", "solve_orbits", "track"]

#: Samples per period of the solved orbits (enough for harmonics up to ~20).
N_SAMPLES = 64
#: The solver's tolerances, matched to what the orbits are compared with: a
#: recording's features are rarely known to better than 10⁻⁵ of the orbit's size,
#: and a shot at these tolerances is within a few 10⁻⁸ of one at 10⁻¹².
_RTOL, _ATOL = 1e-7, 1e-10
#: Newton's convergence on its step relative to the orbit's size, well above the
#: shots' own error (which a smaller tolerance would chase as a stall).
TOL = 1e-6
#: Largest number of solver steps per period, far below the simulators' default:
#: a Newton iterate that blows up stops here.
_MAX_STEPS = 4096
#: A Newton iterate whose step exceeds this fraction of its step two iterations
#: earlier, from iteration :data:`STALL_FROM` on, is stopped as not converging.
STALL_FACTOR = 0.9
STALL_FROM = 5


def _kernels(system: System):
    """The shared kernels of :func:`bayeshopf.simulators.periodic.kernels`, without μ's.

    Newton's method here is at fixed μ, so the shots leave out the sensitivity to μ.
    """
    return kernels(system, _RTOL, _ATOL, max_steps=_MAX_STEPS, mu_sensitivity=False)


#: The batched programs by name: each builds, for a system (and static sizes), a
#: function of ``(*arrays, params)`` (:func:`_batched_call`).
_MAKERS = {
    # state, monodromy and f at the end of one period
    "shoot": lambda system: _kernels(system).shoot_batch,
    "field": lambda system: _kernels(system).f_batch,
    "sample": lambda system, n: (lambda x0, T, mu, p: _kernels(system).sample_batch(x0, T, mu,
                                                                                   p, n)),
    "flow": lambda system: _flow_jacobian(system.rhs),
}


def _batched_call(system: System, name: str, arrays: Sequence, p: dict, *static):
    """Program ``name`` of :data:`_MAKERS` on ``(*arrays, p)``, orbits padded (:func:`padded`).

    The rows added repeat the last one and are dropped from the result (every
    leaf, as NumPy arrays), so the compiled programs see one shape per power of
    two rather than one per number of orbits that a homotopy retries; they are
    stored across processes where the system's code allows
    (:mod:`bayeshopf.simulators.compiled`).
    """
    R = len(arrays[0])
    rows = padded(*arrays)
    fn = program(system.rhs, name, lambda: _MAKERS[name](system, *static), (*rows, p),
                 (_RTOL, _ATOL, _MAX_STEPS, N_SAMPLES, *static))
    return jax.tree_util.tree_map(lambda o: np.asarray(o)[:R], fn(*rows, p))


@dataclass(frozen=True)
class OrbitBatch:
    """Orbits at ``R`` points.

    Attributes:
        x0: Orbit points, shape ``(R, n)``.
        period: Periods, shape ``(R,)``.
        mu: μ of each, shape ``(R,)``.
        ok: Whether each orbit was found (on its branch), shape ``(R,)``.
        states: Samples over one period, shape ``(R, N_SAMPLES, n)`` (NaN where lost).
    """

    x0: np.ndarray
    period: np.ndarray
    mu: np.ndarray
    ok: np.ndarray
    states: np.ndarray


def _params(p: dict) -> dict:
    """The parameters as float64 NumPy scalars, which the compiled calls take as they are.

    A JAX array per parameter would cost a device transfer each, at every call;
    putting them on the device once per solve costs more than its calls save.
    """
    return {k: np.asarray(v, dtype=np.float64) for k, v in p.items()}


def solve_orbits(system: System, params: dict, x0, period, mu, stable, *,
                 max_iter: int = 20, tol: float | None = None, sample: bool = True
                 ) -> OrbitBatch:
    """Newton's method for all orbits from the warm starts ``(x0, period)`` (module docstring).

    Args:
        system: The system (its compiled shooting is cached per system).
        params: All parameters of the system by name.
        x0: Warm-start points, shape ``(R, n)``.
        period: Warm-start periods, shape ``(R,)``.
        mu: μ of each orbit.
        stable: Expected Floquet stability of each (its branch).
        max_iter: Largest number of Newton steps.
        tol: Convergence on the Newton step relative to the orbit's size (default
            :data:`TOL`).
        sample: Sample the orbits found (``states``); otherwise ``states`` is NaN.
    """
    ensure_x64()
    tol = TOL if tol is None else tol
    p = _params(params)
    xhat = np.array(x0, dtype=np.float64)
    R, n = xhat.shape
    mu = np.asarray(mu, dtype=np.float64)
    fhat = _batched_call(system, "field", (xhat, mu), p)
    x, T = xhat.copy(), np.array(period, dtype=np.float64)
    done = np.zeros(R, bool)
    alive = np.ones(R, bool)
    mono = np.zeros((R, n, n))
    steps = np.full((max_iter, R), np.inf)          # each iteration's step relative to the size
    x1, f1 = np.zeros((R, n)), np.zeros((R, n))
    for it in range(max_iter):
        # only the orbits still iterating are shot: a converged one keeps the
        # monodromy of its last shot, a lost one stays lost
        idx = np.nonzero(alive & ~done)[0]
        if idx.size == 0:
            break
        out = _batched_call(system, "shoot", (x[idx], T[idx], mu[idx]), p)
        x1[idx], mono[idx], _, f1[idx], okr = split_shot(out, n)
        alive[idx] &= okr & np.all(np.isfinite(out), axis=1)
        if (done | ~alive).all():
            break
        A = np.zeros((R, n + 1, n + 1))
        A[:, :n, :n] = mono - np.eye(n)
        A[:, :n, n] = f1
        A[:, n, :n] = fhat
        r = np.concatenate([x1 - x, np.einsum("ij,ij->i", x - xhat, fhat)[:, None]], axis=1)
        act = alive & ~done
        d = np.zeros((R, n + 1))
        for i in np.nonzero(act)[0]:
            try:
                d[i] = np.linalg.solve(A[i], -r[i])
            except np.linalg.LinAlgError:
                alive[i] = False
        # limit a step to a fifth of the orbit's size: a wild iterate would blow up
        size = np.max(np.abs(xhat), axis=1) + 1e-12
        steps[it] = np.max(np.abs(d[:, :n]), axis=1) / size
        if it + 1 >= STALL_FROM:
            alive &= ~(act & (steps[it] > STALL_FACTOR * steps[it - 2]))
            act = alive & ~done
        big = np.max(np.abs(d[:, :n]), axis=1) / (0.2 * size)
        d = d / np.maximum(big, 1.0)[:, None]
        x = np.where(act[:, None], x + d[:, :n], x)
        T = np.where(act, T + d[:, n], T)
        alive &= T > 0
        small = (np.max(np.abs(d[:, :n]), axis=1) <= tol * (1 + np.max(np.abs(x), axis=1))) & (
            np.abs(d[:, n]) <= tol * np.abs(T))
        done |= act & small & alive
    ok = done & alive
    for i in np.nonzero(ok)[0]:
        if floquet_stable(np.linalg.eigvals(mono[i])) != bool(np.asarray(stable)[i]):
            ok[i] = False
    states = _sample(system, p, x, T, mu, ok) if sample else np.full((R, N_SAMPLES, n), np.nan)
    return OrbitBatch(x0=x, period=T, mu=mu, ok=ok, states=states)


def _lost_as_found(ok, *arrays) -> list[np.ndarray]:
    """Each array (one row per orbit) with the lost orbits' rows replaced by the first found one's.

    A batch then goes into the compiled programs whole, one shape per batch size.
    """
    first = int(np.argmax(ok))
    return [np.where(np.reshape(ok, (-1,) + (1,) * (np.ndim(a) - 1)), a, np.asarray(a)[first])
            for a in arrays]


def _sample(system: System, p: dict, x, T, mu, ok) -> np.ndarray:
    """Samples over one period of the orbits found, NaN where lost, ``(R, N_SAMPLES, n)``.

    Every orbit goes in (a lost one as a copy of a found one), so the compiled
    sampler has one shape per batch size.
    """
    R, n = np.shape(x)
    states = np.full((R, N_SAMPLES, n), np.nan)
    if not np.any(ok):
        return states
    x, T, mu = _lost_as_found(ok, x, T, mu)
    s = _batched_call(system, "sample", (x, T, mu), p, N_SAMPLES)
    states[ok] = s[ok]
    return states


def track(system: System, params_from: dict, params_to: dict, start: OrbitBatch, stable,
          guess: tuple[np.ndarray, np.ndarray] | None = None) -> OrbitBatch:
    """The orbits at ``params_to``, continued from ``start`` (at ``params_from``) by homotopy.

    The first, whole step starts Newton's method from ``guess`` (points and
    periods, e.g. ``start`` moved along its derivatives in the parameters), or
    from ``start`` itself. An orbit that is not found in that step is retried
    from ``start`` in 4 equal steps of the parameters, then in 16 from the
    furthest of those it reached; one still not found (or ``start`` lost) is lost.
    """
    ensure_x64()
    stable = np.asarray(stable, bool)
    x_first, T_first = (start.x0, start.period) if guess is None else guess
    x0, T, ok = start.x0.copy(), start.period.copy(), np.zeros(start.ok.shape, bool)
    live = np.nonzero(start.ok)[0]                     # an orbit lost at the start stays lost
    if live.size:
        res = solve_orbits(system, params_to, np.asarray(x_first)[live],
                           np.asarray(T_first)[live], start.mu[live], stable[live], sample=False)
        x0[live], T[live], ok[live] = res.x0, res.period, res.ok
    bad = np.nonzero(~ok & start.ok)[0]
    cx, cT = start.x0[bad].copy(), start.period[bad].copy()
    reached = np.zeros(bad.size)                # the fraction of the way each retry has come
    for n_sub in (4, 16):
        alive = reached < 1
        for j in range(1, n_sub + 1):
            w = j / n_sub
            act = np.nonzero(alive & (reached < w))[0]
            if act.size == 0:
                continue
            pj = {k: (1 - w) * float(params_from.get(k, 0.0)) + w * float(v)
                  for k, v in params_to.items()}
            sub = solve_orbits(system, pj, cx[act], cT[act], start.mu[bad[act]],
                               stable[bad[act]], sample=False)
            won = act[sub.ok]
            cx[won], cT[won], reached[won] = sub.x0[sub.ok], sub.period[sub.ok], w
            alive[act[~sub.ok]] = False
            if not alive.any():
                break
    done = reached >= 1
    x0[bad[done]], T[bad[done]], ok[bad[done]] = cx[done], cT[done], True
    states = _sample(system, _params(params_to), x0, T, start.mu, ok)
    return OrbitBatch(x0=x0, period=T, mu=start.mu, ok=ok, states=states)


@functools.lru_cache(maxsize=8)
def _flow_jacobian(rhs):
    """Samples at ``s_k = k/N`` (``k = 0..N``) and their derivatives in ``(x0, T, p)``, batched.

    Differentiated in every parameter, so that one compilation per system (and
    number of orbits) serves every subset a caller asks for.
    """
    ensure_x64()
    solver = diffrax.Dopri8()
    ctrl = diffrax.PIDController(rtol=_RTOL, atol=_ATOL)

    def field(s, x, args):
        T, mu, p = args
        return T * rhs(x, mu, p)

    def path(x0, T, mu, p):
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field), solver, 0.0, 1.0, None, x0, args=(T, mu, p),
            stepsize_controller=ctrl,
            saveat=diffrax.SaveAt(ts=jnp.arange(N_SAMPLES + 1) / N_SAMPLES),
            max_steps=_MAX_STEPS, adjoint=diffrax.ForwardMode(), throw=False)
        return sol.ys

    jac = jax.jacfwd(path, argnums=(0, 1, 3))

    def one(x0, T, mu, p):
        return path(x0, T, mu, p), *jac(x0, T, mu, p)

    return jax.jit(jax.vmap(one, in_axes=(0, 0, 0, None)))


def sensitivities(system: System, params: dict, ob: OrbitBatch, names: Sequence[str]
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Exact derivatives of the found orbits' samples and periods in ``params[names]``.

    Args:
        system: The system whose orbits ``ob`` are (at ``params``).
        params: All its parameters by name.
        ob: Converged orbits (:func:`solve_orbits` or :func:`track`).
        names: The parameters to differentiate in.

    Returns:
        ``(dstates, dperiod)`` of shapes ``(R, N_SAMPLES, n, m)`` and ``(R, m)``
        for ``m = len(names)``; zero for a lost orbit.

    Raises:
        KeyError: For a name that is not among ``params``.
    """
    names = list(names)
    missing = [k for k in names if k not in params]
    if missing:
        raise KeyError(f"names: parameters of the system expected; got {missing}")
    R, n = ob.x0.shape
    m = len(names)
    dS, dT = np.zeros((R, N_SAMPLES, n, m)), np.zeros((R, m))
    ok = np.asarray(ob.ok, bool)
    if not ok.any() or m == 0:
        return dS, dT
    p = _params(params)
    # every orbit goes in (one compiled shape); a lost one runs as a copy of a found one
    x0, T, mu = _lost_as_found(ok, ob.x0, ob.period, ob.mu)
    out = _batched_call(system, "flow", (x0, T, mu), p)
    Jx, JT = out[1], out[2]
    Q = np.stack([out[3][k] for k in names], axis=-1)                  # (R, N+1, n, m)
    f0 = _batched_call(system, "field", (x0, mu), p)
    for i in np.nonzero(ok)[0]:
        A = np.zeros((n + 1, n + 1))
        A[:n, :n] = Jx[i, -1] - np.eye(n)
        A[:n, n] = JT[i, -1]
        A[n, :n] = f0[i]
        b = np.zeros((n + 1, m))
        b[:n] = -Q[i, -1]
        d = np.linalg.solve(A, b)                                # (∂x0/∂p; ∂T/∂p)
        dS[i] = (np.einsum("kab,bm->kam", Jx[i, :-1], d[:n])
                 + JT[i, :-1, :, None] * d[n][None, None, :] + Q[i, :-1])
        dT[i] = d[n]
    return dS, dT
