"""Channels beyond the planar pair, by regression once U12 is inverted.

The paper's "mapping to other coordinates": a further measured channel ``y``
(the actuator command, the CBC target, a strain gauge...) is a function of the
normal-form state, ``y = f(u1, u2, μ)``. Once the planar map is fitted, every
measured sample is placed on its predicted orbit, which inverts U12 along the
LCO: the sample's normal-form phase is that of the nearest point of the
predicted orbit,

    φ(t) = argmin_φ ‖w(t) − U12(r(μ) [cos φ, sin φ], μ̃)‖,

and ``u(t) = r(μ) [cos φ(t), sin φ(t)]``. On the LCO a smooth ``f`` is a Fourier
series in φ whose k-th harmonic is a polynomial in r of lowest degree k,

    y(φ) = Σ_k a_k cos kφ + b_k sin kφ,   a_k, b_k = r^k (β_0 + β_1 μ̃) [+ β_2 r² for k = 0],

so each recording gives its coefficients by least squares in φ, and each
coefficient is a Bayesian linear regression across recordings (conjugate
normal–inverse-gamma, so the scatter between recordings is estimated, not
assumed). This is repeated for draws of the map's posterior, so the channel's
band carries the map's uncertainty and the regression's.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from bayeshopf.data.recording import RecordingSet
from bayeshopf.diagnostics.predictive import _site_arrays
from bayeshopf.errors import FitError
from bayeshopf.model import hybrid, normal_form
from bayeshopf.model.hybrid import branch_signs

#: Phases on which the predicted orbit is searched for the nearest point.
N_PHASE_GRID = 720


@dataclass(frozen=True)
class ChannelFit:
    """A further channel regressed on the normal-form state (immutable).

    Attributes:
        name: Channel name.
        units: Its unit.
        n_harmonics: Harmonics K of the channel's waveform in φ.
        draw_index: Posterior draws of the map used, shape ``(n_draws,)``.
        beta: Regression coefficients per draw and Fourier coefficient,
            shape ``(n_draws, 2K+1, n_design)`` (unused design columns are 0).
        sigma: Scatter between recordings per draw and coefficient, ``(n_draws, 2K+1)``.
        measured_coeffs: Per-recording coefficients at the draw closest to the
            map's MAP point, ``(n_rec, 2K+1)``.
        measured_amplitude: Per-recording peak-to-peak of the measured channel's
            Fourier reconstruction, ``(n_rec,)``.
        phases: Per recording, ``(φ, y)`` of the (down-sampled) measured
            samples at the MAP point, for plots.
    """

    name: str
    units: str
    n_harmonics: int
    draw_index: np.ndarray
    beta: np.ndarray
    sigma: np.ndarray
    measured_coeffs: np.ndarray
    measured_amplitude: np.ndarray
    phases: tuple

    def waveform(self, fit_, mu: float, branch: str = "stable", *, predictive: bool = False,
                 n_phi: int = 128, seed: int = 0) -> np.ndarray:
        """The channel along the orbit at μ, ``(n_draws, n_phi)`` on ``φ ∈ [0, 2π)``.

        ``predictive=True`` adds the scatter between recordings: the band a new
        recording's waveform falls in.
        """
        sign = normal_form.STABLE if branch == "stable" else normal_form.UNSTABLE
        r = _radii(fit_, self.draw_index, np.array([mu]), np.array([sign]))[:, 0]
        x = np.stack([_design(k, r, fit_.spec.mu_tilde(mu)) for k in _orders(self.n_harmonics)],
                     axis=1)  # (n_draws, n_c, n_design)
        c = np.einsum("dcp,dcp->dc", x, self.beta)
        if predictive:
            rng = np.random.default_rng(seed)
            c = c + self.sigma * rng.standard_normal(c.shape)
        phi = np.linspace(0.0, 2.0 * np.pi, n_phi, endpoint=False)
        return c @ _basis(phi, self.n_harmonics).T

    def amplitude(self, fit_, mu, branch: str = "stable", *, predictive: bool = False,
                  seed: int = 0) -> np.ndarray:
        """Peak-to-peak of the channel at each μ, ``(n_draws, n_mu)``."""
        mu = np.atleast_1d(np.asarray(mu, float))
        return np.stack([np.ptp(self.waveform(fit_, m, branch, predictive=predictive,
                                              seed=seed + i), axis=-1)
                         for i, m in enumerate(mu)], axis=1)


def _orders(n_harmonics: int) -> list[int]:
    """Harmonic order of each coefficient ``[a0, a1..aK, b1..bK]``."""
    return [0, *range(1, n_harmonics + 1), *range(1, n_harmonics + 1)]


def _basis(phi: np.ndarray, n_harmonics: int) -> np.ndarray:
    k = np.arange(1, n_harmonics + 1)
    a = phi[:, None] * k[None]
    return np.concatenate([np.ones((phi.size, 1)), np.cos(a), np.sin(a)], axis=1)


def _design(order: int, r, mu_t) -> np.ndarray:
    """Design row(s) of a coefficient of harmonic ``order``: ``r^k [1, μ̃, r²·(k = 0)]``."""
    r = np.asarray(r, float)
    mu_t = np.broadcast_to(np.asarray(mu_t, float), r.shape)
    rk = r**order
    third = r**2 if order == 0 else np.zeros_like(r)
    return np.stack([rk, rk * mu_t, third], axis=-1)


def _radii(fit_, idx, mu, sign) -> np.ndarray:
    s = fit_.samples
    return np.asarray(normal_form.lco_radius(
        np.asarray(mu)[None], np.asarray(s["mu0"])[idx, None], np.asarray(s["a2"])[idx, None],
        np.asarray(sign, float)[None]))


def _phase_finder(spec):
    def build():
        phi_grid = jnp.linspace(0.0, 2.0 * jnp.pi, N_PHASE_GRID, endpoint=False)

        def f(sites, mu, sign, w):
            def one(s):
                orbit = hybrid.orbit_at(hybrid.params_from_sites(s, spec), mu, sign, phi_grid, spec)
                d2 = jnp.sum((w[:, None, :] - orbit[None]) ** 2, axis=-1)
                return phi_grid[jnp.argmin(d2, axis=-1)]

            return jax.lax.map(one, sites)

        return f

    return hybrid.jit_for_spec(spec, "phase_finder", build)


def _nig_draws(x, y, rng, n, g=100.0):
    """Draws of ``(β, σ)`` of ``y = x β + σ ε`` under a conjugate normal–inverse-gamma prior.

    Zellner's g-prior ``β | σ² ~ N(0, g σ² (xᵀx)⁻¹)`` with g = 100 (the data
    outweigh it a hundredfold, and it is invariant to the units of the design),
    and ``σ² ~ InvGamma(1, 0.01·var(y))`` (weak).
    """
    p = x.shape[1]
    v0_inv = (x.T @ x) / g
    vn = np.linalg.inv(v0_inv + x.T @ x)
    mn = vn @ x.T @ y
    a0, b0 = 1.0, 0.01 * (np.var(y) + 1e-30)
    an = a0 + 0.5 * y.size
    bn = b0 + 0.5 * max(float(y @ y - mn @ (v0_inv + x.T @ x) @ mn), 0.0)
    sigma2 = bn / rng.gamma(an, 1.0, size=n)
    chol = np.linalg.cholesky(vn + 1e-15 * np.eye(p))
    beta = mn[None] + np.sqrt(sigma2)[:, None] * (rng.standard_normal((n, p)) @ chol.T)
    return beta, np.sqrt(sigma2)


def fit_channel(
    fit_,
    recordings: RecordingSet,
    channel: str,
    *,
    n_harmonics: int = 3,
    n_draws: int = 100,
    max_samples: int = 4000,
    seed: int = 0,
) -> ChannelFit:
    """Regress a further channel on the normal-form state of a fitted model.

    Args:
        fit_: A :class:`~bayeshopf.pipeline.HopfFit` of ``recordings``.
        recordings: The recordings the model was fitted to (same order).
        channel: Name of the channel to regress (not one of the planar pair).
        n_harmonics: Harmonics K of the channel's waveform in φ.
        n_draws: Posterior draws of the map used.
        max_samples: Samples per recording (evenly strided over the record).
        seed: Seed of the draws.

    Returns:
        A :class:`ChannelFit`.

    Raises:
        FitError: If the channel is missing from a recording, is a planar
            channel, or the recordings do not match the fit.
    """
    if channel in recordings.planar:
        raise FitError(f"channel {channel!r} is one of the planar pair {recordings.planar}; "
                       "expected a further channel")
    for rec in recordings.recordings:
        if channel not in rec.channels:
            raise FitError(f"{rec.name}: no channel {channel!r}; found {sorted(rec.channels)}")
    feats = fit_.features
    if tuple(feats.names) != tuple(recordings.names):
        raise FitError(f"recordings {recordings.names} are not those of the fit {feats.names}")
    rng = np.random.default_rng(seed)
    n_total = np.shape(fit_.samples["mu0"])[0]
    idx = np.sort(rng.choice(n_total, size=min(n_draws, n_total), replace=False))
    sites = {k: v[idx] for k, v in _site_arrays(fit_.samples, fit_.spec).items()}
    signs = branch_signs(feats.unstable).astype(float)
    radii = _radii(fit_, idx, feats.mu, signs)  # (n_draws, n_rec)
    find = _phase_finder(fit_.spec)
    n_c = 2 * n_harmonics + 1
    coeffs = np.empty((idx.size, len(recordings), n_c))
    # the draw nearest the posterior median of μ0, for the plotted phases
    ref = int(np.argmin(np.abs(np.asarray(fit_.samples["mu0"])[idx]
                               - np.median(fit_.samples["mu0"]))))
    phases, amp = [], np.empty(len(recordings))
    for i, rec in enumerate(recordings.recordings):
        stride = max(1, rec.t.size // max_samples)
        z = np.stack([rec.channels[c][::stride] for c in recordings.planar], axis=-1)
        y = np.asarray(rec.channels[channel][::stride], float)
        w = jnp.asarray(fit_.spec.frame.to_frame(z))
        phi = np.asarray(find(sites, jnp.asarray(feats.mu[i]), jnp.asarray(signs[i]), w))
        for d in range(idx.size):
            coeffs[d, i] = np.linalg.lstsq(_basis(phi[d], n_harmonics), y, rcond=None)[0]
        phases.append((phi[ref], y))
        amp[i] = np.ptp(coeffs[ref, i] @ _basis(np.linspace(0, 2 * np.pi, 256), n_harmonics).T)
    if not np.all(np.isfinite(coeffs)):
        raise FitError(f"channel {channel!r}: a recording lies off every predicted branch")
    mu_t = fit_.spec.mu_tilde(feats.mu)
    beta = np.zeros((idx.size, n_c, 3))
    sigma = np.empty((idx.size, n_c))
    for d in range(idx.size):
        for j, k in enumerate(_orders(n_harmonics)):
            x = _design(k, radii[d], mu_t)
            cols = [0, 1, 2] if k == 0 else [0, 1]
            b, s = _nig_draws(x[:, cols], coeffs[d, :, j], rng, 1)
            beta[d, j, cols] = b[0]
            sigma[d, j] = s[0]
    return ChannelFit(name=channel, units=recordings.recordings[0].units.get(channel, ""),
                      n_harmonics=n_harmonics, draw_index=idx, beta=beta, sigma=sigma,
                      measured_coeffs=coeffs[ref], measured_amplitude=amp, phases=tuple(phases))
