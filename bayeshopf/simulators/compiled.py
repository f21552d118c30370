"""Periodic orbits' compiled programs, stored across processes where their code has a key.

JAX's persistent cache skips XLA's compilation of a program it has seen, but
not the tracing of the Python function and its lowering, which for a diffrax
solve with its variational equations takes about a second per program and
batch size, in every process. The periodic orbits' programs therefore go
through :func:`bayeshopf.inference.cache.compiled_function`: exported once with
:mod:`jax.export` and loaded by later processes, when the right-hand side's
code is pinned down by a key:

- a module-level function of bayeshopf (its source is part of every stored
  program's file name), or
- a closure registered with :func:`register` under a key of its own (the term
  library's system, :func:`bayeshopf.discrepancy.terms.library_system`).

Their users: the continuation's shots and samples
(:mod:`bayeshopf.simulators.periodic`, :mod:`bayeshopf.simulators.arclength`)
and the discrepancy analysis's batched programs
(:mod:`bayeshopf.discrepancy.orbits`). Any other right-hand side (a user's
simulator, a planted effect) is traced in every process, and so is every
program when the persistent cache is off or a program cannot be exported.
"""

from __future__ import annotations

import os
import weakref
from collections.abc import Callable, Hashable

from bayeshopf.inference.cache import compiled_function, on_release

__all__ = ["key_of", "program", "register"]

_KEYS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: The stored programs of this process, by key, name, shapes and settings (the
#: code with a key is bayeshopf's, so there are few of them); dropped with the
#: others by :func:`bayeshopf.inference.cache.release_compiled`.
_PROGRAMS: dict[tuple, Callable] = {}


@on_release
def _forget() -> None:
    _PROGRAMS.clear()


def register(fn: Callable, key: tuple) -> None:
    """Declare that ``fn`` (a closure) computes what ``key`` (strings, numbers) says."""
    _KEYS[fn] = key


def key_of(fn: Callable | None) -> tuple | None:
    """The key of a right-hand side or force input, ``None`` where its code is not pinned down."""
    if fn is None:
        return None
    try:
        if fn in _KEYS:
            return _KEYS[fn]
    except TypeError:                   # not weakly referable
        return None
    module = getattr(fn, "__module__", "") or ""
    qualname = getattr(fn, "__qualname__", "<locals>")
    if module.startswith("bayeshopf.") and "<locals>" not in qualname:
        return (f"{module}:{qualname}",)
    return None


def program(rhs: Callable, name: str, make: Callable[[], Callable], args: tuple,
            settings: tuple[Hashable, ...]) -> Callable:
    """The compiled ``make()`` for ``args``' shapes, stored across processes where it can be.

    Args:
        rhs: The right-hand side the program integrates (its key decides).
        name: The program ("shoot", "sample", ...).
        make: Builds the function (jitted or not) of ``args``.
        args: Arrays (one shape per call site and batch size), the parameters last.
        settings: Everything else the function closes over (tolerances, static sizes).

    Returns:
        A callable of ``args``.
    """
    key = key_of(rhs)
    if key is None:
        return make()
    shapes = tuple(getattr(a, "shape", ()) for a in args[:-1])
    sig = (key, name, shapes, settings, tuple(args[-1]) if isinstance(args[-1], dict) else ())
    if sig not in _PROGRAMS:
        stored_key = (*key, name, *settings, os.environ.get("EQX_ON_ERROR", ""))
        try:
            _PROGRAMS[sig] = compiled_function(f"orbits-{name}", make, args, stored_key)
        except Exception:  # noqa: BLE001 - not exportable (e.g. a host callback): trace it
            _PROGRAMS[sig] = make()
    return _PROGRAMS[sig]
