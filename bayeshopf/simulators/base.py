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

**Uncertain parameters.** A system may declare which of its ``params`` a test
engineer does not know exactly (``uncertain``, a tuple of
:class:`UncertainParameter`), each with a prior centred on the nominal value
in ``params`` and a width relative to it. :mod:`bayeshopf.discrepancy`
calibrates them against recordings as nuisance parameters before it names a
missing term. Each prior is a map from a standard normal coordinate
:math:`z \sim \mathcal N(0, 1)` to the physical value :math:`\theta`
(:meth:`UncertainParameter.value`):

.. math::

    \text{lognormal:}\quad \theta = \theta_0\, e^{\sigma z},
        \quad \sigma = \sqrt{\log(1 + s^2)};
    \qquad
    \text{normal:}\quad \theta = \theta_0\,(1 + s z),

with the nominal value :math:`\theta_0` and the relative standard deviation
:math:`s` (``scale``): the log-normal prior has median :math:`\theta_0` and
coefficient of variation exactly :math:`s`, and keeps the sign of
:math:`\theta_0`; the normal prior has mean :math:`\theta_0` and standard
deviation :math:`s|\theta_0|`.
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

__all__ = ["PRIORS", "ExtraForce", "Rhs", "SimulationError", "System", "UncertainParameter"]

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


#: The prior families of an :class:`UncertainParameter`.
PRIORS: tuple[str, ...] = ("lognormal", "normal")


@dataclass(frozen=True)
class UncertainParameter:
    r"""One parameter of a :class:`System` that is known only to within a prior.

    The prior is centred on the system's nominal value :math:`\theta_0` (its
    entry in ``System.params``) and written through a standard normal
    coordinate :math:`z` (module docstring): :math:`\theta = \theta_0 e^{\sigma z}`,
    :math:`\sigma = \sqrt{\log(1+s^2)}` (``"lognormal"``) or
    :math:`\theta = \theta_0(1 + s z)` (``"normal"``).

    Attributes:
        name: The parameter's name in ``System.params``.
        prior: ``"lognormal"`` (positive quantities: stiffness, damping, a
            coefficient that must keep its sign) or ``"normal"``.
        scale: Relative standard deviation :math:`s` (0.1 for ±10%).
        description: Why this width (one sentence, for reports).
        tolerance: Relative error within which the simulator's value counts as
            right (0.01: ±1%): a calibration names the parameter off only when
            most of its posterior lies beyond it
            (:attr:`~bayeshopf.discrepancy.records.ParameterPosterior.off`).
            0: any shift the data resolve.

    Raises:
        SimulationError: If ``prior`` is not one of :data:`PRIORS`, ``scale``
            is not a finite number > 0, or ``tolerance`` not one in [0, 1).
    """

    name: str
    prior: str = "lognormal"
    scale: float = 0.1
    description: str = ""
    tolerance: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise SimulationError(f"UncertainParameter.name must be a parameter name; "
                                  f"got {self.name!r}")
        if self.prior not in PRIORS:
            raise SimulationError(f"UncertainParameter {self.name}: prior must be one of "
                                  f"{', '.join(PRIORS)}; got {self.prior!r}")
        scale = float(self.scale)
        if not (np.isfinite(scale) and scale > 0):
            raise SimulationError(f"UncertainParameter {self.name}: scale (relative standard "
                                  f"deviation) must be a finite number > 0; got {self.scale!r}")
        object.__setattr__(self, "scale", scale)
        tol = float(self.tolerance)
        if not (np.isfinite(tol) and 0.0 <= tol < 1.0):
            raise SimulationError(f"UncertainParameter {self.name}: tolerance (relative error "
                                  f"that counts as right) must be a number in [0, 1); got "
                                  f"{self.tolerance!r}")
        object.__setattr__(self, "tolerance", tol)

    @property
    def sigma(self) -> float:
        r"""Prior sd of :math:`\log\theta` (lognormal), :math:`\theta/\theta_0` (normal)."""
        return float(np.sqrt(np.log1p(self.scale**2))) if self.prior == "lognormal" \
            else self.scale

    def value(self, z, nominal: float):
        """The physical value at standard normal coordinate ``z`` (a float or numpy array)."""
        if self.prior == "lognormal":
            return nominal * np.exp(self.sigma * z)
        return nominal * (1.0 + self.scale * z)

    def coordinate(self, value, nominal: float):
        """The standard normal coordinate ``z`` of a physical value (inverse of :meth:`value`)."""
        if self.prior == "lognormal":
            return np.log(np.asarray(value, dtype=float) / nominal) / self.sigma
        return (np.asarray(value, dtype=float) / nominal - 1.0) / self.scale

    def check(self, system_name: str, params: Mapping[str, float]) -> None:
        """Check the declaration against a system's parameters.

        Raises:
            SimulationError: If the parameter is not among ``params``, or its
                nominal value cannot carry the prior (≤ 0 for a log-normal,
                0 or not finite for a relative width).
        """
        if self.name not in params:
            raise SimulationError(f"{system_name}: uncertain parameter {self.name!r} must be one "
                                  f"of params ({', '.join(params)}); it is not")
        v = float(params[self.name])
        if self.prior == "lognormal" and not (np.isfinite(v) and v > 0):
            raise SimulationError(f"{system_name}: uncertain parameter {self.name} has a "
                                  f"log-normal prior, so a nominal value > 0 is expected; "
                                  f"got {v!r} (use prior='normal' for a signed parameter)")
        if not (np.isfinite(v) and v != 0):
            raise SimulationError(f"{system_name}: uncertain parameter {self.name} has a width "
                                  f"relative to its nominal value, so a finite nonzero nominal "
                                  f"value is expected; got {v!r}")


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
        uncertain: The parameters known only to within a prior
            (:class:`UncertainParameter`, distinct names among ``params``);
            empty when every parameter is taken as exact.
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
    uncertain: tuple[UncertainParameter, ...] = ()

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
        if isinstance(self.uncertain, UncertainParameter):
            raise SimulationError(f"{self.name}: uncertain must be a tuple of "
                                  "UncertainParameter; got a single one (wrap it in a tuple)")
        unc = tuple(self.uncertain)
        bad = [u for u in unc if not isinstance(u, UncertainParameter)]
        if bad:
            raise SimulationError(f"{self.name}: uncertain must hold UncertainParameter "
                                  f"records; got {bad[0]!r}")
        names_u = [u.name for u in unc]
        dup = sorted({n for n in names_u if names_u.count(n) > 1})
        if dup:
            raise SimulationError(f"{self.name}: uncertain parameters must be distinct; "
                                  f"{', '.join(dup)} declared more than once")
        for u in unc:
            u.check(self.name, params)
        set_(self, "uncertain", unc)

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
