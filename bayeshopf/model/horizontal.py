r"""Horizontal model discrepancy: the diagram's curve ``μ(x)``, its curvature a Gaussian process.

The vertical discrepancy (:mod:`bayeshopf.model.discrepancy`) adds a smooth
error to the orbit's size at each point of the diagram. A smooth vertical
change of a curve keeps its vertical tangents, so it cannot move the fold, and
being relative to the orbit it cannot move the Hopf point either. This module
puts the model's error where both live: along μ. With ``x = r²/a_2`` (``x = 0``
at the Hopf point, ``½`` at the fold) the linear unfolding's limit cycles lie on
``μ = μ_SN + Δ·4(x − ½)²``, ``Δ = μ_H − μ_SN = a_2²/4``: a curve of constant
curvature in ``x``. Here the curvature varies,

.. math::

    μ(x) = μ_{SN} + Δ\,H(x),\qquad
    H(x) = \frac{\int_{1/2}^{x} (x - t)\, e^{e(t)}\,dt}{\int_0^{1/2} t\, e^{e(t)}\,dt},
    \qquad e \sim \mathcal{GP}\big(0,\ η_h^2\, e^{-(x-x')^2/2ℓ_h^2}\big),

so ``μ''(x) ∝ e^{e(x)} > 0``: one fold at ``x = ½`` (``H = H' = 0``), the Hopf
point at ``x = 0`` (``H = 1``), both branches monotone, and ``e ≡ 0`` is the
normal form (``H = 4(x − ½)²``). The Hopf point ``μ_H`` and the fold ``μ_SN``
stay the model's sites (the gaps of
:func:`~bayeshopf.model.collapsed.normal_form_sites`); ``e`` changes how the
branches run between and beyond them, so how far the recordings place them
depends on how well the curve's shape is known, with a learned size ``η_h``.
``a_2 = 2√Δ`` keeps the radius's scale that of the normal form.

A recording at μ on the unstable branch is the root of ``H(x) = (μ − μ_SN)/Δ``
in ``[0, ½]``, on the stable branch the root above ``½`` (Newton's steps
safeguarded by a bracket, then one more for the derivatives), its radius
``r = √(a_2 x)``; the integrals are Gauss–Legendre sums (:data:`N_NODES`) over ``[½, x]``.

**The process** is the reduced-rank expansion of Solin & Särkkä (2020) on
``[−L, L]`` (:data:`HALF_WIDTH`, :data:`N_BASIS`):
``e(x) = Σ_k c_k L^{−½} \sin(ω_k (x + L))``, ``ω_k = πk/(2L)``,
``c_k = z_k √S(ω_k)``, ``z_k ~ N(0, 1)`` sampled (non-centred),
``S(ω) = η_h² √(2π) ℓ_h e^{−ℓ_h² ω²/2}`` the squared exponential's
spectral density. With few basis functions it is a smooth process of its own:
close to the squared exponential's covariance at ``ℓ_h = ½`` on
``x ∈ [0, 1.2]`` (the unstable branch and the stable one up to a little
above the Hopf point; ``tests/test_horizontal.py``), without its higher
frequencies at shorter lengths (so smoother than it), and pulled to 0 (the
normal form's curvature) towards ``|x| = L``.

**Priors** (stated, informative): ``η_h ~ HalfNormal(`` :data:`ETA_PRIOR` ``)``
(the log of the curvature), ``ℓ_h ~ LogNormal`` (:data:`LENGTH_PRIOR`, in units
of ``x``: the unstable branch spans ``[0, ½]``).

**The window at the fold** (``unfolding="window"``, :func:`window_sites`). The
same curve with the log curvature

.. math::  e(x) = -A\,e^{-(x - 1/2)^2/2λ^2},

a window of depth ``A`` and width ``λ`` at the fold. The normal form's fold is
quadratic, but how far from the fold the quadratic law holds is not something
recordings above the fold can see: a fold near a degenerate one (the two branches
meeting with a higher-order contact) holds it only very close to the fold,
and extrapolating the recorded pairs with the normal form's curvature then puts
the fold too low. ``A > 0`` is such a flatter fold (the branches stay apart
closer to it and meet abruptly), ``A < 0`` a sharper one, ``A = 0`` the normal
form. Priors (stated): ``A ~ N(0,`` :data:`WINDOW_DEPTH_PRIOR` ``²)``,
``λ ~ LogNormal`` (:data:`WINDOW_WIDTH_PRIOR`, in units of ``x``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

#: Half-normal scale of ``η_h``, the size of the log curvature's discrepancy.
ETA_PRIOR = 0.5
#: Log-normal prior of ``ℓ_h`` (median, log-sd), in units of ``x = r²/a_2``.
LENGTH_PRIOR = (0.5, 0.5)
#: Basis functions of the reduced-rank process.
N_BASIS = 6
#: ``L``: the process lives on ``[−L, L]`` in ``x``.
HALF_WIDTH = 2.0
#: Safeguarded Newton steps of the roots.
N_STEPS = 12
#: Gauss–Legendre nodes of the curve's integrals.
N_NODES = 24


def frequencies() -> np.ndarray:
    """``ω_k = πk/(2L)``, ``k = 1..m``."""
    return np.pi * np.arange(1, N_BASIS + 1) / (2.0 * HALF_WIDTH)


def coefficients(eta, ell, z):
    """``c_k = z_k √S(ω_k)`` for the squared-exponential spectral density, shape of ``z``."""
    w = frequencies()
    eta, ell = jnp.asarray(eta)[..., None], jnp.asarray(ell)[..., None]
    s = eta**2 * jnp.sqrt(2.0 * jnp.pi) * ell * jnp.exp(-0.5 * (ell * w) ** 2)
    return z * jnp.sqrt(s)


def _phases(x):
    return jnp.asarray(x)[..., None] * frequencies() + frequencies() * HALF_WIDTH


#: The forms of the log curvature: the reduced-rank process, the window at the fold.
FORMS = ("process", "window")


def _check(form: str) -> None:
    if form not in FORMS:
        raise ValueError(f"form: expected one of {', '.join(FORMS)}; got {form!r}")


def discrepancy(x, c, form: str = "process"):
    """``e(x)`` for ``x`` (...) and coefficients ``c`` (..., m), broadcasting.

    ``form="process"``: ``c`` holds the reduced-rank process's ``c_k``
    (:data:`N_BASIS` of them); ``form="window"``: the window at the fold,
    ``e(x) = −A e^{−(x−½)²/2λ²}`` with ``c = (A, λ)``.
    """
    _check(form)
    if form == "window":
        a, lam = c[..., 0], c[..., 1]
        return -a * jnp.exp(-0.5 * ((jnp.asarray(x) - 0.5) / lam) ** 2)
    return jnp.sum(jnp.sin(_phases(x)) * c, axis=-1) / np.sqrt(HALF_WIDTH)


def _reach(c, form):
    """``(w, E)`` with ``e(t) ≥ −E`` for every ``t ≥ ½ + w``.

    Then ``H(x) ≥ e^{−E}(x − ½ − w)²/(2n)`` there (``n`` the curve's
    normaliser), so the stable root of ``H = v`` lies below
    ``½ + w + √(2 e^{E} n v)``. The window: ``w = λ√(2 ln max(A, 1))``,
    ``E = 1``; the process: ``w = 0`` and ``E`` a bound of ``|e|``.
    """
    if form == "window":
        a, lam = c[..., 0], c[..., 1]
        return lam * jnp.sqrt(2.0 * jnp.log(jnp.maximum(a, 1.0))), jnp.ones_like(a)
    e_abs = jnp.sum(jnp.abs(c), axis=-1) / np.sqrt(HALF_WIDTH)
    return jnp.zeros_like(e_abs), e_abs


def _nodes():
    t, w = np.polynomial.legendre.leggauss(N_NODES)
    return 0.5 * (t + 1.0), 0.5 * w                       # on [0, 1]


def _moments(x, c, form):
    """``(∫_{½}^x (x−t) e^{e} dt, ∫_{½}^x e^{e} dt)`` by Gauss–Legendre, shape of ``x``."""
    u, w = _nodes()
    x = jnp.asarray(x)
    t = 0.5 + (x[..., None] - 0.5) * u                      # (..., n)
    f = jnp.exp(discrepancy(t, c[..., None, :], form))
    d = x - 0.5
    return d**2 * jnp.sum(w * (1.0 - u) * f, axis=-1), d * jnp.sum(w * f, axis=-1)


def _norm(c, form):
    """``∫_0^{½} t e^{e(t)} dt`` (``1/8`` for ``e ≡ 0``)."""
    return _moments(jnp.zeros(jnp.shape(c)[:-1]), c, form)[0]


def curve(x, c, form: str = "process"):
    """``H(x)``: 0 at the fold ``x = ½``, 1 at the Hopf point ``x = 0``.

    ``form``: :data:`FORMS`.
    """
    _check(form)
    return _moments(x, c, form)[0] / _norm(c, form)


def slope(x, c, form: str = "process"):
    """``H'(x)`` (``form``: :data:`FORMS`)."""
    _check(form)
    return _moments(x, c, form)[1] / _norm(c, form)


