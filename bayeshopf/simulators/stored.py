r"""Continuation results shipped with the package: the built-in 3-DOF aerofoil's.

:func:`~bayeshopf.simulators.bifurcation_diagram` and the orbits that
:func:`~bayeshopf.simulators.simulate_recordings` samples are deterministic
functions of an immutable :class:`~bayeshopf.simulators.System`. For the
``flutter3dof`` system of ``bayeshopf demo`` they took 9–10 s (the
continuation) and 4–5 s (compiling and correcting the plan's orbits) of every
demo process, before any fitting. They are stored in
``bayeshopf/simulators/stored/`` by :func:`write_stored` (``python -m
bayeshopf.simulators.stored``) and read back instead of computed when
everything they depend on is the same:

- the file's **key**, a SHA-256 of the system's description (its parameters,
  states, observed channels), its μ range, the module and name of its
  right-hand side and force input, and the source files of :mod:`bayeshopf.simulators`: a
  change to any of them makes the stored file stale, and the result is
  computed as before (``tests/test_stored.py`` fails until the file is written
  again);
- a right-hand side (and force input, if any) defined at module level in
  :mod:`bayeshopf.simulators`: a closure, such as a planted effect's, is never
  looked up.

The arrays are those the computation returned; ``tests/test_stored.py``
compares them with a fresh continuation, from which they differ by the
rounding of two runs (1e-9 relative, at the ODE solver's tolerance).
"""

from __future__ import annotations

import functools
import hashlib
import io
import json
import os
import sys
from pathlib import Path
from types import MappingProxyType

import numpy as np

from bayeshopf.simulators.base import System

__all__ = ["stored_diagram", "stored_orbit", "system_key", "write_stored"]

#: Folder of the stored files (inside the package).
FOLDER = Path(__file__).with_name("stored")
#: Systems whose results are shipped (their diagram, and the orbits of
#: :func:`_orbits_to_store`).
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
    module, qualname = getattr(f, "__module__", "") or "", getattr(f, "__qualname__", "<locals>")
    if not module.startswith("bayeshopf.simulators") or "<locals>" in qualname:
        return None
    return f"{module}:{qualname}"


def _path(system: System) -> Path:
    return FOLDER / f"{system.name}.npz"


@functools.lru_cache(maxsize=8)
def _load(path: Path, mtime: float) -> dict | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError):
        return None


def _stored(system: System) -> dict | None:
    key = system_key(system)
    path = _path(system)
    if key is None or not path.is_file():
        return None
    data = _load(path, path.stat().st_mtime)
    if data is None or str(data["key"]) != key:
        return None
    return data


def _mapping(data: dict, prefix: str, names) -> MappingProxyType:
    return MappingProxyType({c: data[f"{prefix}{c}"] for c in names})


def stored_diagram(system: System):
    """The stored :class:`~bayeshopf.simulators.BifurcationDiagram` of ``system``, or ``None``."""
    from bayeshopf.simulators.continuation import BifurcationDiagram, Branch, Fold
    from bayeshopf.simulators.equilibria import HopfPoint

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
               orbits=d[f"branch{i}_orbits"], system=system)
        for i in range(int(d["n_branches"])))
    return BifurcationDiagram(system=system, hopf=hopf, folds=folds, branches=branches,
                              criticality=str(d["criticality"]),
                              runtime_s=float(d["runtime_s"]), n_steps=int(d["n_steps"]))


def _orbit_name(branch, mu: float, n_points: int) -> str:
    """Names the orbit by its branch (kind and a hash of the branch's μ), μ and samples."""
    path = hashlib.sha256(np.ascontiguousarray(branch.mu, dtype=np.float64).tobytes())
    return f"orbit_{branch.kind}_{path.hexdigest()[:12]}_{float(mu).hex()}_{int(n_points)}"


def stored_orbit(system: System, branch, mu: float, n_points: int):
    """The stored :class:`~bayeshopf.simulators.periodic.PeriodicOrbit` on a branch, or ``None``."""
    from bayeshopf.simulators.periodic import PeriodicOrbit

    d = _stored(system)
    if d is None:
        return None
    name = _orbit_name(branch, mu, n_points)
    if f"{name}_states" not in d:
        return None
    obs = system.observed
    return PeriodicOrbit(
        mu=float(d[f"{name}_mu"]), period=float(d[f"{name}_period"]), x0=d[f"{name}_x0"],
        states=d[f"{name}_states"], floquet=d[f"{name}_floquet"],
        stable=bool(d[f"{name}_stable"]), state_names=system.state_names,
        amplitude=MappingProxyType({c: float(d[f"{name}_amplitude_{c}"]) for c in obs}),
        mean=MappingProxyType({c: float(d[f"{name}_mean_{c}"]) for c in obs}))


