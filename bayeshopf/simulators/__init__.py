r"""Simulated systems with a Hopf bifurcation, their periodic orbits, and recordings of them.

The ground truth for bayeshopf's fits: a :class:`System` is an ODE
:math:`\dot x = f(x, \mu; p)` with named, unit-carrying states, parameters and
observed channels. Built in are the paper's Van der Pol oscillator
(``"vanderpol"``, supercritical) and 3-DOF aeroelastic aerofoil
(``"flutter3dof"``, subcritical); :func:`get_system` also loads
``"package.module:attr"``. For a system the package finds

* the Hopf point from the Jacobian eigenvalues (:func:`find_hopf`),
* the periodic orbits born there, by shooting and pseudo-arclength continuation
  round the folds, with Floquet multipliers (:func:`continue_from_hopf`,
  :func:`bifurcation_diagram`, :func:`orbit_at`),
* and recordings of stable and unstable LCOs as an experiment with
  control-based continuation gives them (:func:`simulate_recordings`; the
  command ``bayeshopf simulate``).

Example::

    from bayeshopf.simulators import bifurcation_diagram, get_system, simulate_recordings

    flutter = get_system("flutter3dof")
    diagram = bifurcation_diagram(flutter)         # Hopf point, fold, branches
    orbit = diagram.orbit_at(16.5, "unstable")      # PeriodicOrbit: period, amplitude, floquet
    rs = simulate_recordings(flutter, mu=[15.5, 16.5], branch=["stable", "unstable"])
"""

from __future__ import annotations

from bayeshopf._lazy import submodule_getattr
from bayeshopf.simulators.arclength import BifurcationDiagram as BifurcationDiagram
from bayeshopf.simulators.arclength import Branch as Branch
from bayeshopf.simulators.arclength import Fold as Fold
from bayeshopf.simulators.arclength import continue_from_hopf as continue_from_hopf
from bayeshopf.simulators.arclength import orbit_at as orbit_at
from bayeshopf.simulators.base import ExtraForce as ExtraForce
from bayeshopf.simulators.base import Rhs as Rhs
from bayeshopf.simulators.base import SimulationError as SimulationError
from bayeshopf.simulators.base import System as System
from bayeshopf.simulators.base import UncertainParameter as UncertainParameter
from bayeshopf.simulators.continuation import bifurcation_diagram as bifurcation_diagram
from bayeshopf.simulators.equilibria import HopfPoint as HopfPoint
from bayeshopf.simulators.equilibria import eigenvalues as eigenvalues
from bayeshopf.simulators.equilibria import equilibrium as equilibrium
from bayeshopf.simulators.equilibria import find_hopf as find_hopf
from bayeshopf.simulators.equilibria import jacobian as jacobian
from bayeshopf.simulators.flutter import FLUTTER3DOF as FLUTTER3DOF
from bayeshopf.simulators.periodic import PeriodicOrbit as PeriodicOrbit
from bayeshopf.simulators.periodic import periodic_orbit as periodic_orbit
from bayeshopf.simulators.periodic import sample_orbit as sample_orbit
from bayeshopf.simulators.recordings import simulate_recordings as simulate_recordings
from bayeshopf.simulators.recordings import simulation_info as simulation_info
from bayeshopf.simulators.recordings import write_simulation as write_simulation
from bayeshopf.simulators.registry import available_systems as available_systems
from bayeshopf.simulators.registry import get_system as get_system
from bayeshopf.simulators.registry import register_system as register_system
from bayeshopf.simulators.vanderpol import VANDERPOL as VANDERPOL

__getattr__ = submodule_getattr(__name__)