def _root(g, lo, hi, x0):
    """The root of an increasing ``g`` in ``[lo, hi]`` (elementwise) from ``x0``.

    Newton's steps, each replaced by the bracket's midpoint where it would
    leave the bracket, which shrinks with every step (safeguarded Newton).
    ``g`` returns ``(g, g')``.
    """
    def step(_, b):
        lo, hi, x = b
        f, df = g(x)
        lo, hi = jnp.where(f > 0, lo, x), jnp.where(f > 0, x, hi)
        xn = x - f / jnp.where(df > 0, df, 1.0)
        inside = (df > 0) & (xn >= lo) & (xn <= hi)
        return lo, hi, jnp.where(inside, xn, 0.5 * (lo + hi))
    return jax.lax.fori_loop(0, N_STEPS, step, (lo, hi, x0))[2]


def position(mu, sign, mu_hopf, mu_fold, c, form: str = "process"):
    """``x`` of the limit cycle at μ on the branch ``sign`` (+1 stable), ``nan`` where none.

    ``mu`` and ``sign`` broadcast against the draws' leading shape of
    ``mu_hopf``, ``mu_fold`` and ``c`` (..., m); ``form``: :data:`FORMS`.
    """
    _check(form)
    shape = jnp.broadcast_shapes(jnp.shape(mu), jnp.shape(sign), jnp.shape(mu_hopf),
                                 jnp.shape(c)[:-1])
    c = jnp.broadcast_to(c, shape + jnp.shape(c)[-1:])
    v = jnp.broadcast_to((mu - mu_fold) / (mu_hopf - mu_fold), shape)
    stable = jnp.broadcast_to(sign, shape) > 0
    n = _norm(c, form)                                   # the same at every step
    w, e_tail = _reach(c, form)                          # a bracket of the stable root
    top = 0.5 + w + jnp.sqrt(2.0 * jnp.exp(e_tail) * n * jnp.maximum(v, 0.0)) + 1e-9
    lo = jnp.where(stable, 0.5, 0.0)
    hi = jnp.where(stable, top, 0.5)
    direction = jnp.where(stable, 1.0, -1.0)            # H rises on the stable side
    x0 = jnp.clip(0.5 + direction * 0.5 * jnp.sqrt(jnp.maximum(v, 0.0)), lo, hi)

    def g(x):
        m, dm = _moments(x, c, form)
        return direction * (m / n - v), direction * dm / n

    xb = jax.lax.stop_gradient(_root(g, lo, hi, x0))
    h, fp = (m / n for m in _moments(xb, c, form))
    safe = jnp.abs(fp) > 1e-12
    x = xb - jnp.where(safe, (h - v) / jnp.where(safe, fp, 1.0), 0.0)
    ok = (v >= -1e-12) & (stable | (v <= 1.0 + 1e-12))
    return jnp.where(ok, x, jnp.nan)


