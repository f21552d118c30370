"""Predictions of a fitted model: orbits, amplitudes, frequencies and new recordings.

One path for every command: given posterior draws of the normal form and the
hyperparameters ``θ``, the map's (and the discrepancy's latent) coefficients
``β`` and the frequency's ``γ``, these functions give the predicted orbits'
harmonic coefficients at any μ (:func:`orbit_coefficients`), the model
discrepancy there (:func:`discrepancy_draws`), the infinite-width network's
spread there (:func:`network_draws`), the noise of a new recording
(:func:`noise_sd`), amplitudes (:func:`amplitude_of`) and frequencies
(:func:`frequency_draws`). :class:`~bayeshopf.posterior.HybridPosterior`, saved
fits (:mod:`bayeshopf.fit_folder`), leave-one-out (:mod:`bayeshopf.validation`) and
``next`` (:mod:`bayeshopf.design`) call them.
"""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np

from bayeshopf._x64 import ensure_x64
from bayeshopf.features.harmonics import HarmonicFeatures, phase_design
from bayeshopf.inference.devices import mapped_call
from bayeshopf.model import collapsed as cm
from bayeshopf.model import network_kernel as nk
from bayeshopf.model import normal_form

#: Draws used for bands (quantiles at 5%–95% are stable with 500).
N_BAND_DRAWS = 500


def _per_draw(mu, n: int) -> np.ndarray:
    """μ as one row per draw, ``(n, n_mu)``, from ``(n_mu,)`` (every draw's) or ``(n, n_mu)``."""
    mu = np.asarray(mu, dtype=float)
    return mu if mu.ndim == 2 else np.broadcast_to(np.atleast_1d(mu), (n, np.atleast_1d(mu).size))


def _common_over_mu(rng, shape) -> np.ndarray:
    """Standard normals for coefficient draws ``(n, n_mu, …)``, one set per draw for every μ.

    A new recording's noise at each μ has its exact marginal, and a band over μ
    is smooth (the frequency's predictive draws do the same, :func:`frequency_draws`).
    """
    return rng.standard_normal((shape[0], 1) + tuple(shape[2:]))


def draw_indices(total: int, n: int | None = N_BAND_DRAWS) -> np.ndarray:
    """``n`` draw indices spread evenly over ``total`` (all of them when ``n ≥ total``)."""
    if n is None or n >= total:
        return np.arange(total)
    return np.unique(np.linspace(0, total - 1, n).round().astype(int))


def _spec_key(spec: cm.CollapsedSpec) -> str:
    """What the orbit and frequency programs close over: the spec, as JSON."""
    return json.dumps(spec.to_dict(), sort_keys=True)


def _orbit_program(spec: cm.CollapsedSpec):
    """One draw ``(θ, β, μ, sign) ↦`` its coefficients ``(n_mu, 2, 2K+1)``: ``Φ(μ) β``.

    The design of the likelihood at every μ of the draw's grid; mapped over the
    draws (:func:`~bayeshopf.inference.devices.mapped_call`), so that one
    draw's network features (μ × phase × unit) are in memory at a time.
    """
    def one(a):
        t, b, mu, sign = a
        return jnp.einsum("mkj,jc->mck", cm.design(spec, mu, sign, t), b[:spec.n_basis])

    return one


