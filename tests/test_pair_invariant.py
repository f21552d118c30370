"""The map-free pair invariant x = (A_s A_u)²/(A_s² + A_u²)² = (μ0 − μ)/a2²."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.figure import Figure

from bayeshopf.diagnostics.pair_invariant import (
    invariant,
    invariant_line,
    leave_one_pair_out,
    pair_invariants,
    unstable_amplitude_from,
)
from bayeshopf.model.normal_form import STABLE, UNSTABLE, fold_point, lco_radius
from bayeshopf.plotting.pair_invariant import plot_pair_invariant

MU0, A2 = 17.5, 3.3


def _features(mu_s, mu_u, gain, sd=1e-6):
    """Amplitudes g(μ) r(μ) of the closed-form LCOs, as a features-like record."""
    mu = np.concatenate([mu_s, mu_u])
    sign = np.concatenate([np.full(len(mu_s), STABLE), np.full(len(mu_u), UNSTABLE)])
    amp = gain(mu) * np.asarray(lco_radius(mu, MU0, A2, sign))
    return SimpleNamespace(
        mu=mu, unstable=sign < 0, amplitude=amp, amplitude_sd=np.full(mu.size, sd),
        names=tuple(f"{'s' if s > 0 else 'u'}{m:g}" for s, m in zip(sign, mu, strict=True)))


def test_invariant_is_linear_in_mu_whatever_the_gain():
    # any gain per μ (here a wild one) multiplies both orbits at that μ alike
    f = _features([14.9, 15.7, 16.5], [14.9, 15.7, 16.5], lambda m: 0.01 * (1 + np.sin(3 * m) ** 2))
    pairs = pair_invariants(f)
    assert [p.mu for p in pairs] == [14.9, 15.7, 16.5]
    np.testing.assert_allclose([p.x for p in pairs], (MU0 - np.array([14.9, 15.7, 16.5])) / A2**2,
                               rtol=1e-10)
    line = invariant_line(pairs)
    assert line.mu0 == pytest.approx(MU0, abs=1e-9)
    assert line.a2 == pytest.approx(A2, rel=1e-9)
    assert line.mu_fold == pytest.approx(float(fold_point(MU0, A2)), abs=1e-9)
    np.testing.assert_allclose(line.residuals, 0.0, atol=1e-12)
    # the intervals (tiny spreads) hold the truth
    assert line.interval("mu0").contains(MU0) and line.interval("a2").contains(A2)


def test_two_pairs_predict_the_third_and_interpolation():
    # the stable orbit is measured at 15.6 and 16.5 only; at 16.0 its amplitude
    # is interpolated (exact here: the gain makes A_s linear in μ there)
    mu_s = np.array([14.9, 15.6, 16.5])
    slope = (0.05 - 0.03) / (16.5 - 15.6)

    def gain(m):
        # A_s = 0.03 + slope (μ − 15.6) on [15.6, 16.5] at the stable radius
        r = np.asarray(lco_radius(m, MU0, A2, STABLE))
        return (0.03 + slope * (m - 15.6)) / r

    f = _features(mu_s, [14.9, 16.0, 16.5], gain)
    pairs = pair_invariants(f)
    assert pairs[1].stable == ("s15.6", "s16.5")
    assert pairs[1].x == pytest.approx((MU0 - 16.0) / A2**2, rel=1e-9)
    loo = leave_one_pair_out(pairs)
    assert [h.mu for h, _ in loo] == [14.9, 16.0, 16.5]
    held, line = loo[2]
    assert line.draws == pytest.approx(invariant_line(pairs[:2]).draws)
    pred = line.unstable_amplitude(held.mu, held.stable_amplitude)
    assert pred.median == pytest.approx(held.unstable_amplitude, rel=1e-4)
    assert pred.contains(held.unstable_amplitude)


def test_unstable_amplitude_inverts_the_invariant():
    a_s = np.array([1.0, 2.0, 5.0])
    a_u = np.array([0.9, 0.3, 4.99])
    np.testing.assert_allclose(unstable_amplitude_from(invariant(a_s, a_u), a_s), a_u, rtol=1e-6)
    # past the fold (x > 1/4) there is no pair of orbits
    assert np.isnan(unstable_amplitude_from(0.3, 1.0))


def test_needs_two_mu():
    f = _features([15.0], [15.0], lambda m: np.ones_like(m))
    with pytest.raises(ValueError, match="two or more distinct μ"):
        invariant_line(pair_invariants(f))


def test_plot_pair_invariant():
    f = _features([14.9, 15.7, 16.5], [14.9, 15.7, 16.5], lambda m: 0.02 + 0.01 * (m - 14.0), 1e-4)
    pairs = pair_invariants(f)
    rng = np.random.default_rng(0)
    fake_fit = SimpleNamespace(samples={"mu0": MU0 + 0.01 * rng.normal(size=200),
                                        "a2": A2 + 0.01 * rng.normal(size=200)})
    fig = plot_pair_invariant(pairs, fit=fake_fit)
    ax = fig.axes[0]
    lines = {}
    for ln in ax.lines:  # an errorbar's data line comes before its caps
        lines.setdefault(ln.get_gid(), ln)
    (line,) = [ln for ln in ax.lines if ln.get_gid() == "all-pairs-line"]
    mu, x = line.get_data()
    np.testing.assert_allclose(x, (MU0 - mu) / A2**2, atol=1e-4)
    fit_mu, fit_x = lines["fit-line"].get_data()
    np.testing.assert_allclose(fit_x, (MU0 - fit_mu) / A2**2, atol=2e-3)
    # one leave-one-pair-out line and prediction per pair, and the measured points
    for k, held in enumerate(pairs):
        rest = invariant_line([p for i, p in enumerate(pairs) if i != k])
        assert lines[f"predicted-{k}"].get_ydata()[0] == pytest.approx(
            np.median(rest.x_draws(held.mu)))
        assert f"without-{k}" in lines
    np.testing.assert_allclose(lines["measured"].get_ydata(), [p.x for p in pairs])
    assert isinstance(fig, Figure)
