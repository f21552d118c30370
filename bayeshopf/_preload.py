"""Imports needed after the sampler, done beside it; a process that draws figures.

ArviZ (R̂ and ESS, ``posterior.nc``) and Matplotlib with the plotting code (the
CLI's figures) take seconds of Python to import, and are needed only once the
draws exist. NUTS's compiled loops do not hold the
interpreter, so :func:`start`, called by the sampler once its first compiled
chunk is dispatched, imports them beside it. Not sooner: beside a Python loop
that calls small compiled programs (the Laplace covariance's gradients) the
import thread holds the interpreter for up to the switch interval at each of the
loop's calls, which slows the loop several times over.
A module wanted sooner is imported by whichever thread asks first: Python's
import lock makes the other wait for it.
"""

from __future__ import annotations

import importlib
import multiprocessing
import os
import threading
from concurrent.futures import Executor, ProcessPoolExecutor

#: Modules :func:`start` imports; ArviZ always (R̂ and ESS follow the draws).
_WANTED: list[str] = ["bayeshopf.diagnostics.arviz_io"]


def request(*modules: str) -> None:
    """Ask for ``modules`` to be imported at the next :func:`start`."""
    _WANTED.extend(m for m in modules if m not in _WANTED)


def _work(modules: list[str]) -> None:
    try:
        for name in modules:
            mod = importlib.import_module(name)
            if name == "bayeshopf.diagnostics.arviz_io":
                mod.arviz()
    except Exception:  # noqa: BLE001 - the caller's own import reports it, in one line
        pass


def start() -> threading.Thread:
    """Import the requested modules in a daemon thread; returns the thread."""
    t = threading.Thread(target=_work, args=(list(_WANTED),), name="bayeshopf-preload",
                         daemon=True)
    t.start()
    return t


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def _import(name: str) -> None:
    importlib.import_module(name)


def figure_worker() -> Executor:
    """A one-process pool for :func:`~bayeshopf.plotting.plot_all`'s ``executor``, starting now.

    A fresh interpreter (``spawn``: nothing of the caller's JAX threads is
    copied) that imports :mod:`bayeshopf.plotting`, and Matplotlib with it, at
    once, so that the import happens on the other core while the caller fits.
    Shut it down after use (``with figure_worker() as ex:``).
    """
    ex = ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn"))
    ex.submit(_import, "bayeshopf.plotting")
    return ex
