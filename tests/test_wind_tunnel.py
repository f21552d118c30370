"""The real wind-tunnel CBC recordings (../shared/data/flutter_cbc), fitted at default settings."""

from __future__ import annotations

from pathlib import Path

import pytest

from bayeshopf.data import load_recordings
from bayeshopf.pipeline import fit

CBC_DIR = (Path(__file__).parents[1] / ".." / "shared" / "data" / "flutter_cbc").resolve()


@pytest.fixture(scope="module")
def result():
    if not CBC_DIR.is_dir():
        pytest.skip(f"flutter CBC recordings not found at {CBC_DIR}")
    return fit(load_recordings(CBC_DIR), "subcritical", seed=0, progress=False)


def test_subcritical_diagram_contains_all_seven_amplitudes(result):
    ppc = result.ppc()
    assert ppc.measured.size == 7
    assert ppc.covered.all(), [(a, iv) for a, iv in zip(ppc.measured, ppc.predictive, strict=True)]


def test_hopf_and_fold_near_the_papers_estimates(result):
    """The paper reports μ0 = 17.67 m/s and a fold at 14.66 m/s (MAP-like point estimates)."""
    mu0, fold = result.interval("mu0"), result.interval("mu_fold")
    assert mu0.contains(17.67), mu0
    assert fold.contains(14.66), fold
    # every unstable recording lies between the fold and the Hopf point
    assert fold.hi <= 14.9 + 1e-9 and mu0.lo >= 16.5
