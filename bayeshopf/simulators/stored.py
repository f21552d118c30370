r"""Continuation results shipped with the package, and the key that says they are current.

:func:`~bayeshopf.simulators.arclength.continue_from_hopf` and the orbits that
:func:`~bayeshopf.simulators.simulate_recordings` samples are deterministic
functions of an immutable :class:`~bayeshopf.simulators.System`. For the
systems of :data:`SHIPPED` (the ``flutter3dof`` system of ``bayeshopf demo``)
they are stored in ``bayeshopf/simulators/stored/`` (written by
:mod:`bayeshopf.simulators.ship`, ``python -m bayeshopf.simulators.ship``), and
:func:`stored_diagram` reads them back when everything they depend on is the
same:

- the file's **key**, a SHA-256 of the system's description (its parameters,
  states, observed channels), its μ range, the module and name of its
  right-hand side and force input, and the source files of :mod:`bayeshopf.simulators`: a
  change to any of them makes the stored file stale, and the result is
  computed as before (``tests/test_stored.py`` fails until the file is written
  again);
- a right-hand side (and force input, if any) defined at module level in
  :mod:`bayeshopf.simulators`: a closure, such as a planted effect's, is never
  looked up.

The arrays are those a continuation returned; they differ from a fresh one by
the rounding of two runs (at the ODE solver's tolerance).
:func:`~bayeshopf.simulators.bifurcation_diagram` is the reader's caller.
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path
from types import MappingProxyType

import numpy as np

from bayeshopf.simulators.arclength import BifurcationDiagram, Branch, Fold
from bayeshopf.simulators.base import System
from bayeshopf.simulators.compiled import key_of
from bayeshopf.simulators.equilibria import HopfPoint
from bayeshopf.simulators.periodic import PeriodicOrbit

__all__ = ["FOLDER", "SHIPPED", "orbit_name", "stored_diagram", "stored_path",
           "system_key"]

#: Folder of the stored files (inside the package).
FOLDER = Path(__file__).with_name("stored")
#: Systems whose results are shipped (their diagram, and the orbits
#: :mod:`bayeshopf.simulators.ship` solves along it).
SHIPPED = ("flutter3dof",)


@functools.lru_cache(maxsize=1)
def _sources_digest() -> bytes:
    h = hashlib.sha256()
    here = Path(__file__).parent
    for p in sorted(here.glob("*.py")):
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.digest()


def system_key(system: System) -> str | None:
    """The key of ``system``'s stored results, or ``None`` where nothing may be stored for it."""
    names = [_function_name(f) for f in (system.rhs, system.force_input) if f is not None]
    if None in names:
        return None
    h = hashlib.sha256(_sources_digest())
    h.update(json.dumps(system.describe(), sort_keys=True).encode())
    h.update(repr(tuple(float(v) for v in system.mu_range)).encode())
    h.update(" ".join(names).encode())
    return h.hexdigest()[:32]


def _function_name(f) -> str | None:
    """``module:name`` of a module-level function of bayeshopf.simulators, else ``None``."""
    key = key_of(f)
    if key is None or len(key) != 1 or not key[0].startswith("bayeshopf.simulators."):
        return None
    return key[0]


def stored_path(system: System, folder: Path = FOLDER) -> Path:
    """The file of ``system``'s stored results in ``folder``."""
    return folder / f"{system.name}.npz"


@functools.lru_cache(maxsize=8)
def _load(path: Path, mtime: float) -> dict | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError):
        return None


def _stored(system: System) -> dict | None:
    key = system_key(system)
    path = stored_path(system, FOLDER)
    if key is None or not path.is_file():
        return None
    data = _load(path, path.stat().st_mtime)
    if data is None or str(data["key"]) != key:
        return None
    return data


def _mapping(data: dict, prefix: str, names) -> MappingProxyType:
    return MappingProxyType({c: data[f"{prefix}{c}"] for c in names})


def orbit_name(branch: Branch, mu: float, n_points: int) -> str:
    """The stored name of an orbit: its branch (kind, a hash of the branch's μ), μ and samples."""
    return f"{_branch_prefix(branch.kind, branch.mu)}{float(mu).hex()}_{int(n_points)}"


def _branch_prefix(kind: str, mu: np.ndarray) -> str:
    path = hashlib.sha256(np.ascontiguousarray(mu, dtype=np.float64).tobytes())
    return f"orbit_{kind}_{path.hexdigest()[:12]}_"


def _orbit(d: dict, name: str, system: System) -> PeriodicOrbit:
    obs = system.observed
    return PeriodicOrbit(
        mu=float(d[f"{name}_mu"]), period=float(d[f"{name}_period"]), x0=d[f"{name}_x0"],
        states=d[f"{name}_states"], floquet=d[f"{name}_floquet"],
        stable=bool(d[f"{name}_stable"]), state_names=system.state_names,
        amplitude=MappingProxyType({c: float(d[f"{name}_amplitude_{c}"]) for c in obs}),
        mean=MappingProxyType({c: float(d[f"{name}_mean_{c}"]) for c in obs}))


def _solved(d: dict, i: int, system: System) -> dict[tuple[float, int], PeriodicOrbit]:
    """The stored orbits on branch ``i``, by ``(μ, n_points)`` (their names carry both)."""
    prefix = _branch_prefix(str(d[f"branch{i}_kind"]), d[f"branch{i}_mu"])
    out = {}
    for key in d:
        if key.startswith(prefix) and key.endswith("_states"):
            name = key[:-len("_states")]
            mu, n_points = name[len(prefix):].split("_")
            out[(float.fromhex(mu), int(n_points))] = _orbit(d, name, system)
    return out


def stored_diagram(system: System) -> BifurcationDiagram | None:
    """The stored :class:`~bayeshopf.simulators.BifurcationDiagram` of ``system``, or ``None``.

    Its branches carry the orbits stored along them (``Branch.solved``), which
    their ``orbit`` returns instead of solving again.
    """
    d = _stored(system)
    if d is None:
        return None
    hopf = HopfPoint(mu=float(d["hopf_mu"]), omega=float(d["hopf_omega"]),
                     equilibrium=d["hopf_equilibrium"], eigenvector=d["hopf_eigenvector"],
                     crossing_speed=float(d["hopf_crossing_speed"]))
    obs = system.observed
    folds = tuple(
        Fold(mu=float(d[f"fold{i}_mu"]), period=float(d[f"fold{i}_period"]),
             x0=d[f"fold{i}_x0"],
             amplitude=MappingProxyType({c: float(d[f"fold{i}_amplitude_{c}"]) for c in obs}))
        for i in range(int(d["n_folds"])))
    branches = tuple(
        Branch(kind=str(d[f"branch{i}_kind"]), mu=d[f"branch{i}_mu"],
               period=d[f"branch{i}_period"],
               amplitude=_mapping(d, f"branch{i}_amplitude_", obs),
               mean=_mapping(d, f"branch{i}_mean_", obs), stable=d[f"branch{i}_stable"],
               floquet=d[f"branch{i}_floquet"], x0=d[f"branch{i}_x0"],
               orbits=d[f"branch{i}_orbits"], system=system, solved=_solved(d, i, system))
        for i in range(int(d["n_branches"])))
    return BifurcationDiagram(system=system, hopf=hopf, folds=folds, branches=branches,
                              criticality=str(d["criticality"]),
                              runtime_s=float(d["runtime_s"]), n_steps=int(d["n_steps"]))
