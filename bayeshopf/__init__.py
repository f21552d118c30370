"""bayeshopf: Bayesian hybrid normal-form models of Hopf bifurcations from LCO recordings.

The data flow one way: recordings -> phase-aligned harmonic features -> model
(normal form, map and frequency integrated out) -> inference (start, MAP, NUTS
or SVI) -> diagnostics and posterior predictive -> plots.

Importing bayeshopf leaves JAX's configuration alone; its computing functions
switch on JAX's float64 mode when they run (:func:`ensure_x64`).
"""

from bayeshopf._x64 import ensure_x64

__all__ = ["ensure_x64"]
__version__ = "0.1.0"
