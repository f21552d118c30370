"""JAX's persistent compilation cache, so repeated fits reuse compiled code."""

from __future__ import annotations

import os
from pathlib import Path

import jax

_ENABLED: list[str] = []


def default_cache_dir() -> Path:
    """``$BAYESHOPF_CACHE_DIR``, else ``$XDG_CACHE_HOME/bayeshopf/jax`` (``~/.cache``)."""
    env = os.environ.get("BAYESHOPF_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "bayeshopf" / "jax"


def enable_compilation_cache(path: str | os.PathLike[str] | None = None) -> Path | None:
    """Turn on JAX's persistent compilation cache for every compiled program.

    Every compilation is cached, the small op-by-op ones NumPyro triggers at
    initialisation included (minimum compile time and entry size set to zero),
    so a second fit of the same shapes starts without compiling. Set
    ``BAYESHOPF_CACHE_DIR=off`` to disable.

    Returns:
        The cache folder, or ``None`` when disabled or not writable.
    """
    target = Path(path) if path is not None else default_cache_dir()
    if str(target) == "off":
        return None
    if _ENABLED:
        return Path(_ENABLED[0])
    try:
        target.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", str(target))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    _ENABLED.append(str(target))
    return target


def release_compiled() -> None:
    """Drop every in-memory compiled program (bayeshopf's per-spec jits and JAX's caches).

    Each fit compiles its own closures (the potential, the SVI step, the
    predictions of its :class:`~bayeshopf.model.hybrid.ModelSpec`), and JAX
    keeps the compiled code mapped in memory. A process that fits many data
    sets (leave-one-out, calibration over seeds) then exhausts the kernel's
    limit on memory mappings (``vm.max_map_count``, 65530 by default): LLVM
    fails with "Cannot allocate memory" (the 3-DOF calibration crashed at its
    14th fit of 4 starts, with 23 GB of memory free).
    :func:`~bayeshopf.pipeline.fit` calls this first; nothing compiled for an
    earlier fit is reused by a later one, and the persistent cache on disk is
    kept, so a repeated fit still loads its programs instead of compiling.
    """
    from bayeshopf.model import hybrid

    hybrid.clear_spec_jits()
    jax.clear_caches()
