"""JAX's 64-bit mode, switched on where bayeshopf computes, never at import.

The normal-form model, the ODE solves and the continuation of periodic orbits
need float64 (the fold, the Floquet multipliers and the Newton steps are lost
in float32). ``import bayeshopf`` leaves JAX's configuration alone; every public
function that computes with JAX calls :func:`ensure_x64` first, which turns
``jax_enable_x64`` on for the rest of the session (JAX has no per-call switch
that covers compiled and traced code alike). Call it yourself before using the
low-level building blocks (``bayeshopf.model``, the systems' right-hand sides)
directly.
"""

from __future__ import annotations

__all__ = ["ensure_x64"]


def ensure_x64() -> None:
    """Turn on JAX's float64 mode (``jax_enable_x64``) if it is off; otherwise do nothing.

    JAX is imported here, not with bayeshopf: the CLI's figure process imports
    the plotting code only, and JAX's import (1.1 s) would take that time from
    the fit beside it.
    """
    import jax

    if not jax.config.jax_enable_x64:
        jax.config.update("jax_enable_x64", True)
