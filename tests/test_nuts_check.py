"""NUTS chains from the MAP point against the SVI posterior and the planted values."""

from __future__ import annotations

import numpy as np
import pytest

from bayeshopf.data.synthetic import demo_system
from bayeshopf.inference.nuts import nuts_check
from bayeshopf.pipeline import FitSettings, fit


@pytest.fixture(scope="module")
def planted():
    return demo_system(seed=11, fast=True)


@pytest.fixture(scope="module")
def fitted(planted):
    rs, _ = planted
    return fit(rs, "subcritical", seed=0, settings=FitSettings.fast(), progress=False)


@pytest.fixture(scope="module")
def check(fitted):
    return nuts_check(fitted, num_chains=2, num_warmup=150, num_samples=150, seed=0)


def test_chains_hold_the_planted_normal_form(check, planted):
    """Each chain's 90% intervals of μ0, a2 and the fold hold the planted values."""
    _, truth = planted
    for name, value in (("mu0", truth.mu0), ("a2", truth.a2), ("mu_fold", truth.mu_fold)):
        for c, iv in enumerate(check.per_chain[name]):
            assert iv.lo - 0.02 <= value <= iv.hi + 0.02, f"chain {c} {name}: {iv} vs {value}"


def test_chains_agree_with_svi_where_the_data_identify_the_model(check, fitted):
    """On well-identified data the chains' μ0 lies inside SVI's band and vice versa."""
    svi = fitted.interval("mu0")
    pooled = check.pooled["mu0"]
    assert svi.lo < pooled.median < svi.hi, (svi, pooled)
    assert pooled.lo < svi.median < pooled.hi, (svi, pooled)
    lo, hi = check.spread("mu0")
    assert hi - lo < svi.width, (lo, hi, svi)


def test_report_has_rhat_per_latent_site_and_draws_per_chain(check):
    assert {"gap_fold", "gap_hopf", "sigma", "nn_scale", "nn_W0"} <= set(check.rhat)
    assert "mu0" not in check.rhat  # deterministic, not sampled
    assert check.samples["mu0"].shape == (2, 150)
    assert len(check.divergences) == 2
    assert check.mixed == (check.max_rhat < 1.05)
    assert np.isfinite(check.max_rhat)


def test_one_chain_is_refused(fitted):
    with pytest.raises(ValueError, match="at least 2"):
        nuts_check(fitted, num_chains=1)
