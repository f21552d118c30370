"""Independent items (chains, draws) spread over this process's devices.

With one CPU device, JAX's default, everything here is the identity. The CLI
asks for one host device per core
(:func:`~bayeshopf.inference.cache.configure_xla_cpu`'s ``host_devices``); the
items are then split between the devices along their leading axis
(``shard_map``), each device working through its share one item after
another, and the results come back in order, the same as on one device.
"""

from __future__ import annotations

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from bayeshopf.inference.cache import compile_ahead, compiled_call


def spread_devices(n: int) -> int:
    """How many of this process's devices ``n`` independent items (chains, draws) are spread over.

    The most devices that divide ``n``; 1 in a process with one CPU device,
    JAX's default. The CLI asks for one host device per core
    (:func:`~bayeshopf.inference.cache.configure_xla_cpu`'s ``host_devices``),
    so that its four chains run two by two on two cores.
    """
    n_dev = jax.local_device_count()
    return max(d for d in range(1, min(n_dev, n) + 1) if n % d == 0)


def spread(fn, n_dev: int):
    """``fn`` over a leading axis split into ``n_dev`` blocks, one per device (``shard_map``).

    ``fn`` must map a block of items to the outputs for those items, each with
    the items on its leading axis; the blocks' outputs are put back in order.
    With ``n_dev == 1`` this is ``fn``.
    """
    if n_dev == 1:
        return fn
    part = PartitionSpec("items")
    return jax.shard_map(fn, mesh=_mesh(n_dev), in_specs=part, out_specs=part, check_vma=False)


def _mesh(n_dev: int) -> Mesh:
    """The first ``n_dev`` local devices along one axis, ``"items"``."""
    return Mesh(np.array(jax.local_devices()[:n_dev]), ("items",))


def place(tree, n_dev: int):
    """``tree`` split over ``n_dev`` devices along its leading axes, as :func:`spread` takes it."""
    if n_dev == 1:
        return tree
    # from host memory: splitting arrays already on one device compiles a slicing
    # program per shape, beside the NUTS compilations with an empty cache
    return jax.device_put(jax.tree.map(np.asarray, tree), placement(n_dev))


def placement(n_dev: int) -> NamedSharding | None:
    """The sharding :func:`place` gives (``None``: one device, left where it is)."""
    return None if n_dev == 1 else NamedSharding(_mesh(n_dev), PartitionSpec("items"))


def mapped_call(name: str, one, items, key, ahead: bool = False):
    """``lax.map(one, items)``, compiled and stored, the items split over this process's devices.

    ``lax.map``, not ``vmap``: XLA's batched Cholesky and triangular solves are
    slow on CPU (and hung in some versions). With several CPU devices (the
    CLI's, :func:`spread_devices`) each device maps its share of the items; the
    results come back in order, the same as on one device.

    Args:
        name: The stored program's name (:func:`~bayeshopf.inference.cache.compiled_call`).
        one: Maps one item (a slice of ``items``' leaves) to its outputs.
        items: A pytree of arrays with the items on their leading axes
            (``jax.ShapeDtypeStruct`` with ``ahead``).
        key: Everything ``one`` closes over besides its input's shapes.
        ahead: Only start compiling the program for such items in the
            background (:func:`~bayeshopf.inference.cache.compile_ahead`); returns ``None``.
    """
    n_dev = spread_devices(jax.tree.leaves(items)[0].shape[0])

    def make():
        return spread(lambda it: jax.lax.map(one, it), n_dev)

    if ahead:
        where = placement(n_dev)
        compile_ahead(name, make, (jax.tree.map(
            lambda a: jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=where), items),),
            key=(key, n_dev))
        return None
    return compiled_call(name, make, (place(items, n_dev),), key=(key, n_dev))
