r"""The interface of a simulated dynamical system with a Hopf bifurcation.

A :class:`System` is an immutable record that holds everything the simulators
need to know about an autonomous ODE

.. math::  \dot x = f(x, \mu; p), \qquad x \in \mathbb{R}^n,

with a scalar bifurcation parameter :math:`\mu` and physical parameters
:math:`p`: the names and units of the states, of :math:`\mu` and of :math:`p`,
which states a sensor observes, and the right-hand side ``rhs(x, mu, params)``
as a pure JAX function (it is differentiated with :func:`jax.jacfwd` and
compiled with :func:`jax.jit`, so it must use ``jax.numpy`` and must not branch
in Python on ``x`` or ``mu``).

To simulate your own system, build a :class:`System` in a module of yours and
pass ``"package.module:attr"`` to :func:`bayeshopf.simulators.get_system` or to
``bayeshopf simulate`` (``attr`` may be the record or a function of no
arguments returning it)::

    import jax.numpy as jnp
    from bayeshopf.simulators import System

    def rhs(x, mu, p):
        return jnp.array([x[1], 2 * mu * x[1] - p["c"] * x[0] ** 2 * x[1] - x[0]])

    my_system = System(
        name="my_vdp", state_names=("z1", "z2"), state_units=("", ""),
        parameter="mu", parameter_units="", params={"c": 1.0}, rhs=rhs,
        observed=("z1", "z2"), mu_range=(-0.5, 1.0),
        default_plan=((0.5, "stable"),),
    )

**Extra forces.** Mechanical systems declare their generalised coordinates
(``coordinates``) and ``force_input(x, mu, params)``, the matrix :math:`B` of
shape ``(n_states, n_coordinates)`` through which an additive generalised force
:math:`F` enters the state equation, :math:`\dot x = f(x, \mu; p) + B F`. For
:math:`M\ddot q + D\dot q + Kq + N(q) = F` in the states :math:`(q, \dot q)`,
:math:`B` puts :math:`M^{-1}F` in the velocity rows. :meth:`System.with_extra_force`
returns a new system with a term such as a cubic stiffness or a friction force
added, which is how missing-physics terms are planted in a simulated truth.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import jax.numpy as jnp
import numpy as np

from bayeshopf._x64 import ensure_x64
from bayeshopf.errors import BayesHopfError

__all__ = ["ExtraForce", "Rhs", "SimulationError", "System"]

#: ``rhs(x, mu, params) -> dx``: states of shape ``(n,)``, scalar μ, parameter dict.
Rhs = Callable[[Any, Any, Mapping[str, Any]], Any]
#: ``force(x, mu, params) -> F``: generalised force of shape ``(n_coordinates,)``.
ExtraForce = Callable[[Any, Any, Mapping[str, Any]], Any]


class SimulationError(BayesHopfError, ValueError):
    """A system, branch or simulation setting is not what the simulators accept.

    The CLI reports it as one line. Example: ``"unstable branch of flutter3dof:
    no LCO at U = 19 m/s; it exists for 14.94 <= U <= 18.27 m/s"``.
    """


def _tuple_of_str(name: str, value) -> tuple[str, ...]:
    if isinstance(value, str):
        raise SimulationError(f"{name} must be a sequence of names; got the string {value!r}")
    out = tuple(value)
    if not all(isinstance(v, str) for v in out):
        raise SimulationError(f"{name} must hold strings; got {out!r}")
    return out


@dataclass(frozen=True, eq=False)
class System:
    r"""An autonomous ODE :math:`\dot x = f(x, \mu; p)` with a Hopf bifurcation in μ.

    Instances compare and hash by identity, so compiled solvers can be cached
    per system.

    **Main attributes**

    Attributes:
        name: Short name (``"flutter3dof"``).
        state_names: Names of the ``n`` states, in the order of ``x``.
        state_units: Unit of each state (``""`` for dimensionless).
        parameter: Symbol of the bifurcation parameter μ (``"U"``).
        parameter_units: Unit of μ (``"m/s"``).
        params: Physical parameters :math:`p` by name (floats; read-only).
        rhs: ``rhs(x, mu, params) -> dx``, a pure JAX function.
        observed: The states a sensor records; only these are written to
            recordings.
        mu_range: ``(lo, hi)``: where to look for the Hopf point and how far to
            continue the periodic orbits.

    **Other attributes**

    Attributes:
        param_units: Unit of each parameter.
        planar: The planar pair (z1, z2) among ``observed``; defaults to the
            first two observed states.
        parameter_label: Name of μ for plots and manifests (``"airspeed"``).
        default_plan: ``((mu, branch), ...)`` recorded when none is given.
        coordinates: Generalised coordinates on which extra forces act.
        force_input: ``force_input(x, mu, params) -> B`` of shape
            ``(n, len(coordinates))``; ``None`` if extra forces are not supported.
        description: One paragraph on the model and its source.
    """

    name: str
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    parameter: str
    parameter_units: str
    params: Mapping[str, float]
    rhs: Rhs
    observed: tuple[str, ...]
    mu_range: tuple[float, float]
    param_units: Mapping[str, str] = field(default_factory=dict)
    planar: tuple[str, str] | None = None
    parameter_label: str = ""
    default_plan: tuple[tuple[float, str], ...] = ()
    coordinates: tuple[str, ...] = ()
    force_input: Callable[[Any, Any, Mapping[str, Any]], Any] | None = None
    description: str = ""

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        names = _tuple_of_str("state_names", self.state_names)
        units = _tuple_of_str("state_units", self.state_units)
        if len(units) != len(names) or len(set(names)) != len(names):
            raise SimulationError(
                f"{self.name}: state_names must be distinct and state_units one per state; "
                f"got {len(names)} names {names} and {len(units)} units"
            )
        observed = _tuple_of_str("observed", self.observed)
        unknown = [c for c in observed if c not in names]
        if not observed or unknown:
            raise SimulationError(
                f"{self.name}: observed must name states among {', '.join(names)}; "
                f"got {observed!r}"
            )
        planar = tuple(self.planar) if self.planar is not None else observed[:2]
        if len(planar) != 2 or planar[0] == planar[1] or not set(planar) <= set(observed):
            raise SimulationError(
                f"{self.name}: planar must be two distinct observed states; got {planar!r}"
            )
        lo, hi = (float(v) for v in self.mu_range)
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise SimulationError(
                f"{self.name}: mu_range must be (lo, hi) with lo < hi; got {self.mu_range!r}"
            )
        if not callable(self.rhs):
            raise SimulationError(f"{self.name}: rhs must be callable; got {self.rhs!r}")
        params = {str(k): float(v) for k, v in dict(self.params).items()}
        plan = tuple((float(m), str(b)) for m, b in self.default_plan)
        set_(self, "state_names", names)
        set_(self, "state_units", units)
        set_(self, "observed", observed)
        set_(self, "planar", planar)
        set_(self, "mu_range", (lo, hi))
        set_(self, "params", MappingProxyType(params))
        set_(self, "param_units", MappingProxyType({str(k): str(v) for k, v in
                                                   dict(self.param_units).items()}))
        set_(self, "coordinates", _tuple_of_str("coordinates", self.coordinates))
        set_(self, "default_plan", plan)
        set_(self, "parameter_label", self.parameter_label or self.parameter)

    # ------------------------------------------------------------------ helpers

    @property
    def n_states(self) -> int:
        """Number of states ``n``."""
        return len(self.state_names)

    @property
    def observed_index(self) -> tuple[int, ...]:
        """Positions of the observed states in ``x``."""
        return tuple(self.state_names.index(c) for c in self.observed)

    @property
    def observed_units(self) -> dict[str, str]:
        """Observed state name -> unit."""
        return {c: self.state_units[self.state_names.index(c)] for c in self.observed}

    def param_tree(self, params: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """The parameters as a dict of float64 JAX scalars (a pytree for ``rhs``).

        Args:
            params: Values overriding ``self.params`` (unknown names are refused).

        Raises:
            SimulationError: If ``params`` names a parameter the system lacks.
        """
        base = dict(self.params)
        if params:
            unknown = sorted(set(params) - set(base))
            if unknown:
                raise SimulationError(
                    f"{self.name}: unknown parameter(s) {', '.join(unknown)}; "
                    f"expected some of {', '.join(base)}"
                )
            base.update(params)
        ensure_x64()
        return {k: jnp.asarray(v, dtype=jnp.float64) for k, v in base.items()}

    def vector_field(self, x, mu, params: Mapping[str, Any] | None = None):
        """``rhs(x, mu, params)`` with the system's own parameters by default."""
        ensure_x64()
        p = self.param_tree() if params is None else params
        return self.rhs(jnp.asarray(x, dtype=jnp.float64), jnp.asarray(mu, dtype=jnp.float64), p)

    def replace(self, **changes) -> System:
        """A copy with some fields changed (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)

    def with_params(self, **values: float) -> System:
        """A copy with some physical parameters changed."""
        unknown = sorted(set(values) - set(self.params))
        if unknown:
            raise SimulationError(
                f"{self.name}: unknown parameter(s) {', '.join(unknown)}; "
                f"expected some of {', '.join(self.params)}"
            )
        return self.replace(params={**self.params, **values})

    def with_extra_force(self, force: ExtraForce, *, name: str | None = None,
                         params: Mapping[str, float] | None = None,
                         param_units: Mapping[str, str] | None = None) -> System:
        r"""A copy whose right-hand side has an additive generalised force.

        The new system integrates :math:`\dot x = f(x, \mu; p) + B(x, \mu; p)\,F(x, \mu; p)`
        with :math:`B` = ``force_input`` and :math:`F` = ``force``; for a
        mechanical system :math:`M\ddot q + D\dot q + Kq + N = F`. Forces add up
        when this is called more than once.

        Args:
            force: ``force(x, mu, params) -> F`` of shape ``(len(coordinates),)``,
                a pure JAX function (e.g. ``-k3 * alpha**3`` on the pitch
                coordinate for an extra cubic stiffness).
            name: Name of the new system (default ``"<name>+force"``).
            params: Parameters the force uses, added to ``params``.
            param_units: Their units.

        Raises:
            SimulationError: If the system declares no ``force_input``.
        """
        if self.force_input is None or not self.coordinates:
            raise SimulationError(
                f"{self.name}: extra forces need `coordinates` and `force_input`; "
                "this system declares none"
            )
        base, B = self.rhs, self.force_input

        def rhs(x, mu, p):
            return base(x, mu, p) + B(x, mu, p) @ force(x, mu, p)

        return self.replace(
            name=name or f"{self.name}+force",
            rhs=rhs,
            params={**self.params, **dict(params or {})},
            param_units={**self.param_units, **dict(param_units or {})},
        )

    def describe(self) -> dict[str, Any]:
        """JSON-serialisable description (no functions)."""
        return {
            "name": self.name,
            "states": dict(zip(self.state_names, self.state_units, strict=True)),
            "parameter": self.parameter,
            "parameter_units": self.parameter_units,
            "parameter_label": self.parameter_label,
            "params": dict(self.params),
            "param_units": dict(self.param_units),
            "observed": self.observed_units,
            "planar": list(self.planar),
            "description": self.description,
        }
