"""JAX's persistent compilation cache, so repeated fits reuse compiled code."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from bayeshopf._atomic import replacing
from bayeshopf._xla import (  # noqa: F401 (re-exported)
    BLAS_THREADS,
    CLASSIC_FUSION,
    HOST_DEVICES,
    SINGLE_THREAD_EIGEN,
    configure_xla_cpu,
)

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


#: Functions that forget a layer's in-memory compiled programs (:func:`on_release`).
_RELEASERS: list[Callable[[], None]] = []


def on_release(forget: Callable[[], None]) -> Callable[[], None]:
    """Register ``forget`` to run at each :func:`release_compiled` (usable as a decorator).

    The layers that keep compiled programs of their own (the model's per-spec
    jits, the inference's model functions) register here, so that this module
    needs none of them.
    """
    if forget not in _RELEASERS:
        _RELEASERS.append(forget)
    return forget


def release_compiled() -> None:
    """Drop every in-memory compiled program (bayeshopf's registered ones and JAX's caches).

    Each fit compiles its own closures (the potential, the SVI step, the
    predictions of its :class:`~bayeshopf.model.collapsed.CollapsedSpec`), and JAX
    keeps the compiled code mapped in memory. A process that fits many data
    sets (leave-one-out, calibration over seeds) would otherwise exhaust the
    kernel's limit on memory mappings (``vm.max_map_count``), and LLVM fails
    with "Cannot allocate memory". :func:`~bayeshopf.posterior.fit_hybrid`
    calls this first; nothing compiled for an earlier fit is reused by a later
    one, and the persistent cache on disk is kept, so a repeated fit still
    loads its programs instead of compiling.
    """
    for forget in _RELEASERS:
        forget()
    _COMPILED.clear()
    jax.clear_caches()


#: Prefix of the files :func:`compiled_call` keeps in the compilation cache folder.
STORED_PREFIX = "bayeshopf-exported-"


def _source_digest() -> bytes:
    """SHA-256 of bayeshopf's sources, the versions it traces with and XLA's flags."""
    if _SOURCE_DIGEST:
        return _SOURCE_DIGEST[0]
    from importlib.metadata import PackageNotFoundError, version

    h = hashlib.sha256()
    root = Path(__file__).resolve().parents[1]
    for p in sorted(root.rglob("*.py")):
        h.update(str(p.relative_to(root)).encode())
        h.update(p.read_bytes())
    for dist in ("jax", "jaxlib", "numpyro", "optax"):
        try:
            h.update(f"{dist}={version(dist)}".encode())
        except PackageNotFoundError:
            h.update(dist.encode())
    h.update(os.environ.get("XLA_FLAGS", "").encode())
    h.update(f"x64={jax.config.jax_enable_x64}".encode())
    _SOURCE_DIGEST.append(h.digest())
    return _SOURCE_DIGEST[0]


_SOURCE_DIGEST: list[bytes] = []


def _digest(name: str, key, args) -> str:
    """Hex SHA-256 of the sources, ``name``, ``key``'s values and the arguments' shapes."""
    h = hashlib.sha256(_source_digest())
    h.update(name.encode())
    for leaf in jax.tree_util.tree_leaves(key):
        if isinstance(leaf, str | int | float | bool | bytes):
            h.update(repr(leaf).encode())
        else:
            a = np.asarray(leaf)
            h.update(f"{a.dtype}{a.shape}".encode())
            h.update(np.ascontiguousarray(a).tobytes())
    for leaf in jax.tree_util.tree_leaves(args):   # the program takes any values of these
        h.update(f"{np.dtype(_dtype(leaf))}{tuple(np.shape(leaf))}".encode())
    h.update(str(jax.tree_util.tree_structure((key, args))).encode())
    return h.hexdigest()[:40]


def _dtype(leaf):
    """The dtype of an array, a Python number or a ``jax.ShapeDtypeStruct``."""
    return leaf.dtype if hasattr(leaf, "dtype") else np.result_type(leaf)


def compiled_call(name: str, make: Callable[[], Callable], args: tuple, key) -> object:
    """``jax.jit(make())(*args)``, through a stored :mod:`jax.export` artifact.

    JAX's persistent cache skips XLA's compilation of a program it has seen,
    but not the tracing of the Python function and its lowering to StableHLO:
    for the MAP and NUTS programs that is most of a warm fit's time. The first
    call with a given ``key`` exports the jitted function
    (:func:`jax.export.export`) and stores its serialization in the
    compilation cache folder; later calls deserialize it and run it, so
    ``make`` is not even called and only the (cached) compilation remains.

    The file name is a SHA-256 of ``name``, ``key`` (everything the traced
    function closes over: data, settings), the arguments' shapes, bayeshopf's
    own source files, the versions of jax, jaxlib, numpyro and optax, and
    ``XLA_FLAGS``; a change to any of them makes a new file, and a file that
    does not load is replaced. Without the persistent cache
    (``enable_compilation_cache`` not called, or ``BAYESHOPF_CACHE_DIR=off``)
    this is ``jax.jit(make())(*args)``.

    Args:
        name: Names the program in the file name.
        make: Builds the function to compile (called only when nothing is stored).
        args: Its arguments (arrays).
        key: A pytree of arrays, strings and numbers: every value the function
            closes over.
    """
    return compiled_function(name, make, args, key)(*args)


def compiled_function(name: str, make: Callable[[], Callable], args: tuple, key) -> Callable:
    """The jitted function :func:`compiled_call` would run, to call more than once.

    The same stored artifact and file name as :func:`compiled_call`; ``args``
    only gives the shapes the function is compiled for. Calls with arguments
    of those shapes run the compiled program without tracing, lowering or
    loading anything again (a loop of calls, such as NUTS's chains advanced in
    stages), and so does a later request for the same name and key in this
    process, until :func:`release_compiled`.
    """
    digest = _digest(name, key, args)
    if (name, digest) not in _COMPILED:
        _COMPILED[name, digest] = _load_or_export(name, digest, make, args)
    return _COMPILED[name, digest]


def compile_ahead(name: str, make: Callable[[], Callable], args: tuple, key) -> Callable | None:
    """Start compiling what :func:`compiled_function` would return, in a background thread.

    With an empty cache most of a fit is XLA compiling its programs one after
    another, on one core: the MAP's potential, then NUTS's start and its
    advance, each when it is first called. XLA's compiler does not hold
    Python's interpreter, so a program that will be needed later can compile
    on the other core while this thread goes on (the MAP, the other programs'
    tracing). Here the function is traced and exported (or loaded) in the
    calling thread (tracing runs NumPyro's handlers, whose stack is shared by
    every thread), and only its lowering and compilation run in a background
    thread. A later :func:`compiled_function` with the same name, key and
    argument shapes gets a callable that waits for that compilation and runs
    its result (arguments of other shapes make another program, as for
    :func:`compiled_function`; placed on other devices, they go through
    ``jax.jit``). Without the persistent cache this does nothing.

    Args:
        name: As :func:`compiled_call`.
        make: As :func:`compiled_call`.
        args: Arrays or ``jax.ShapeDtypeStruct`` (with the ``sharding`` the
            arguments will have, for a program over several devices).
        key: As :func:`compiled_call`.

    Returns:
        The jitted function (for ``jax.eval_shape``), or ``None`` without the
        persistent cache.
    """
    if not _ENABLED:
        return None
    digest = _digest(name, key, args)
    if (name, digest) not in _COMPILED:
        _COMPILED[name, digest] = _Ahead(_load_or_export(name, digest, make, args), args)
    fn = _COMPILED[name, digest]
    return fn.jitted if isinstance(fn, _Ahead) else fn


def stored_shapes(name: str, key, compute: Callable[[], dict]) -> dict:
    """Shapes and dtypes that take tracing to find, stored beside the programs.

    :func:`compile_ahead` needs the shapes of a program's arguments before the
    program exists, and finding them traces the model (NumPyro's
    ``initialize_model``, NUTS's ``init``): a noticeable part of a warm fit,
    which otherwise loads every program without tracing anything. ``compute``'s
    result is stored in the compilation cache folder under a SHA-256 of
    ``name``, ``key`` and the sources (as :func:`compiled_call`'s programs are)
    and read back by the next process.

    Args:
        name: Names the file.
        key: Everything the shapes depend on.
        compute: Returns a dict whose values are ``jax.ShapeDtypeStruct``, or
            lists or dicts of them (computed with ``jax.eval_shape``).

    Returns:
        ``compute()``, or the stored copy of it (without shardings).
    """
    folder = _ENABLED[0] if _ENABLED else None
    path = None if folder is None else (
        Path(folder) / f"{STORED_PREFIX}{name}-{_digest(name, key, ())}.json")
    if path is not None and path.is_file():
        with contextlib.suppress(Exception):    # damaged or foreign: computed again
            return {k: _from_json(v) for k, v in json.loads(path.read_text()).items()}
    shapes = compute()
    if path is not None:
        with contextlib.suppress(OSError), replacing(path) as tmp:
            tmp.write_text(json.dumps({k: _to_json(v) for k, v in shapes.items()}))
    return shapes


def _to_json(v):
    if isinstance(v, dict):
        return {"dict": {k: _to_json(x) for k, x in v.items()}}
    if isinstance(v, list | tuple):
        return {"list": [_to_json(x) for x in v]}
    return {"shape": list(v.shape), "dtype": np.dtype(v.dtype).name}


def _from_json(v):
    if "dict" in v:
        return {k: _from_json(x) for k, x in v["dict"].items()}
    if "list" in v:
        return [_from_json(x) for x in v["list"]]
    return jax.ShapeDtypeStruct(tuple(v["shape"]), np.dtype(v["dtype"]))


class _Ahead:
    """A jitted function whose compilation for ``args``' shapes runs in a background thread."""

    def __init__(self, jitted, args: tuple):
        self.jitted = jitted
        self.signature = _signature(args)
        self.future = _compiler().submit(lambda: jitted.lower(*args).compile())
        self.calls = [0, 0]      # calls that ran the program compiled ahead, and the others

    def __call__(self, *args):
        if _signature(args, like=self.signature) == self.signature:
            self.calls[0] += 1
            return self.future.result()(*args)
        self.calls[1] += 1
        return self.jitted(*args)


def _signature(args: tuple, like=None) -> tuple:
    """Tree structure, shapes, dtypes and (where ``like`` names one) shardings of ``args``."""
    leaves, tree = jax.tree_util.tree_flatten(args)
    want = like[1] if like is not None else [None] * len(leaves)
    if len(want) != len(leaves):
        return (tree, ())
    return (tree, tuple(
        (tuple(np.shape(x)), np.dtype(_dtype(x)),
         getattr(x, "sharding", None) if (like is None or w[2] is not None) else None)
        for x, w in zip(leaves, want, strict=True)))


_POOL: list = []


def _compiler():
    """The background thread of :func:`compile_ahead` (one: the process's other core)."""
    if not _POOL:
        from concurrent.futures import ThreadPoolExecutor

        _POOL.append(ThreadPoolExecutor(1, thread_name_prefix="bayeshopf-compile"))
    return _POOL[0]


#: The functions :func:`compiled_function` returned in this process, by name and digest.
_COMPILED: dict[tuple[str, str], Callable] = {}


def _load_or_export(name: str, digest: str, make: Callable[[], Callable], args) -> Callable:
    folder = _ENABLED[0] if _ENABLED else None
    if folder is None:
        return jax.jit(make())
    path = Path(folder) / f"{STORED_PREFIX}{name}-{digest}.bin"
    exp = None
    if path.is_file():
        try:
            exp = jax.export.deserialize(bytearray(path.read_bytes()))
        except Exception:  # noqa: BLE001 - a damaged or foreign file: export again
            exp = None
    if exp is None:
        exp = jax.export.export(jax.jit(make()))(*args)
        # a read-only cache: the call still works
        with contextlib.suppress(OSError), replacing(path) as tmp:
            tmp.write_bytes(exp.serialize())
    return jax.jit(exp.call)