#: Prior sd of the fold window's depth ``A`` (log of the curvature's drop at the fold).
WINDOW_DEPTH_PRIOR = 2.0
#: Log-normal prior of the window's width ``λ`` (median, log-sd), in units of ``x``.
WINDOW_WIDTH_PRIOR = (0.15, 0.5)


def window_sites(mu0, mu_fold) -> dict:
    """The window's NumPyro sites, given the Hopf point and the fold.

    Called by :func:`~bayeshopf.model.collapsed.normal_form_sites`: the depth
    ``A`` (``depth_h``) and width ``λ`` (``width_h``) of the window at the fold;
    then, as deterministic sites, ``h_coef = (A, λ)`` and ``a2 = 2√(μ0 − μ_SN)``.
    """
    a = numpyro.sample("depth_h", dist.Normal(0.0, WINDOW_DEPTH_PRIOR))
    lam = numpyro.sample("width_h", dist.LogNormal(np.log(WINDOW_WIDTH_PRIOR[0]),
                                                   WINDOW_WIDTH_PRIOR[1]))
    return {"h_coef": numpyro.deterministic("h_coef", jnp.stack([a, lam], axis=-1)),
            "a2": numpyro.deterministic("a2", 2.0 * jnp.sqrt(mu0 - mu_fold))}


def sites(mu0, mu_fold) -> dict:
    """The horizontal discrepancy's NumPyro sites, given the Hopf point and the fold.

    Called by :func:`~bayeshopf.model.collapsed.normal_form_sites`: ``η_h``,
    ``ℓ_h`` and the process's standard-normal weights ``z_h``; then, as
    deterministic sites, its coefficients ``h_coef`` and ``a2 = 2√(μ0 − μ_SN)``,
    the radius's scale.
    """
    eta = numpyro.sample("eta_h", dist.HalfNormal(ETA_PRIOR))
    ell = numpyro.sample("ell_h", dist.LogNormal(np.log(LENGTH_PRIOR[0]), LENGTH_PRIOR[1]))
    z = numpyro.sample("z_h", dist.Normal(0.0, 1.0).expand([N_BASIS]).to_event(1))
    return {"h_coef": numpyro.deterministic("h_coef", coefficients(eta, ell, z)),
            "a2": numpyro.deterministic("a2", 2.0 * jnp.sqrt(mu0 - mu_fold))}
