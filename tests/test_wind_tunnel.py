"""The real wind-tunnel CBC recordings (../shared/data/flutter_cbc), fitted as `bayeshopf fit` is.

One fit of the collapsed core at its default settings (seed 0): the call a user
makes. The bars are issue 19's: every amplitude and frequency inside its 90%
predictive band, every orbit within 5% (or twice its segment spread), and NUTS
converged. The criticality comparison (``fit_auto``) is checked in the slow
``test_wind_tunnel_validation``.
"""

from __future__ import annotations

import pytest

from bayeshopf.diagnostics.pair_invariant import invariant_line, pair_invariants

#: The recording the core does not fit to the bar (README, Limits).
UNFITTED = "CBC_unstable_v16_5.mat"


@pytest.fixture(scope="module")
def post(cbc_recordings):
    from bayeshopf.posterior import fit_hybrid

    return fit_hybrid(cbc_recordings, "subcritical", seed=0, progress=False)


def test_all_seven_amplitudes_and_frequencies_inside_their_bands(post):
    ppc = post.ppc()
    assert ppc.measured.size == 7
    assert ppc.covered.all(), [(a, iv) for a, iv in zip(ppc.measured, ppc.predictive, strict=True)]
    freq = post.diagnostics["fit"]["frequency"]
    assert len(freq) == 7 and all(e["inside_ci90"] for e in freq), freq


def test_nuts_converged_on_the_rig(post):
    d = post.diagnostics["posterior"]
    assert d["method"] == "nuts" and d["chains"] == 4
    for name in ("mu0", "a2", "mu_fold"):
        site = d["sites"][name]
        assert site["r_hat"] <= 1.01 and site["ess_bulk"] >= 400, (name, site)


def test_orbits_fitted_except_the_last_unstable_one(post):
    """Six of the seven posterior-median orbits meet the bar; UNFITTED is the strict xfail below."""
    errs = {e["name"]: e for e in post.diagnostics["fit"]["orbit_error"]}
    assert len(errs) == 7
    for name, e in errs.items():
        # the parts by harmonic (Parseval) add up to the error sampled over the orbit
        assert sum(p**2 for p in e["by_harmonic"]) == pytest.approx(e["relative"] ** 2, rel=1e-9)
        if name != UNFITTED:
            assert e["ok"], e
            assert e["relative"] < 0.05 or e["relative"] < 2 * e["spread"], e


def test_the_warning_says_where_the_unfitted_orbit_misses(post):
    """Most of the 16.5 m/s orbit's error is its fundamental (the heave–pitch phase,
    docs/validation.md), and the CLI's warning line says so."""
    e = next(e for e in post.diagnostics["fit"]["orbit_error"] if e["name"] == UNFITTED)
    parts = e["by_harmonic"]
    assert max(range(len(parts)), key=parts.__getitem__) == 1, parts
    line = next(w for w in post.diagnostics["warnings"] if UNFITTED in w and "orbit error" in w)
    assert f"the largest part in the fundamental, {100 * parts[1]:.1f}%" in line, line


@pytest.mark.xfail(strict=True, reason=(
    "issue 19: the unstable 16.5 m/s orbit, the smallest (19.5 mm) and next to the Hopf point, is "
    "missed by 7.8–8.0% of its size against a 2.7% segment spread (seed 0): the pitch–heave phase "
    "of its fundamental and its harmonics; the posterior prefers a model error to the curvature "
    "in μ of the map that this one orbit needs (docs/validation.md, README Limits)"))
def test_the_unstable_orbit_next_to_the_hopf_point_is_fitted(post):
    e = next(e for e in post.diagnostics["fit"]["orbit_error"] if e["name"] == UNFITTED)
    assert e["ok"], e


def test_unstable_recordings_lie_between_the_fold_and_the_hopf_point(post):
    mu0, fold = post.interval("mu0"), post.interval("mu_fold")
    assert fold.hi <= 14.9 and mu0.lo >= 16.5, (fold, mu0)


def test_map_free_pair_invariant_of_the_rig(post):
    """Three stable/unstable pairs give μ0 without any map, and two pairs mis-predict the third.

    The line through the pairs assumes the paper's linear unfolding; it puts μ0
    at 17.3–17.5 m/s and predicts the unstable 16.5 m/s orbit from the pairs at
    14.9 and 15.7 m/s too large (docs/validation.md, "Why the unstable 16.5 m/s orbit"). The
    fit's curved unfolding bends through all three pairs instead, so its μ0 lies
    below the line's (README, Limits): asserted here, so that a change of either
    shows.
    """
    pairs = pair_invariants(post.features)
    assert [round(p.mu, 1) for p in pairs] == [14.9, 15.7, 16.5]
    line = invariant_line(pairs).interval("mu0")
    assert 17.2 < line.lo < line.hi < 17.6, line
    assert post.interval("mu0").hi < line.lo
    held = pairs[2]
    pred = invariant_line(pairs[:2]).unstable_amplitude(held.mu, held.stable_amplitude)
    assert pred.lo > held.unstable_amplitude, (pred, held.unstable_amplitude)
