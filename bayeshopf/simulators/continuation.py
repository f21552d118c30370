r"""The periodic orbits born at a Hopf point: continued, or read where the package stores them.

The numerics are in :mod:`bayeshopf.simulators.arclength` (pseudo-arclength
continuation, :func:`continue_from_hopf`, :func:`orbit_at`); the results
shipped with the package in :mod:`bayeshopf.simulators.stored`.
:func:`bifurcation_diagram` joins the two: the stored diagram of a system where
it is current, else a fresh continuation, once per system object.
"""

from __future__ import annotations

import functools

from bayeshopf._x64 import ensure_x64
from bayeshopf.simulators.arclength import BifurcationDiagram as BifurcationDiagram
from bayeshopf.simulators.arclength import Branch as Branch
from bayeshopf.simulators.arclength import Fold as Fold
from bayeshopf.simulators.arclength import continue_from_hopf as continue_from_hopf
from bayeshopf.simulators.arclength import orbit_at as orbit_at
from bayeshopf.simulators.base import System
from bayeshopf.simulators.stored import stored_diagram

__all__ = ["BifurcationDiagram", "Branch", "Fold", "bifurcation_diagram", "continue_from_hopf",
           "orbit_at"]


@functools.lru_cache(maxsize=16)
def bifurcation_diagram(system: System) -> BifurcationDiagram:
    """:func:`continue_from_hopf` with default settings, cached per system object.

    Where the package stores a current diagram of ``system``
    (:func:`~bayeshopf.simulators.stored.stored_diagram`), that is returned, with
    the orbits stored along it: what :func:`continue_from_hopf` computes, to the
    rounding of two runs.
    """
    ensure_x64()
    return stored_diagram(system) or continue_from_hopf(system)