def _mu_bucket(m: int) -> int:
    """The μ count a program is compiled for: 8, or a multiple of 40 (:func:`_over_draws`)."""
    return 8 if m <= 8 else -(-m // 40) * 40


def _over_draws(name: str, one, items: tuple, key, mu_at: int):
    """``lax.map(one, items)`` over the draws, in few compiled shapes.

    :func:`~bayeshopf.inference.devices.mapped_call` (stored, the draws split
    over the process's devices) in blocks of :data:`N_BAND_DRAWS` draws, with
    ``items[mu_at]``, the μ of each draw ``(n, n_mu)``, padded to
    :func:`_mu_bucket` ``(n_mu)`` by its last value: the training recordings of
    either branch, a draw's fold, the diagram's grid and the 2,000 draws of
    ``posterior.nc`` each reuse a program compiled for another (every new
    shape is a compilation on a cold start). The outputs,
    each with the draws on axis 0 and μ on axis 1, come back unpadded.
    """
    n, m = np.shape(items[mu_at])
    pad_mu = _mu_bucket(m) - m
    items = tuple(np.pad(a, ((0, 0), (0, pad_mu)), mode="edge") if i == mu_at and pad_mu
                  else a for i, a in enumerate(items))
    size = min(n, N_BAND_DRAWS)
    blocks = []
    for start in range(0, n, size):
        rows = slice(start, min(start + size, n))
        short = size - (rows.stop - rows.start)          # the last block, padded
        block = jax.tree.map(lambda a, rows=rows, short=short: np.concatenate(
            [a[rows], np.repeat(a[rows.stop - 1:rows.stop], short, 0)]), items)
        out = mapped_call(name, one, block, key=key)
        blocks.append(jax.tree.map(lambda r, k=size - short: np.asarray(r)[:k, :m], out))
    return jax.tree.map(lambda *b: np.concatenate(b), *blocks)


def _host(theta: dict) -> dict:
    """Draws as host arrays (:func:`~bayeshopf.inference.devices.mapped_call` places them)."""
    return {k: np.asarray(v, float) for k, v in theta.items()}


def _frequency_program(spec: cm.CollapsedSpec):
    """One draw ``(θ, γ, μ, sign) ↦ Ω`` (rad/s) on its μ grid (mapped over the draws)."""
    def one(a):
        t, g, mu, sign = a
        return cm.frequency(spec, t, g, mu, sign)

    return one


def orbit_coefficients(spec: cm.CollapsedSpec, theta: dict, betas, mu, sign: float, *,
                       per_draw: bool = False, control=None):
    """Predicted orbits' harmonic coefficients, ``(n, n_mu, 2, 2K+1)``, for draws ``(θ, β)``.

    Args:
        spec: Model structure.
        theta: Draws of the nonlinear parameters, leading axis ``n``.
        betas: Map coefficients, ``(n, J, 2)``.
        mu: μ values ``(n_mu,)``, the same for every draw; with ``per_draw``,
            shape ``(n, n_mu)`` (e.g. each draw's own fold).
        sign: +1 stable, −1 unstable.
        per_draw: Whether ``mu`` holds one row of μ per draw.
        control: The control's fundamental ``(u_a, u_b)`` at each μ, ``(n_mu, 2)``:
            the orbit as that control holds it (the response ``H U`` of
            :mod:`bayeshopf.model.collapsed`, "Control", with ``β``'s last two
            rows as ``h``); ``None``: the uncontrolled system's.
    """
    ensure_x64()
    n = np.shape(betas)[0]
    mu = np.asarray(mu, dtype=float) if per_draw else _per_draw(mu, n)
    # stored (inference.cache.compiled_call): a warm process neither traces nor lowers
    # it; the draws split over the process's devices (the CLI's: one per core)
    c = _over_draws("orbits", _orbit_program(spec), (
        _host(theta), np.asarray(betas, float), mu, np.full(n, float(sign))),
        _spec_key(spec), mu_at=2)
    if control is None or spec.control_scale is None:
        return c
    cols = np.asarray(cm.control_columns(spec, np.asarray(control, float)))  # (n_mu, 2K+1, 2)
    return c + np.einsum("mkj,njc->nmck", cols,
                         np.asarray(betas)[:, spec.n_map:spec.n_basis, :])


def frequency_draws(spec: cm.CollapsedSpec, theta: dict, gammas, mu, sign: float, *,
                    predictive: bool = False, omega_se: float = 0.0, seed: int = 0
                    ) -> np.ndarray:
    """Frequency (Hz) draws ``(n, n_mu)`` at μ for draws ``(θ, γ)``; ``nan`` where no LCO.

    ``mu``: ``(n_mu,)``, or ``(n, n_mu)``, one row per draw.

    With ``predictive``, each draw gets a new recording's error
    ``N(0, σ_ω² + omega_se²)`` (rad/s): one standard-normal number per draw for
    every μ, so that a band over μ is smooth while each μ's marginal is exact.
    """
    ensure_x64()
    n = np.shape(gammas)[0]
    mu = _per_draw(mu, n)
    om = _over_draws("frequency-grid", _frequency_program(spec), (
        _host(theta), np.asarray(gammas, float), mu, np.full(n, float(sign))),
        _spec_key(spec), mu_at=2)
    hz = om / (2 * np.pi)
    return frequency_noise(theta, hz, omega_se, seed) if predictive else hz


def frequency_noise(theta: dict, hz, omega_se: float, seed: int) -> np.ndarray:
    """Frequency draws ``hz`` ``(n, n_mu)`` (Hz) plus a new recording's error.

    ``N(0, σ_ω² + omega_se²)`` (rad/s), one standard-normal number per draw for
    every μ (:func:`frequency_draws` with ``predictive``).
    """
    sd = np.sqrt(np.asarray(theta["sigma_omega"])[:, None] ** 2 + omega_se**2)
    z = np.random.default_rng(seed).standard_normal((np.shape(hz)[0], 1))
    return hz + sd / (2 * np.pi) * z


def extrapolation_factor(mu, mu_data, mu_span: float, n: int, seed: int, *,
                         scale=cm.EXTRAPOLATION_SCALE) -> np.ndarray:
    """Draws of ``e^{δ_b(μ)}``, the model error away from the recordings, ``(n, n_mu)``.

    ``δ_b(μ) = s_e z c_b(μ)`` with ``s_e ~ HalfNormal(scale)`` and
    ``z ~ N(0, 1)``, one pair per draw for every μ (smooth bands over μ, exact
    marginals at each μ), and ``c_b`` :func:`~bayeshopf.model.collapsed.extrapolation_sd`
    with ``ℓ = EXTRAPOLATION_LENGTH · Δμ`` (:mod:`bayeshopf.model.collapsed`).

    Args:
        mu: Where, ``(n_mu,)``.
        mu_data: The branch's training μ.
        mu_span: The recordings' μ span Δμ.
        n: Draws.
        seed: Seed (its own stream, apart from the measurement noise's).
        scale: Half-normal scale of ``s_e``
            (:attr:`HybridPosterior.extrapolation_scale`).
    """
    rng = np.random.default_rng([seed, 1])
    s = np.abs(rng.normal(0.0, scale, n))
    z = rng.standard_normal(n)
    c = cm.extrapolation_sd(mu, mu_data, cm.EXTRAPOLATION_LENGTH * mu_span)
    return np.exp((s * z)[:, None] * c[None])


def _discrepancy_program(spec: cm.CollapsedSpec):
    """One draw ``(θ, β, μ, sign, training μ and signs) ↦ (mean, var, nugget)`` of ``Δ``."""
    from bayeshopf.model import discrepancy as dm

    def one(a):
        t, b, mu, sign, mu_ref, sign_ref = a
        g_ref, x_ref = cm.discrepancy_geometry(spec, t, mu_ref, sign_ref, mu_ref, sign_ref)
        g, x = cm.discrepancy_geometry(spec, t, mu, sign * jnp.ones_like(mu), mu_ref, sign_ref)
        z = b[spec.n_basis:]                                          # (n_ref S, 2)
        pairs = [dm.conditional(z[:, c], g[:, c], x_ref, x, t["eta"], t["ell"]) for c in range(2)]
        mean = jnp.stack([p[0] for p in pairs], axis=1)               # (n_mu, 2, M)
        var = jnp.stack([p[1] for p in pairs], axis=1)
        return mean, var, (t["sigma_rel"] * g) ** 2

    return one


def discrepancy_moments(spec: cm.CollapsedSpec, theta: dict, betas, features: HarmonicFeatures,
                        mu, sign: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The discrepancy's conditional mean and variance at μ per draw, and ``(σ_rel g)²``.

    Each ``(n, n_mu, 2, 2K+1)`` (:func:`discrepancy_draws`); ``mu`` ``(n_mu,)``,
    or ``(n, n_mu)``, one row per draw.
    """
    ensure_x64()
    n = np.shape(betas)[0]
    mu = _per_draw(mu, n)
    ref_mu = np.asarray(features.mu, float)
    ref_sign = np.where(features.unstable, -1.0, 1.0)
    return tuple(_over_draws(
        "discrepancy", _discrepancy_program(spec),
        (_host(theta), np.asarray(betas, float), mu, np.full(n, float(sign)),
         np.broadcast_to(ref_mu, (n, ref_mu.size)), np.broadcast_to(ref_sign, (n, ref_sign.size))),
        _spec_key(spec), mu_at=2))


def discrepancy_draws(spec: cm.CollapsedSpec, theta: dict, betas, features: HarmonicFeatures,
                      mu, sign: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Draws of the model discrepancy ``Δ`` at μ, and its independent variance there.

    Per posterior draw ``(θ, β, z)`` (``z`` the last rows of ``β``), the smooth
    part's Gaussian-process conditional at μ on ``sign``'s branch
    (:func:`~bayeshopf.model.discrepancy.conditional`), drawn with one set of
    standard normals per draw for every μ (smooth bands, exact marginals), and
    ``(σ_rel g)²``, the variance of a new recording's own relative error.

    Returns:
        ``(delta, nugget_var)``, each ``(n, n_mu, 2, 2K+1)``; ``nan`` where a draw
        has no orbit on the branch.
    """
    mean, var, nugget = discrepancy_moments(spec, theta, betas, features, mu, sign)
    rng = np.random.default_rng([seed, 3])
    eps = _common_over_mu(rng, mean.shape)
    return mean + np.sqrt(var) * eps, nugget


def _network_program(spec: cm.CollapsedSpec):
    """One draw ``(θ, μ, sign) ↦ ρ²τ_s² var`` of the infinite-width network's coefficients."""
    def one(a):
        t, mu, sign = a
        var = nk.conditional_var(spec, t, mu, sign * jnp.ones_like(mu), cm.N_PHI)   # (n_mu, M)
        return (spec.orbit_scale * t["tau_shape"]) ** 2 * var

    return one


def network_draws(spec: cm.CollapsedSpec, theta: dict, mu, sign: float, seed: int) -> np.ndarray:
    """The infinite-width network's part of the orbits at μ beyond its conditional mean.

    Per posterior draw ``θ``, the network's coefficients at μ given those at the
    training recordings have the mean that :func:`orbit_coefficients` includes
    (the design's network columns times ``z``) and the variance
    :func:`~bayeshopf.model.network_kernel.conditional_var` (zero at a training
    recording); this draws the rest, one set of standard normals per draw for
    every μ (smooth bands, exact marginals). Zero for a network of finite width.

    ``mu``: ``(n_mu,)``, or ``(n, n_mu)``, one row per draw.

    Returns:
        ``(n, n_mu, 2, 2K+1)``; ``nan`` where a draw has no orbit on the branch.
    """
    ensure_x64()
    n = len(next(iter(theta.values())))
    mu = _per_draw(mu, n)
    M = 2 * spec.n_harmonics + 1
    if spec.nn_training is None:
        return np.zeros((n, mu.shape[1], 2, M))
    var = _over_draws("network", _network_program(spec),
                      (_host(theta), mu, np.full(n, float(sign))), _spec_key(spec),
                      mu_at=1)                                                 # (n, n_mu, M)
    eps = _common_over_mu(np.random.default_rng([seed, 4]), (n, mu.shape[1], 2, M))
    return np.sqrt(var)[:, :, None, :] * eps


def scale_orbits(coeffs, factor) -> np.ndarray:
    """Orbits ``(n, n_mu, 2, 2K+1)`` scaled about their centres (``a_0`` kept) by ``(n, n_mu)``."""
    c = np.array(coeffs, dtype=float, copy=True)
    c[..., 1:] *= np.asarray(factor)[..., None, None]
    return c


def predictive_draws(spec: cm.CollapsedSpec, theta: dict, betas, gammas,
                     features: HarmonicFeatures, seed: int) -> dict:
    """A replicated recording at each training recording, one per posterior draw.

    At recording ``i``'s μ and branch, each draw's predicted coefficients (with
    the model discrepancy there, smooth and independent parts, where the model
    has it) plus ``N(0, se_i² + σ_c² + (σ_rel c)²)`` noise (without ``σ_rel c``
    with the discrepancy) (``se_i`` its standard errors,
    as in :meth:`HybridPosterior.ppc`) and, with ``gammas``, its frequency plus
    ``N(0, σ_ω² + se_ω,i²)``; the noise is independent between recordings.

    Returns:
        ``{"coeffs": (n, n_rec, 2, 2K+1), "amplitude": (n, n_rec)}`` and, with
        ``gammas``, ``"frequency"`` (Hz) ``(n, n_rec)``; ``nan`` where a draw has
        no LCO on the recording's branch.
    """
    f = features
    n = np.shape(betas)[0]
    rng = np.random.default_rng([seed, 2])
    coeffs = np.full((n, f.n_recordings, 2, 2 * spec.n_harmonics + 1), np.nan)
    freq = np.full((n, f.n_recordings), np.nan)
    for unstable in (False, True):
        idx = np.flatnonzero(f.unstable == unstable)
        if idx.size == 0:
            continue
        sign = normal_form.UNSTABLE if unstable else normal_form.STABLE
        u = None if f.control is None else np.asarray(f.control)[idx]
        coeffs[:, idx] = orbit_coefficients(spec, theta, betas, f.mu[idx], sign, control=u)
        if spec.has_discrepancy:
            mean, var, nugget = discrepancy_moments(spec, theta, betas, f, f.mu[idx], sign)
            coeffs[:, idx] += mean + np.sqrt(var + nugget) * rng.standard_normal(mean.shape)
        if gammas is not None:
            freq[:, idx] = frequency_draws(spec, theta, gammas, f.mu[idx], sign)
    rel = 0.0 if spec.has_discrepancy else theta["sigma_rel"]     # the discrepancy's is in
    sd = np.stack([noise_sd(coeffs[:, i], theta["sigma"], rel, f.coeffs_se[i])
                   for i in range(f.n_recordings)], axis=1)
    reps = coeffs + sd * rng.standard_normal(coeffs.shape)
    out = {"coeffs": reps, "amplitude": amplitude_of(spec, reps)}
    if gammas is not None:
        sd_omega = np.sqrt(np.asarray(theta["sigma_omega"])[:, None] ** 2 + f.omega_se[None] ** 2)
        out["frequency"] = freq + sd_omega / (2 * np.pi) * rng.standard_normal(freq.shape)
    return out


def noise_sd(coeffs, sigma, sigma_rel, coeffs_se) -> np.ndarray:
    """``√(se² + σ_c² + (σ_rel c)²)`` for predicted coefficients ``(n, ..., 2, 2K+1)``.

    ``sigma`` ``(n, 2)`` and ``sigma_rel`` ``(n,)`` per draw; ``coeffs_se`` ``(2, 2K+1)``.
    """
    c = np.asarray(coeffs)
    extra = (1,) * (c.ndim - 3)
    s = np.asarray(sigma).reshape((-1,) + extra + (2, 1))
    r = np.asarray(sigma_rel).reshape((-1,) + extra + (1, 1))
    return np.sqrt(np.asarray(coeffs_se) ** 2 + s**2 + (r * c) ** 2)


def amplitude_of(spec: cm.CollapsedSpec, coeffs) -> np.ndarray:
    """Peak-to-peak of z1 of the orbits with these frame coefficients (last two axes).

    ``z1 = c_1 + L_{1·} w`` is linear in the frame coordinates, so its harmonic
    coefficients are ``L_{1·}`` applied to the frame's (the centre only shifts
    ``a_0``, which the peak-to-peak ignores); only z1 is reconstructed, at 256 phases.
    """
    phi = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    K = (np.shape(coeffs)[-1] - 1) // 2
    z1_coeffs = np.asarray(spec.frame.L)[0] @ np.asarray(coeffs)        # (..., 2K+1)
    design = phase_design(phi, K).T                                       # (2K+1, 256)
    if z1_coeffs.ndim < 3:
        z1 = z1_coeffs @ design
        return z1.max(axis=-1) - z1.min(axis=-1)
    # a few draws at a time: the orbits of every draw at every μ at once (500 ×
    # 120 × 256 values for a diagram's band) cost more in fresh memory than in
    # arithmetic. The product is batched over the leading axis, one matrix
    # product per draw either way, so the values are the same
    out = np.empty(z1_coeffs.shape[:-1])
    step = max(1, _CHUNK_POINTS // (int(np.prod(z1_coeffs.shape[1:-1])) * phi.size))
    for i in range(0, z1_coeffs.shape[0], step):
        z1 = z1_coeffs[i:i + step] @ design
        out[i:i + step] = z1.max(axis=-1) - z1.min(axis=-1)
    return out


#: Orbit points reconstructed at once by :func:`amplitude_of` (a few MB, in cache).
_CHUNK_POINTS = 1 << 19
