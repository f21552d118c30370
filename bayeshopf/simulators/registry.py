"""Look systems up by name: the built-ins, or ``"package.module:attr"`` for your own."""

from __future__ import annotations

import importlib
import inspect

from bayeshopf.simulators.base import SimulationError, System
from bayeshopf.simulators.flutter import FLUTTER3DOF
from bayeshopf.simulators.vanderpol import VANDERPOL

__all__ = ["available_systems", "get_system", "register_system"]

_REGISTRY: dict[str, System] = {"vanderpol": VANDERPOL, "flutter3dof": FLUTTER3DOF}


def available_systems() -> tuple[str, ...]:
    """Names of the registered systems (built-ins first)."""
    return tuple(_REGISTRY)


def register_system(system: System, *, overwrite: bool = False) -> System:
    """Make ``system`` available to :func:`get_system` under ``system.name``.

    Raises:
        SimulationError: If the name is taken and ``overwrite`` is false.
    """
    if not isinstance(system, System):
        raise SimulationError(f"register_system expects a System; got {type(system).__name__}")
    if system.name in _REGISTRY and not overwrite:
        raise SimulationError(
            f"a system named {system.name!r} is already registered (pass overwrite=True)"
        )
    _REGISTRY[system.name] = system
    return system


def _load(spec: str) -> System:
    module_name, _, attr = spec.partition(":")
    if not module_name or not attr:
        raise SimulationError(f"system {spec!r}: 'package.module:attr' expected")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise SimulationError(
            f"system {spec!r}: module {module_name!r} cannot be imported ({exc})"
        ) from exc
    obj = module
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise SimulationError(
                f"system {spec!r}: {module_name} has no attribute {attr!r}"
            ) from None
    if not isinstance(obj, System) and callable(obj):
        try:
            inspect.signature(obj).bind()
        except TypeError:
            raise SimulationError(
                f"system {spec!r}: a System, or a function of no arguments returning one, "
                f"expected; found {getattr(obj, '__name__', type(obj).__name__)}, which takes "
                "arguments"
            ) from None
        except ValueError:  # no signature (some builtins): just try
            pass
        obj = obj()
    if not isinstance(obj, System):
        raise SimulationError(
            f"system {spec!r}: a bayeshopf.simulators.System (or a function returning one) "
            f"expected; found {type(obj).__name__}"
        )
    return obj


def get_system(name: str | System) -> System:
    """The system called ``name``.

    Args:
        name: ``"vanderpol"``, ``"flutter3dof"``, a name given to
            :func:`register_system`, or ``"package.module:attr"`` where ``attr``
            is a :class:`System` or a function of no arguments returning one.
            A :class:`System` is returned as is.

    Raises:
        SimulationError: If the name is unknown or the import fails (one line).
    """
    if isinstance(name, System):
        return name
    if not isinstance(name, str):
        raise SimulationError(f"system name expected as a string; got {type(name).__name__}")
    if name in _REGISTRY:
        return _REGISTRY[name]
    if ":" in name:
        return _load(name)
    raise SimulationError(
        f"unknown system {name!r}; expected one of {', '.join(_REGISTRY)} "
        "or 'package.module:attr' for your own"
    )
