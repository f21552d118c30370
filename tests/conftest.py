"""Fixtures shared between test modules (each expensive fit is made once per session)."""

from __future__ import annotations

from pathlib import Path

import pytest

from bayeshopf.inference.cache import single_thread_eigen

single_thread_eigen()   # before any JAX work (bayeshopf.inference.cache)

CBC_DIR = (Path(__file__).parents[1] / ".." / "shared" / "data" / "flutter_cbc").resolve()


@pytest.fixture(scope="session")
def cbc_recordings():
    """The wind-tunnel CBC recordings (../shared/data/flutter_cbc), or a skip."""
    if not CBC_DIR.is_dir():
        pytest.skip(f"flutter CBC recordings not found at {CBC_DIR}")
    from bayeshopf.data import load_recordings

    return load_recordings(CBC_DIR)


@pytest.fixture(scope="session")
def cbc_auto(cbc_recordings):
    """``fit_auto`` on the rig at default settings, seed 0: ``(preferred fit, evidence)``.

    Both normal forms fitted once per session (PSIS-LOO, no exact refits):
    test_wind_tunnel_validation checks the criticality evidence.
    """
    from bayeshopf.posterior import fit_auto

    return fit_auto(cbc_recordings, seed=0, progress=False)
