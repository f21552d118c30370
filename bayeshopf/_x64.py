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

    The first call also gives JAX its CPU settings
    (:func:`bayeshopf._xla.configure_xla_cpu`), which take effect only before
    JAX's first computation in the process: every computing function of
    bayeshopf calls this first, so user code need not. JAX is imported here,
    not with bayeshopf, so that a process that only draws figures does not
    import it.
    """
    if not _CONFIGURED:
        from bayeshopf._xla import configure_xla_cpu

        configure_xla_cpu()
        _CONFIGURED.append(True)
    import jax

    if not jax.config.jax_enable_x64:
        jax.config.update("jax_enable_x64", True)


#: Whether :func:`ensure_x64` has made JAX's CPU settings in this process.
_CONFIGURED: list[bool] = []
