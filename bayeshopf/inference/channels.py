"""Channels beyond the planar pair, by regression once U12 is inverted.

The paper's "mapping to other coordinates": a further measured channel ``y``
(the actuator command, the CBC target, a strain gauge...) is a function of the
state, ``y = f(u, μ)``. Once the planar map is fitted (the collapsed
core, :class:`~bayeshopf.posterior.HybridPosterior`), every measured sample is
placed on its predicted orbit, which inverts the map along the LCO: the
sample's normal-form phase is that of the nearest point of the predicted orbit
in the frame of the features,

    φ(t) = argmin_φ ‖w(t) − w_θ,β(φ; μ)‖,   w_θ,β(φ; μ) = Ψ(s(μ) [cos φ, sin φ], μ̃) β

(:func:`~bayeshopf.model.collapsed.orbit`, ``s = r(μ)/r_ref``), for each
posterior draw ``(θ, β)`` of the normal form and the map.

``f`` is linear in basis functions of the state,

    f = β · b(u, μ̃),   b = [1, μ̃, w1, w2, μ̃ w1, μ̃ w2, w1², w1 w2, w2², w1³, w2³],

where ``w = w_θ,β(φ; μ)`` is the fitted planar position in the frame (so the
basis carries the map's gain and its correction) and the quadratic and cubic terms allow a
nonlinear channel. As for the map, the fit compares closed curves: ``y`` and
each basis function are projected onto a Fourier series in φ (K harmonics) per
recording, and ``β`` is a conjugate Bayesian linear regression of all
recordings' coefficients (conjugate, under the reference prior), so the misfit
σ is estimated. It is repeated for posterior draws of ``(θ, β)``, so
the channel's band carries the fit's uncertainty and the regression's.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from bayeshopf._x64 import ensure_x64
from bayeshopf.data.recording import RecordingSet
from bayeshopf.errors import FitError
from bayeshopf.model import collapsed as cm
from bayeshopf.model.normal_form import branch_sign

#: Phases on which the predicted orbit is searched for the nearest point.
N_PHASE_GRID = 720


#: Names of the basis functions ``b(u, μ̃)``.
BASIS = ("1", "mu", "w1", "w2", "mu*w1", "mu*w2", "w1^2", "w1*w2", "w2^2", "w1^3", "w2^3")


@dataclass(frozen=True)
class ChannelFit:
    """A further channel regressed on the normal-form state (immutable).

    Attributes:
        name: Channel name.
        units: Its unit.
        n_harmonics: Harmonics K of the channel's waveform in φ.
        draw_index: Posterior draws ``(θ, β)`` of the fit used, shape ``(n_draws,)``.
        beta: Regression coefficients per draw, ``(n_draws, len(BASIS))``.
        sigma: Misfit scatter of a Fourier coefficient per draw, ``(n_draws,)``.
        measured_coeffs: Per-recording Fourier coefficients of the channel at a
            central draw, ``(n_rec, 2K+1)``.
        measured_amplitude: Per-recording peak-to-peak of the measured
            channel's Fourier reconstruction, ``(n_rec,)``.
        phases: Per recording, ``(φ, y)`` of the (down-sampled) measured
            samples at that draw, for plots.
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

    def waveform(self, post, mu: float, branch: str = "stable", *, predictive: bool = False,
                 n_phi: int = 128, seed: int = 0) -> np.ndarray:
        """The channel along the orbit at μ, ``(n_draws, n_phi)`` on ``φ ∈ [0, 2π)``.

        ``y(φ) = βᵀ b(w_θ,β(φ; μ), μ̃)`` for each draw; ``nan`` where the branch
        does not exist in a draw. ``predictive=True`` adds the misfit σ to every
        Fourier coefficient: the band a new recording's waveform falls in.

        Args:
            post: The :class:`~bayeshopf.posterior.HybridPosterior` the channel was fitted with.
            mu: μ.
            branch: ``"stable"`` or ``"unstable"``.
            predictive: Add a new recording's misfit.
            n_phi: Phases.
            seed: Seed of the misfit draws.
        """
        phi = np.linspace(0.0, 2.0 * np.pi, n_phi, endpoint=False)
        b = _basis_along_orbits(post, self.draw_index, mu, branch_sign(branch), phi)  # (d, n, p)
        y = np.einsum("dnp,dp->dn", b, self.beta)
        if predictive:
            rng = np.random.default_rng(seed)
            eps = self.sigma[:, None] * rng.standard_normal((y.shape[0], 2 * self.n_harmonics + 1))
            y = y + eps @ _fourier(phi, self.n_harmonics).T
        return y

    def amplitude(self, post, mu, branch: str = "stable", *, predictive: bool = False,
                  seed: int = 0) -> np.ndarray:
        """Peak-to-peak of the channel at each μ, ``(n_draws, n_mu)``.

        The predictive draws use common random numbers along μ (one replicated
        recording per draw), so band edges are smooth curves.
        """
        mu = np.atleast_1d(np.asarray(mu, float))
        return np.stack([np.ptp(self.waveform(post, m, branch, predictive=predictive,
                                              seed=seed), axis=-1)
                         for m in mu], axis=1)


