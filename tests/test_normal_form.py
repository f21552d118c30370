from __future__ import annotations

import jax
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bayeshopf.model.normal_form import (
    STABLE,
    UNSTABLE,
    branch_exists,
    fold_point,
    lco_radius,
    radial_field,
)

MU0 = 18.0


def closed_form(mu, mu0, a2, sign):
    """r from r² = (a2 ± √(a2² + 4(μ − μ0)))/2, nan where it is not a positive real."""
    mu = np.asarray(mu, dtype=float)
    disc = a2**2 + 4.0 * (mu - mu0)
    out = np.full(mu.shape, np.nan)
    ok = disc >= 0
    r2 = 0.5 * (a2 + sign * np.sqrt(disc[ok]))
    out[ok] = np.where(r2 > 0, np.sqrt(np.abs(r2)), np.nan)
    return out


@pytest.mark.parametrize("a2", [3.4, 1.0, -0.7, -3.4])
@pytest.mark.parametrize("sign", [STABLE, UNSTABLE])
def test_lco_radius_matches_closed_form(a2: float, sign: float) -> None:
    mu = np.linspace(MU0 - 6.0, MU0 + 4.0, 401)
    r = np.asarray(lco_radius(mu, MU0, a2, sign))
    expected = closed_form(mu, MU0, a2, sign)
    np.testing.assert_array_equal(np.isnan(r), np.isnan(expected))
    np.testing.assert_allclose(r[~np.isnan(r)], expected[~np.isnan(r)], rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(branch_exists(mu, MU0, a2, sign)), ~np.isnan(r))
    # r solves the quartic r⁴ − a2 r² − (μ − μ0) = 0
    ok = ~np.isnan(r)
    np.testing.assert_allclose(r[ok] ** 4 - a2 * r[ok] ** 2 - (mu[ok] - MU0), 0.0, atol=1e-9)


def test_branch_domains() -> None:
    a2 = 3.4
    fold = MU0 - a2**2 / 4
    mu = np.array([fold - 0.5, fold + 0.5, MU0 - 0.5, MU0 + 0.5])
    stable = np.asarray(lco_radius(mu, MU0, a2, STABLE))
    unstable = np.asarray(lco_radius(mu, MU0, a2, UNSTABLE))
    assert np.isnan(stable[0]) and np.all(np.isfinite(stable[1:]))
    assert np.isnan(unstable[0]) and np.all(np.isfinite(unstable[1:3])) and np.isnan(unstable[3])
    # supercritical: one stable branch for μ > μ0, no unstable LCO anywhere
    sup = np.asarray(lco_radius(mu, MU0, -a2, STABLE))
    assert np.all(np.isnan(sup[:3])) and np.isfinite(sup[3])
    assert np.all(np.isnan(np.asarray(lco_radius(mu, MU0, -a2, UNSTABLE))))


@pytest.mark.parametrize(
    ("a2", "sign", "mu"),
    [
        (3.4, STABLE, 15.5),
        (3.4, STABLE, 19.5),
        (3.4, UNSTABLE, 15.5),
        (3.4, UNSTABLE, 17.5),
        (-2.0, STABLE, 18.7),
    ],
)
def test_radius_is_fixed_point(a2: float, sign: float, mu: float) -> None:
    r = float(lco_radius(mu, MU0, a2, sign))
    assert r > 0
    assert abs(float(radial_field(r, mu, MU0, a2))) < 1e-12 * max(1.0, r**5)
    # the field changes sign across it (it is an isolated zero)
    assert radial_field(0.99 * r, mu, MU0, a2) * radial_field(1.01 * r, mu, MU0, a2) < 0


def _integrate(r0: float, mu: float, a2: float, t_end: float) -> float:
    sol = solve_ivp(
        lambda t, y: [float(radial_field(y[0], mu, MU0, a2))],
        (0.0, t_end),
        [r0],
        rtol=1e-10,
        atol=1e-12,
    )
    assert sol.success
    return float(sol.y[0, -1])


@pytest.mark.parametrize(("a2", "mu"), [(3.4, 15.5), (3.4, 17.0), (3.4, 19.5), (-2.0, 18.7)])
@pytest.mark.parametrize("offset", [-0.1, 0.1])
def test_stable_radius_attracts(a2: float, mu: float, offset: float) -> None:
    r_s = float(lco_radius(mu, MU0, a2, STABLE))
    r_end = _integrate(r_s * (1 + offset), mu, a2, 40.0)
    assert r_end == pytest.approx(r_s, rel=1e-6)


@pytest.mark.parametrize("mu", [15.5, 16.5, 17.5])
def test_unstable_radius_repels(mu: float) -> None:
    a2 = 3.4
    r_u = float(lco_radius(mu, MU0, a2, UNSTABLE))
    r_s = float(lco_radius(mu, MU0, a2, STABLE))
    inside = _integrate(r_u * 0.98, mu, a2, 40.0)
    outside = _integrate(r_u * 1.02, mu, a2, 40.0)
    # inside: decays to the equilibrium; outside: grows to the stable LCO
    assert inside < 0.01 * r_u
    assert outside == pytest.approx(r_s, rel=1e-6)


