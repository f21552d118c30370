"""Submodules of a subpackage reachable as its attributes, imported when first used.

``bh.simulators.truth`` then works after ``import bayeshopf as bh`` alone,
without importing every submodule (and JAX) with the package.
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable
from types import ModuleType


def submodule_getattr(package: str) -> Callable[[str], ModuleType]:
    """A module ``__getattr__`` for ``package`` that imports ``package.<name>`` on first use.

    Raises:
        AttributeError: For a name that is neither an attribute nor a submodule.
    """
    def __getattr__(name: str) -> ModuleType:
        if not name.startswith("_") and importlib.util.find_spec(f"{package}.{name}"):
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
