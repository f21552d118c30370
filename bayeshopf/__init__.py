"""bayeshopf: Bayesian hybrid normal-form models of Hopf bifurcations from LCO recordings.

>>> import bayeshopf as bh
>>> recordings = bh.read_recordings("my_rig/")          # doctest: +SKIP
>>> fit = bh.fit(recordings, seed=0)                    # doctest: +SKIP
>>> fit.predict([15.0, 16.0], branch="stable")          # doctest: +SKIP

The data flow one way: recordings -> phase-aligned harmonic features -> model
(normal form, map and frequency integrated out, model discrepancy) ->
inference (start, MAP, importance sampling, NUTS or SVI) -> posterior and predictive -> plots and
reports, with simulators, the missing-physics analysis and experimental design
beside it.

The names below are loaded when first used, so ``import bayeshopf`` stays
light and leaves JAX's configuration alone; the computing functions switch on
JAX's float64 mode when they run (:func:`ensure_x64`).
"""

from __future__ import annotations

import importlib

from bayeshopf._version import __version__
from bayeshopf._x64 import ensure_x64

#: Public name -> ``module:attribute`` (``module`` alone for a subpackage).
_EXPORTS = {
    "fit": "bayeshopf.hybrid:fit",
    "load_fit": "bayeshopf.hybrid:load_fit",
    "Fit": "bayeshopf.hybrid:Fit",
    "Settings": "bayeshopf.hybrid:Settings",
    "Diagnostics": "bayeshopf.diagnostics.checks:Diagnostics",
    "Check": "bayeshopf.diagnostics.checks:Check",
    "Status": "bayeshopf.diagnostics.checks:Status",
    "Interval": "bayeshopf.diagnostics.summaries:Interval",
    "read_recordings": "bayeshopf.data:read_recordings",
    "Recording": "bayeshopf.data.recording:Recording",
    "RecordingSet": "bayeshopf.data.recording:RecordingSet",
    "next_measurements": "bayeshopf.design:next_measurements",
    "simulate": "bayeshopf.simulators.recordings:simulate_recordings",
    "discrepancy": "bayeshopf.discrepancy",
}

__all__ = ["__version__", "ensure_x64", *_EXPORTS]


#: Subpackages and modules reachable as ``bh.<name>`` (imported when first used).
_MODULES = ("data", "features", "model", "inference", "posterior", "predictive", "fit_folder",
            "diagnostics", "plotting", "validation", "design", "simulators",
            "datasets")


def __getattr__(name: str):
    if name in _MODULES:
        value = importlib.import_module(f"bayeshopf.{name}")
        globals()[name] = value
        return value
    target = _EXPORTS.get(name)
    if target is None:
        raise AttributeError(f"module 'bayeshopf' has no attribute {name!r}")
    module, _, attr = target.partition(":")
    value = importlib.import_module(module)
    if attr:
        value = getattr(value, attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS) | set(_MODULES))