@pytest.mark.parametrize("a2", [3.0, 1.0, 2.5])
def test_fold_is_where_branches_meet(a2: float) -> None:
    # a2²/4 is exact in binary for these a2, so μ = fold_point gives disc = 0 exactly
    fold = float(fold_point(MU0, a2))
    assert fold == MU0 - a2**2 / 4
    r_s = float(lco_radius(fold, MU0, a2, STABLE))
    r_u = float(lco_radius(fold, MU0, a2, UNSTABLE))
    assert r_s == pytest.approx(np.sqrt(a2 / 2), rel=1e-12)
    assert r_u == pytest.approx(r_s, rel=1e-12)
    # at the fold the radius is a double root: ∂ṙ/∂r = 0 there
    assert abs(float(jax.grad(radial_field)(r_s, fold, MU0, a2))) < 1e-10


@pytest.mark.parametrize("a2", [3.4, 1.2, 0.3])
def test_branches_merge_at_fold(a2: float) -> None:
    fold = float(fold_point(MU0, a2))
    assert fold == pytest.approx(MU0 - a2**2 / 4, abs=1e-14)
    # just below: no LCO; just above: two LCOs that merge as μ → μ_SN⁺
    below = fold - 1e-3
    assert np.isnan(float(lco_radius(below, MU0, a2, STABLE)))
    assert np.isnan(float(lco_radius(below, MU0, a2, UNSTABLE)))
    for rel in (1e-2, 1e-4, 1e-8):
        d = rel * a2**2 / 4
        r_s = float(lco_radius(fold + d, MU0, a2, STABLE))
        r_u = float(lco_radius(fold + d, MU0, a2, UNSTABLE))
        assert r_s > r_u > 0
        # r_s² − r_u² = √(a2² + 4(μ − μ0)) = √(4(μ − μ_SN)): the gap closes like √d
        assert r_s**2 - r_u**2 == pytest.approx(np.sqrt(4 * d), rel=1e-4)
    # and both tend to the double root √(a2/2)
    assert r_s == pytest.approx(np.sqrt(a2 / 2), rel=1e-3)
    assert r_u == pytest.approx(np.sqrt(a2 / 2), rel=1e-3)


def test_gradients_finite_where_branch_exists() -> None:
    g = jax.grad(lambda mu0, a2: lco_radius(16.0, mu0, a2, UNSTABLE), argnums=(0, 1))(18.0, 3.4)
    assert np.all(np.isfinite(np.array(g)))
    # r² = (a2 − √(a2² + 4(μ − μ0)))/2 ⇒ ∂r/∂μ0 = 1/(2 r √disc)
    r = float(lco_radius(16.0, 18.0, 3.4, UNSTABLE))
    disc = 3.4**2 + 4 * (16.0 - 18.0)
    assert float(g[0]) == pytest.approx(1.0 / (2 * r * np.sqrt(disc)), rel=1e-10)


# ------------------------------------------------- the supercritical gauge: a2 = −1, a4 = −κ


@pytest.mark.parametrize("kappa", [0.0, 0.05, 1.0, 20.0])
def test_supercritical_gauge_radius(kappa: float) -> None:
    """r² = 2(μ−μ0)/(1 + √(1 + 4κ(μ−μ0))): a zero of ṙ = Δ r − r³ − κ r⁵, none below μ0."""
    mu = np.linspace(MU0 - 1.0, MU0 + 3.0, 401)
    r = np.asarray(lco_radius(mu, MU0, -1.0, STABLE, -kappa))
    d = mu - MU0
    above = d > 0
    assert np.all(np.isnan(r[~above])) and np.all(np.isfinite(r[above]))
    expected = np.sqrt(2 * d[above] / (1 + np.sqrt(1 + 4 * kappa * d[above])))
    np.testing.assert_allclose(r[above], expected, rtol=1e-12)
    np.testing.assert_allclose(
        np.asarray(radial_field(r[above], mu[above], MU0, -1.0, -kappa)), 0.0, atol=1e-12
    )
    assert np.all(np.isnan(np.asarray(lco_radius(mu, MU0, -1.0, UNSTABLE, -kappa))))
    if kappa == 0.0:  # the square-root law of a generic supercritical Hopf point
        np.testing.assert_allclose(r[above] ** 2, d[above], rtol=1e-12)


@pytest.mark.parametrize("a2", [-0.7, -3.4])
def test_supercritical_gauges_are_the_same_family(a2: float) -> None:
    """Quintic gauge (a2 < 0, a4 = −1) = supercritical gauge (−1, −1/a2²) with r scaled by √|a2|."""
    mu = np.linspace(MU0 + 1e-3, MU0 + 4.0, 101)
    r_quintic = np.asarray(lco_radius(mu, MU0, a2, STABLE))
    r_gauge = np.asarray(lco_radius(mu, MU0, -1.0, STABLE, -1.0 / a2**2))
    np.testing.assert_allclose(r_gauge, np.sqrt(abs(a2)) * r_quintic, rtol=1e-12)


@pytest.mark.parametrize("offset", [-0.3, 0.3])
def test_supercritical_gauge_radius_attracts(offset: float) -> None:
    """solve_ivp of ṙ = Δ r − r³ − κ r⁵ from ±30 % ends on the closed-form radius."""
    mu, kappa = MU0 + 0.8, 0.4
    r_s = float(lco_radius(mu, MU0, -1.0, STABLE, -kappa))
    sol = solve_ivp(lambda t, y: [float(radial_field(y[0], mu, MU0, -1.0, -kappa))],
                    (0.0, 80.0), [r_s * (1 + offset)], rtol=1e-10, atol=1e-12)
    assert sol.success and sol.y[0, -1] == pytest.approx(r_s, rel=1e-6)
    # and the gradient in κ is finite at κ = 0 (the prior's mode)
    g = jax.grad(lambda k: lco_radius(mu, MU0, -1.0, STABLE, -k))(0.0)
    assert np.isfinite(float(g)) and float(g) < 0