def _fourier(phi: np.ndarray, n_harmonics: int) -> np.ndarray:
    """``[1, cos φ..cos Kφ, sin φ..sin Kφ]``, shape ``(n_phi, 2K+1)``."""
    k = np.arange(1, n_harmonics + 1)
    a = phi[:, None] * k[None]
    return np.concatenate([np.ones((phi.size, 1)), np.cos(a), np.sin(a)], axis=1)


def _basis(w, mu_t):
    """``b(u, μ̃)`` from the planar position ``w`` (..., 2), shape ``(..., len(BASIS))``."""
    w1, w2 = w[..., 0], w[..., 1]
    m = jnp.broadcast_to(mu_t, w1.shape)
    one = jnp.ones_like(w1)
    return jnp.stack([one, m, w1, w2, m * w1, m * w2, w1**2, w1 * w2, w2**2, w1**3, w2**3],
                     axis=-1)


_PHASE_GRID = np.linspace(0.0, 2.0 * np.pi, N_PHASE_GRID, endpoint=False)


def _basis_along(spec: cm.CollapsedSpec, theta, betas, mu, sign, phi):
    """``b`` along each draw's orbit at μ (``lax.map``: batched algebra is slow on CPU)."""
    return jax.lax.map(lambda a: _basis(cm.orbit(spec, a[0], a[1], mu, sign, phi),
                                        spec.mu_tilde(mu)), (theta, betas))


def _nearest_phase(spec: cm.CollapsedSpec, theta, betas, mu, sign, w):
    """Per draw, the grid phase whose orbit point is nearest each sample ``w``."""
    grid = jnp.asarray(_PHASE_GRID)

    def one(a):
        o = cm.orbit(spec, a[0], a[1], mu, sign, grid)
        d2 = jnp.sum((w[:, None, :] - o[None]) ** 2, axis=-1)
        return grid[jnp.argmin(d2, axis=-1)]

    return jax.lax.map(one, (theta, betas))


def _draws(post, idx) -> tuple[dict, jnp.ndarray]:
    theta = {k: jnp.asarray(np.asarray(v)[idx]) for k, v in post.theta.items()}
    return theta, jnp.asarray(post.run.betas[idx])


def _basis_along_orbits(post, idx, mu, sign, phi) -> np.ndarray:
    """``b`` along each draw's predicted orbit at μ, ``(n_draws, n_phi, len(BASIS))``."""
    theta, betas = _draws(post, idx)
    return np.asarray(cm.spec_jit(post.spec, _basis_along)(
        theta, betas, jnp.asarray(mu, float), jnp.asarray(sign, float), jnp.asarray(phi)))


def _regression_draw(x, y, rng):
    """One posterior draw of ``(β, σ)`` of ``y = x β + σ ε`` under the reference prior.

    With ``p(β, σ²) ∝ 1/σ²`` the posterior is conjugate:
    ``σ² | y ~ InvGamma((n − p)/2, RSS/2)`` and ``β | σ², y ~ N(β̂, σ² (xᵀx)⁻¹)``,
    where ``β̂`` is the least-squares solution and RSS its residual sum of squares.
    """
    n, p = x.shape
    if n <= p:
        raise FitError(f"channel regression needs more coefficients than basis functions; "
                       f"got {n} coefficients for {p} basis functions")
    xtx = x.T @ x
    xtx = xtx + 1e-12 * np.trace(xtx) / p * np.eye(p)
    cov = np.linalg.inv(xtx)
    beta_hat = cov @ x.T @ y
    rss = float(np.sum((y - x @ beta_hat) ** 2))
    sigma2 = (0.5 * rss + 1e-300) / rng.gamma(0.5 * (n - p), 1.0)
    beta = rng.multivariate_normal(beta_hat, sigma2 * (cov + cov.T) / 2.0)
    return beta, float(np.sqrt(sigma2))


