"""Data-driven starting point and prior constants (no hand-tuned magic numbers).

The closed-form LCO radius explains how the orbit size grows with μ; fitting
``a0_i ≈ g r(μ_i)`` (a0: the mean of the measured R(θ) in the frame) over the
gaps to μ0 and the fold (supercritical: the gap to μ0 and the quintic κ) gives
starting values for the normal form and for the gain g of T_L.
The orbit centres, regressed on μ̃, give T_s and the μ column of T_L.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.optimize import least_squares

from bayeshopf.errors import FitError
from bayeshopf.features import fourier
from bayeshopf.features.orbits import OrbitFeatures
from bayeshopf.model import normal_form
from bayeshopf.model.hybrid import ModelSpec, branch_signs


def build_spec(
    features: OrbitFeatures,
    criticality: str,
    *,
    nn_width: int = 10,
    nn_depth: int = 2,
    n_phi: int = 64,
    mu_label: str = "mu",
    mu_units: str = "",
) -> ModelSpec:
    """Model structure and prior constants from the training features.

    Raises:
        FitError: For fewer than two distinct μ, or unstable recordings under a
            supercritical model (a supercritical Hopf has no unstable LCOs).
    """
    if criticality not in ("subcritical", "supercritical"):
        raise FitError(f"criticality must be 'subcritical' or 'supercritical'; got {criticality!r}")
    mu = features.mu
    if np.unique(mu).size < 2:
        raise FitError(
            f"the fit needs recordings at two or more distinct values of μ; found "
            f"{features.n_recordings} recording(s) at μ = {sorted(set(mu.tolist()))}"
        )
    if criticality == "supercritical" and features.unstable.any():
        raise FitError(
            "criticality 'supercritical' has no unstable LCO branch, but the data hold "
            f"{int(features.unstable.sum())} unstable recording(s); use 'subcritical' or 'auto'"
        )
    unstable_mu = mu[features.unstable]
    return ModelSpec(
        criticality=criticality,
        frame=features.frame,
        n_h=features.n_h,
        mu_centre=float(0.5 * (mu.max() + mu.min())),
        mu_span=float(mu.max() - mu.min()),
        mu_min=float(mu.min()),
        mu_unstable_max=float(unstable_mu.max()) if unstable_mu.size else None,
        orbit_scale=float(np.median(features.coeffs[:, 0])),
        nn_width=nn_width,
        nn_depth=nn_depth,
        n_phi=n_phi,
        mu_label=mu_label,
        mu_units=mu_units,
    )


def _normal_form_from_gaps(spec: ModelSpec, x: np.ndarray) -> tuple[float, float, float]:
    """``(μ0, a2, a4)`` from the log gaps (and, supercritical, log κ) in ``x[:2]``."""
    if spec.criticality == "subcritical":
        g_fold, g_hopf = np.exp(x[:2])
        mu_fold = spec.mu_min - g_fold
        anchor = mu_fold if spec.mu_unstable_max is None else max(mu_fold, spec.mu_unstable_max)
        mu0 = anchor + g_hopf
        return mu0, 2.0 * np.sqrt(mu0 - mu_fold), -1.0
    g_hopf, kappa = np.exp(x[:2])
    return spec.mu_min - g_hopf, -1.0, -kappa


def initial_values(features: OrbitFeatures, spec: ModelSpec) -> dict:
    """Constrained starting values of the model's sites (see the module docstring)."""
    a0 = features.coeffs[:, 0]
    sign = branch_signs(features.unstable)
    span = spec.mu_span

    def resid(x):
        mu0, a2, a4 = _normal_form_from_gaps(spec, x)
        r = np.asarray(normal_form.lco_radius(features.mu, mu0, a2, sign, a4))
        return np.log(a0) - x[2] - np.log(r)

    best = None
    for g1, g2 in itertools.product([0.03, 0.1, 0.3, 1.0], repeat=2):
        scale2 = 1.0 / span if spec.criticality == "supercritical" else span
        x0 = np.array([np.log(g1 * span), np.log(g2 * scale2), 0.0])
        mu0, a2, a4 = _normal_form_from_gaps(spec, x0)
        r0 = np.asarray(normal_form.lco_radius(features.mu, mu0, a2, sign, a4))
        x0[2] = np.mean(np.log(a0) - np.log(r0))
        with np.errstate(over="ignore", invalid="ignore"):  # trial steps may overflow
            sol = least_squares(resid, x0, method="lm")
        if best is None or sol.cost < best.cost:
            best = sol
    if best is None or not np.isfinite(best.cost):
        raise FitError("could not find a starting point: the closed-form radius fit failed")
    x = best.x.copy()
    # keep the start off the boundary: a gap of 0 puts a recording exactly at the
    # fold, where the radius has an infinite μ-derivative and the gradient is nan
    # (supercritical: a κ of 0 is the square-root law, allowed but kept off
    # the log's singularity)
    floor = np.log(0.02 * np.array([span, span if spec.criticality == "subcritical" else 1 / span]))
    x[:2] = np.maximum(x[:2], floor)
    gain = float(np.exp(x[2]))
    # orbit centres in the frame, regressed on μ̃: T_s + T_L_mu μ̃
    centres = fourier.curve(features.coeffs, 256).mean(axis=1)
    X = np.stack([np.ones_like(features.mu), spec.mu_tilde(features.mu)], axis=1)
    beta, *_ = np.linalg.lstsq(X, centres, rcond=None)
    rho = spec.orbit_scale
    v = {
        "T_L_diag": np.array([gain, gain]),
        "T_L_21": 0.0,
        "T_L_mu": beta[1],
        "T_L1": np.zeros(3),
        "T_L2": np.zeros(3),
        "T_s": beta[0],
        "nn_scale": 0.01 * rho,
        # the closed-form fit's RMS error in a0, as a first guess of every σ_k
        "sigma": np.full(
            spec.n_h + 1,
            float(np.sqrt(np.mean((a0 * (1.0 - np.exp(-resid(x)))) ** 2))) + 1e-3 * rho,
        ),
    }
    if spec.criticality == "subcritical":
        v["gap_fold"], v["gap_hopf"] = np.exp(x[:2])
    else:
        v["gap_hopf"], v["kappa"] = np.exp(x[:2])
    return {k: np.asarray(val, dtype=np.float64) for k, val in v.items()}

