"""The collapsed core end to end on planted systems (small problems; statistics in benchmarks)."""

from dataclasses import replace

import numpy as np
import pytest

from bayeshopf.data.recording import RecordingSet
from bayeshopf.data.synthetic import demo_system
from bayeshopf.inference.collapsed import CollapsedSettings
from bayeshopf.posterior import fit_hybrid

SETTINGS = replace(CollapsedSettings.fast(), num_chains=2)


@pytest.fixture(scope="module")
def planted():
    rs, truth = demo_system(seed=11, fast=True)
    return fit_hybrid(rs, "subcritical", seed=0, settings=SETTINGS, progress=False), rs, truth


def test_planted_hopf_and_fold_inside_their_intervals(planted):
    post, _, truth = planted
    assert post.interval("mu0").contains(truth.mu0)
    assert post.interval("mu_fold").contains(truth.mu_fold)
    # the data pin μ0 to a fraction of the span of the recordings (4.2)
    assert post.interval("mu0").width < 0.5


def test_planted_orbits_fitted_and_diagnostics_reported(planted):
    post, rs, truth = planted
    d = post.diagnostics
    assert d["map"]["converged"] and d["map"]["grad_norm"] < 1e-4
    assert set(d["posterior"]["sites"]) >= {"mu0", "a2", "mu_fold"}
    for e in d["fit"]["orbit_error"]:
        assert e["relative"] < 0.03, e
    # the posterior-median orbit against the planted orbit (not the noisy data)
    for rec in rs:
        pred = np.median(post.orbits(rec.mu, rec.branch), axis=0)
        true = truth.orbit(rec.mu, rec.branch, n_points=pred.shape[0])
        # phases differ: compare as point clouds (distance to the nearest true point)
        dist = np.min(np.linalg.norm(pred[:, None] - true[None], axis=-1), axis=1)
        size = np.sqrt(np.mean(np.sum((true - true.mean(0)) ** 2, -1)))
        assert np.sqrt(np.mean(dist**2)) / size < 0.02


def test_planted_diagram_band_holds_the_true_branches(planted):
    post, _, truth = planted
    mu = np.linspace(15.4, 17.9, 12)
    for branch, band in (("stable", post.diagram(mu).stable),
                         ("unstable", post.diagram(mu).unstable)):
        true = truth.amplitude(mu, branch)
        lo, hi = band.quantiles[0], band.quantiles[4]
        assert np.all((lo <= true) & (true <= hi)), (branch, lo, true, hi)


def test_a_fit_that_does_not_fit_says_so():
    """Recordings whose μ labels are scrambled: the map cannot follow them, diagnostics warn."""
    rs, _ = demo_system(seed=12, fast=True)
    mus = [15.3, 19.5, 16.7, 18.1, 16.0, 17.4]       # stable sizes no longer grow with μ
    recs = tuple(replace(r, mu=m) if r.branch == "stable" else r
                 for r, m in zip(rs, mus, strict=False))
    bad = RecordingSet(recs, rs.planar, rs.mu_label, rs.mu_units)
    post = fit_hybrid(bad, "subcritical", seed=0, settings=SETTINGS, progress=False)
    assert any(w.startswith("fit:") for w in post.diagnostics["warnings"])
