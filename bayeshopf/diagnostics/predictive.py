"""Posterior predictions of the hybrid model, vectorised over draws.

Every function takes the posterior draws (a dict of site arrays with a leading
draw axis, as NumPyro returns them) and the :class:`ModelSpec`, rebuilds
:class:`HopfParams` per draw (``params_from_sites``) and maps the pure model
functions over draws and μ with ``jax.vmap``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from bayeshopf.features import fourier
from bayeshopf.model import hybrid, normal_form
from bayeshopf.model.hybrid import ModelSpec
from bayeshopf.model.probabilistic import harmonic_scatter


def _site_arrays(samples: dict, spec: ModelSpec) -> dict:
    keys = hybrid.param_site_names(spec, samples)
    missing = [k for k in keys if k not in samples]
    if missing:
        raise KeyError(f"posterior draws lack the site(s) {', '.join(missing)}")
    return {k: jnp.asarray(samples[k]) for k in keys}


def amplitude_draws(samples: dict, spec: ModelSpec, mu, sign) -> np.ndarray:
    """Peak-to-peak of z1 on branch ``sign`` at each μ, per draw.

    Args:
        samples: Posterior draws, leading axis ``n_draws``.
        spec: The model structure.
        mu: μ values, shape ``(n_mu,)``.
        sign: Branch sign per μ (+1 stable, −1 unstable), shape ``(n_mu,)`` or scalar.

    Returns:
        Array ``(n_draws, n_mu)``; ``nan`` where the draw has no LCO on that branch.
    """

    def build():
        def f(sites, mu, sign):
            def one(s):
                p = hybrid.params_from_sites(s, spec)
                return jax.vmap(lambda m, g: hybrid.amplitude(p, m, g, spec))(mu, sign)

            return jax.vmap(one)(sites)

        return f

    mu = jnp.atleast_1d(jnp.asarray(mu, dtype=float))
    sign = jnp.broadcast_to(jnp.asarray(sign, dtype=float), mu.shape)
    f = hybrid.jit_for_spec(spec, "amplitude", build)
    return np.asarray(f(_site_arrays(samples, spec), mu, sign))


def orbit_draws(samples: dict, spec: ModelSpec, mu: float, sign: float) -> np.ndarray:
    """Predicted orbits in physical units at one μ, shape ``(n_draws, n_phi, 2)``."""

    def build():
        def f(sites, mu, sign):
            return jax.vmap(
                lambda s: hybrid.orbit_physical(hybrid.params_from_sites(s, spec), mu, sign, spec)
            )(sites)

        return f

    f = hybrid.jit_for_spec(spec, "orbit", build)
    return np.asarray(f(_site_arrays(samples, spec), jnp.asarray(mu, float),
                        jnp.asarray(sign, float)))


def fold_amplitude_draws(samples: dict, spec: ModelSpec) -> np.ndarray:
    """Amplitude at the fold (where the branches meet, ``r² = a2/2``), per draw.

    ``nan`` for supercritical draws (no fold).
    """
    mu_fold = np.asarray(normal_form.fold_point(samples["mu0"], samples["a2"]))
    amp = _diag_amplitude(samples, spec, mu_fold + 1e-9, normal_form.STABLE)
    return np.where(np.asarray(samples["a2"]) > 0, amp, np.nan)


def _diag_amplitude(samples: dict, spec: ModelSpec, mu_per_draw, sign) -> np.ndarray:
    """Amplitude of draw i at its own μ_i, shape ``(n_draws,)``."""

    def build():
        def f(sites, mu, sign):
            return jax.vmap(
                lambda s, m: hybrid.amplitude(hybrid.params_from_sites(s, spec), m, sign, spec)
            )(sites, mu)

        return f

    f = hybrid.jit_for_spec(spec, "diag", build)
    return np.asarray(f(_site_arrays(samples, spec), jnp.asarray(mu_per_draw, float),
                        jnp.asarray(sign, float)))


#: Smallest ``min R / max R`` of a predicted orbit about the frame centre for
#: which its R(θ) coefficients are used. Where the orbit centres drift with the
#: amplitude (3-DOF flutter: the mean pitch moves by 0.035 rad between small and
#: large orbits) the centre that every training orbit encircles lies off-centre
#: in the large ones, down to a ratio of 0.12 at 20 m/s; there the amplitude of
#: the R(θ) reconstruction (n_phi = 64 points, 8 harmonics) still matches the
#: mapped orbit's to 0.4%.
MIN_RADIUS_RATIO = 0.1


def _encircles_origin(w):
    """Whether closed curves ``w`` (..., n, 2) wind once around the frame origin.

    R(θ) features describe an orbit only if it encircles the common centre;
    tiny orbits near μ0 may not, and their Fourier coefficients are meaningless.
    """
    th = jnp.arctan2(w[..., 1], w[..., 0])
    d = jnp.diff(jnp.concatenate([th, th[..., :1]], axis=-1), axis=-1)
    d = (d + jnp.pi) % (2.0 * jnp.pi) - jnp.pi
    R = jnp.hypot(w[..., 0], w[..., 1])
    # the centre must lie well inside: otherwise θ bunches up and the
    # least-squares Fourier fit of R(θ) is ill-conditioned
    well_inside = jnp.min(R, axis=-1) > MIN_RADIUS_RATIO * jnp.max(R, axis=-1)
    return (jnp.abs(jnp.sum(d, axis=-1)) > jnp.pi) & well_inside


def predictive_amplitude_draws(
    samples: dict, spec: ModelSpec, mu, sign, key: jax.Array, coeffs_sd=None
) -> np.ndarray:
    """Posterior predictive amplitude of a new recording at each μ, per draw.

    A replicated recording has coefficients ``Φ̃ ~ N(Φ(R̂), √(σ² + s²))`` (the
    likelihood of the model; ``s`` is the recording's measured segment spread,
    zero for an unseen μ), and its amplitude is the peak-to-peak of z1 of the
    orbit those coefficients describe. This is the band a new measurement falls
    in, whereas :func:`amplitude_draws` is the band of the model's curve.

    Returns:
        Array ``(n_draws, n_mu)``; ``nan`` where the branch does not exist or
        the predicted orbit does not encircle the frame's centre (very small
        orbits next to μ0, where R(θ) is undefined).
    """
    n_pts = 256

    def build():
        def f(sites, sigma, mu, sign, eps, sd):
            def one(s, sg, e):
                p = hybrid.params_from_sites(s, spec)
                c = jax.vmap(lambda m, g: hybrid.predicted_coeffs(p, m, g, spec))(mu, sign)
                w = jax.vmap(lambda m, g: hybrid.orbit_in_frame(p, m, g, spec))(mu, sign)
                c = c + jnp.sqrt(harmonic_scatter(sg) ** 2 + sd**2) * e
                z = spec.frame.from_frame(fourier.curve(c, n_pts))
                amp = jnp.max(z[..., 0], axis=-1) - jnp.min(z[..., 0], axis=-1)
                return jnp.where(_encircles_origin(w), amp, jnp.nan)

            return jax.vmap(one)(sites, sigma, eps)

        return f

    mu = jnp.atleast_1d(jnp.asarray(mu, dtype=float))
    sign = jnp.broadcast_to(jnp.asarray(sign, dtype=float), mu.shape)
    n_draws = np.shape(samples["mu0"])[0]
    n_c = fourier.n_coefficients(spec.n_h)
    # common random numbers along μ: one replicated recording per draw, so the
    # band's edges are smooth curves rather than per-μ Monte Carlo noise
    eps = jnp.broadcast_to(jax.random.normal(key, (n_draws, 1, n_c)), (n_draws, mu.size, n_c))
    sd = jnp.zeros((mu.size, n_c)) if coeffs_sd is None else jnp.asarray(coeffs_sd, float)
    return np.asarray(
        hybrid.jit_for_spec(spec, "predictive", build)(
            _site_arrays(samples, spec), jnp.asarray(samples["sigma"]), mu, sign, eps, sd
        )
    )
