"""bayeshopf: Bayesian hybrid normal-form models of Hopf bifurcations from LCO recordings.

The data flow one way: recordings -> phase-aligned harmonic features -> model
(normal form, map and frequency integrated out) -> inference (start, MAP, NUTS
or SVI) -> diagnostics and posterior predictive -> plots.
"""

import jax

jax.config.update("jax_enable_x64", True)

__version__ = "0.1.0"
