"""Fixtures shared between test modules (each expensive fit is made once per session)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest


def _pin_xdist_worker() -> None:
    """Pin each pytest-xdist worker (``-n auto``) to a core of its own, before any JAX work.

    Two JAX processes sharing cores slow each other far beyond their share (a fit
    of 22 s alone took 736 s beside another test process, README Limits); one
    core each runs both at full speed. The subprocesses a test starts (CLI,
    notebook kernels) inherit the worker's core.
    """
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    if not worker.startswith("gw") or not hasattr(os, "sched_setaffinity"):
        return
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) > 1:
        os.sched_setaffinity(0, {cpus[int(worker[2:]) % len(cpus)]})


_pin_xdist_worker()
# as the CLI runs (bayeshopf.cli.main): Equinox's run-time checks give NaN, which every
# solve here reads from its result code, so the orbits' programs hold no host callback
# and the persistent compilation cache can share them between the workers and the CLI
# processes the tests start
os.environ.setdefault("EQX_ON_ERROR", "nan")

from bayeshopf._x64 import ensure_x64  # noqa: E402  (after the pinning: it imports JAX)
from bayeshopf.inference.cache import configure_xla_cpu  # noqa: E402

configure_xla_cpu()   # before any JAX work (bayeshopf.inference.cache)
ensure_x64()   # tests of the low-level blocks (bayeshopf.model) compute in float64 too;
#                tests/test_x64.py checks, in a fresh process, that import leaves it off

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


@pytest.fixture(scope="session")
def fast_demo_fit():
    """The fast demo set fitted once per session (fast settings, seed 0): ``(fit, rs, truth)``.

    Shared by test_plotting (figures) and test_outputs (saved folder, ArviZ, xarray).
    """
    from bayeshopf.data.synthetic import demo_system
    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.posterior import fit_hybrid

    rs, truth = demo_system(seed=0, fast=True)
    fit = fit_hybrid(rs, "subcritical", seed=0, settings=CollapsedSettings.fast(),
                     progress=False)
    return fit, rs, truth


@pytest.fixture(scope="session")
def cbc_mirror(tmp_path_factory):
    """A local HTTP mirror of the authors' 7 files (a copy of ../shared), for download tests.

    Yields ``(base_url, requests)``: ``requests`` lists the paths served so far.
    Tests never use the network: the download is pointed at this server.
    """
    import functools
    import http.server
    import shutil
    import threading

    if not CBC_DIR.is_dir():
        pytest.skip(f"flutter CBC recordings not found at {CBC_DIR}")
    root = tmp_path_factory.mktemp("mirror")
    for f in CBC_DIR.glob("CBC_*.mat"):
        shutil.copy(f, root)
    served: list[str] = []

    class Handler(http.server.SimpleHTTPRequestHandler):
        def log_message(self, fmt, *args):   # quiet; remember what was fetched
            served.append(self.path)

    server = http.server.ThreadingHTTPServer(
        ("127.0.0.1", 0), functools.partial(Handler, directory=str(root)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}/", served
    server.shutdown()
    server.server_close()


@pytest.fixture
def user_without_shared(cbc_mirror, tmp_path, monkeypatch):
    """A user without ../shared: ``flutter_cbc(download=True)`` fetches from the local mirror.

    ``$BAYESHOPF_FLUTTER_CBC`` unset, ``$BAYESHOPF_FLUTTER_CBC_URL`` the mirror,
    ``$BAYESHOPF_DATA_DIR`` a fresh folder; any other URL is refused. Returns
    ``(base_url, requests, data_dir)``.
    """
    import pooch

    url, served = cbc_mirror

    def local_only(u, *args, **kwargs):
        assert u.startswith(url), f"tests must not download: {u}"
        return _RETRIEVE(u, *args, **kwargs)

    monkeypatch.setattr(pooch, "retrieve", local_only)
    monkeypatch.delenv("BAYESHOPF_FLUTTER_CBC", raising=False)
    monkeypatch.setenv("BAYESHOPF_FLUTTER_CBC_URL", url)
    monkeypatch.setenv("BAYESHOPF_DATA_DIR", str(tmp_path / "user-cache"))
    monkeypatch.setenv("NO_PROXY", "127.0.0.1,localhost")
    monkeypatch.setenv("no_proxy", "127.0.0.1,localhost")
    return url, served, tmp_path / "user-cache"


def _pooch_retrieve():
    import pooch

    return pooch.retrieve


_RETRIEVE = _pooch_retrieve()   # the real one, before any test replaces it