def fit_channel(
    post,
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
        post: A :class:`~bayeshopf.posterior.HybridPosterior` of ``recordings``.
        recordings: The recordings the model was fitted to (same order).
        channel: Name of the channel to regress (not one of the planar pair).
        n_harmonics: Harmonics K of the channel's waveform in φ.
        n_draws: Posterior draws ``(θ, β)`` used.
        max_samples: Samples per recording (evenly strided over the record).
        seed: Seed of the draws.

    Returns:
        A :class:`ChannelFit`.

    Raises:
        FitError: If the channel is missing from a recording, is a planar
            channel, the recordings do not match the fit, or a recording lies
            off every predicted branch.
    """
    ensure_x64()
    if channel in recordings.planar:
        raise FitError(f"channel {channel!r} is one of the planar pair {recordings.planar}; "
                       "expected a further channel")
    for rec in recordings.recordings:
        if channel not in rec.channels:
            raise FitError(f"{rec.name}: no channel {channel!r}; found {sorted(rec.channels)}")
    feats = post.features
    if tuple(feats.names) != tuple(recordings.names):
        raise FitError(f"recordings {tuple(recordings.names)} are not those of the fit "
                       f"{tuple(feats.names)}")
    rng = np.random.default_rng(seed)
    mu0 = np.asarray(post.samples["mu0"])
    idx = np.sort(rng.choice(mu0.size, size=min(n_draws, mu0.size), replace=False))
    theta, betas = _draws(post, idx)
    find = cm.spec_jit(post.spec, _nearest_phase)
    n_c = 2 * n_harmonics + 1
    phi_grid = np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False)
    proj = np.linalg.pinv(_fourier(phi_grid, n_harmonics))  # grid values -> coefficients
    y_coeffs = np.empty((idx.size, len(recordings), n_c))
    b_coeffs = np.empty((idx.size, len(recordings), n_c, len(BASIS)))
    # a central draw (nearest the posterior median of μ0) for the plotted phases
    ref = int(np.argmin(np.abs(mu0[idx] - np.median(mu0))))
    phases = []
    for i, rec in enumerate(recordings.recordings):
        sign = -1.0 if feats.unstable[i] else 1.0
        stride = max(1, rec.t.size // max_samples)
        z = np.stack([rec.channels[c][::stride] for c in recordings.planar], axis=-1)
        y = np.asarray(rec.channels[channel][::stride], float)
        w = jnp.asarray(post.spec.frame.to_frame(z))
        phi = np.asarray(find(theta, betas, jnp.asarray(feats.mu[i], float), jnp.asarray(sign),
                              w))
        for d in range(idx.size):
            y_coeffs[d, i] = np.linalg.lstsq(_fourier(phi[d], n_harmonics), y, rcond=None)[0]
        b = _basis_along_orbits(post, idx, feats.mu[i], sign, phi_grid)   # (d, 64, p)
        b_coeffs[:, i] = np.einsum("cn,dnp->dcp", proj, b)
        phases.append((phi[ref], y))
    if not (np.all(np.isfinite(y_coeffs)) and np.all(np.isfinite(b_coeffs))):
        raise FitError(f"channel {channel!r}: a recording lies off its predicted branch in some "
                       "posterior draws (the orbit does not exist at its μ); expected every "
                       "recording on its branch")
    beta = np.empty((idx.size, len(BASIS)))
    sigma = np.empty(idx.size)
    for d in range(idx.size):
        beta[d], sigma[d] = _regression_draw(b_coeffs[d].reshape(-1, len(BASIS)),
                                             y_coeffs[d].reshape(-1), rng)
    amp = np.ptp(y_coeffs[ref] @ _fourier(np.linspace(0, 2 * np.pi, 256), n_harmonics).T,
                 axis=-1)
    return ChannelFit(name=channel, units=recordings.recordings[0].units.get(channel, ""),
                      n_harmonics=n_harmonics, draw_index=idx, beta=beta, sigma=sigma,
                      measured_coeffs=y_coeffs[ref], measured_amplitude=amp, phases=tuple(phases))