def _orbits_to_store(system: System) -> list[tuple[float, str, int]]:
    """The orbits ``bayeshopf demo`` and its checks sample: the plan's and the held-out ones."""
    from bayeshopf.simulators.recordings import N_ORBIT
    from bayeshopf.simulators.truth import FLUTTER_HELD_OUT, FLUTTER_PLAN

    if system.name != "flutter3dof":
        return []
    # the recordings sample N_ORBIT points; the truth's checks the branch's own (None)
    return [(m, b, n) for m, b in (*FLUTTER_PLAN, *FLUTTER_HELD_OUT) for n in (N_ORBIT, None)]


def write_stored(system: System, folder: Path = FOLDER) -> Path:
    """Compute ``system``'s diagram and demo orbits afresh and store them (atomically)."""
    from bayeshopf.simulators.continuation import _orbit_on, continue_from_hopf

    key = system_key(system)
    if key is None:
        raise ValueError(f"{system.name}: its right-hand side or force input is not a "
                         "module-level function of bayeshopf.simulators, so nothing can be "
                         "stored for it")
    diagram = continue_from_hopf(system)
    out: dict[str, np.ndarray] = {"key": np.array(key)}
    h = diagram.hopf
    out.update(hopf_mu=np.array(h.mu), hopf_omega=np.array(h.omega),
               hopf_equilibrium=np.asarray(h.equilibrium),
               hopf_eigenvector=np.asarray(h.eigenvector),
               hopf_crossing_speed=np.array(h.crossing_speed),
               n_folds=np.array(len(diagram.folds)), n_branches=np.array(len(diagram.branches)),
               criticality=np.array(diagram.criticality), runtime_s=np.array(diagram.runtime_s),
               n_steps=np.array(diagram.n_steps))
    for i, f in enumerate(diagram.folds):
        out.update({f"fold{i}_mu": np.array(f.mu), f"fold{i}_period": np.array(f.period),
                    f"fold{i}_x0": np.asarray(f.x0)})
        out.update({f"fold{i}_amplitude_{c}": np.array(v) for c, v in f.amplitude.items()})
    for i, b in enumerate(diagram.branches):
        out.update({f"branch{i}_kind": np.array(b.kind), f"branch{i}_mu": b.mu,
                    f"branch{i}_period": b.period, f"branch{i}_stable": b.stable,
                    f"branch{i}_floquet": b.floquet, f"branch{i}_x0": b.x0,
                    f"branch{i}_orbits": b.orbits})
        out.update({f"branch{i}_amplitude_{c}": v for c, v in b.amplitude.items()})
        out.update({f"branch{i}_mean_{c}": v for c, v in b.mean.items()})
    for mu, branch, n_points in _orbits_to_store(system):
        on = diagram.branch(branch)
        orbit = _orbit_on(on, mu, n_points, look_up=False)     # solved, never read back
        name = _orbit_name(on, mu, orbit.states.shape[0])
        out.update({f"{name}_mu": np.array(orbit.mu), f"{name}_period": np.array(orbit.period),
                    f"{name}_x0": orbit.x0, f"{name}_states": orbit.states,
                    f"{name}_floquet": orbit.floquet, f"{name}_stable": np.array(orbit.stable)})
        out.update({f"{name}_amplitude_{c}": np.array(v) for c, v in orbit.amplitude.items()})
        out.update({f"{name}_mean_{c}": np.array(v) for c, v in orbit.mean.items()})
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{system.name}.npz"
    buf = io.BytesIO()
    np.savez_compressed(buf, **out)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(buf.getvalue())
    os.replace(tmp, path)
    return path


def main(argv: list[str] | None = None) -> int:
    """``python -m bayeshopf.simulators.stored``: write the shipped files again."""
    from bayeshopf.inference.cache import configure_xla_cpu
    from bayeshopf.simulators.registry import get_system

    configure_xla_cpu()        # as the CLI runs
    for name in (argv if argv else SHIPPED):
        path = write_stored(get_system(name))
        print(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
