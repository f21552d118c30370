r"""Writing the continuation results shipped with the package.

``python -m bayeshopf.simulators.ship [system ...]`` writes them again.

For every system of :data:`~bayeshopf.simulators.stored.SHIPPED`,
:func:`write_stored` computes the bifurcation diagram afresh
(:func:`~bayeshopf.simulators.arclength.continue_from_hopf`) and the orbits
that ``bayeshopf demo`` and its checks sample along it (the training plan and
the held-out orbits of :mod:`bayeshopf.simulators.truth`, at the recordings'
:data:`~bayeshopf.simulators.recordings.N_ORBIT` samples and at the branch's
own), and writes them, with the system's key
(:func:`~bayeshopf.simulators.stored.system_key`), where
:func:`~bayeshopf.simulators.stored.stored_diagram` reads them.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from bayeshopf._atomic import replacing
from bayeshopf.simulators.arclength import continue_from_hopf
from bayeshopf.simulators.base import System
from bayeshopf.simulators.recordings import N_ORBIT
from bayeshopf.simulators.stored import FOLDER, SHIPPED, orbit_name, stored_path, system_key
from bayeshopf.simulators.truth import FLUTTER_HELD_OUT, FLUTTER_PLAN

__all__ = ["orbits_to_store", "write_stored"]


def orbits_to_store(system: System) -> list[tuple[float, str, int | None]]:
    """``(mu, branch, n_points)`` of the orbits stored for ``system``: the demo's and its checks'.

    The recordings sample :data:`~bayeshopf.simulators.recordings.N_ORBIT`
    points; the truth's checks the branch's own (``None``).
    """
    if system.name != "flutter3dof":
        return []
    return [(m, b, n) for m, b in (*FLUTTER_PLAN, *FLUTTER_HELD_OUT) for n in (N_ORBIT, None)]


def _arrays(system: System, key: str) -> dict[str, np.ndarray]:
    """The diagram and the orbits of :func:`orbits_to_store`, computed afresh, by stored name."""
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
    for mu, branch, n_points in orbits_to_store(system):
        on = diagram.branch(branch)
        orbit = on.orbit(mu, n_points=n_points)        # a fresh diagram: solved, never read
        name = orbit_name(on, mu, orbit.states.shape[0])
        out.update({f"{name}_mu": np.array(orbit.mu), f"{name}_period": np.array(orbit.period),
                    f"{name}_x0": orbit.x0, f"{name}_states": orbit.states,
                    f"{name}_floquet": orbit.floquet, f"{name}_stable": np.array(orbit.stable)})
        out.update({f"{name}_amplitude_{c}": np.array(v) for c, v in orbit.amplitude.items()})
        out.update({f"{name}_mean_{c}": np.array(v) for c, v in orbit.mean.items()})
    return out


def save_arrays(arrays: dict[str, np.ndarray], path: Path) -> Path:
    """Write ``arrays`` to the ``.npz`` file ``path`` (compressed), atomically."""
    with replacing(path) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    return path


def write_stored(system: System, folder: Path = FOLDER) -> Path:
    """Compute ``system``'s diagram and demo orbits afresh and store them in ``folder``.

    Raises:
        ValueError: If nothing may be stored for ``system`` (its right-hand side
            or force input is not a module-level function of
            :mod:`bayeshopf.simulators`).
    """
    key = system_key(system)
    if key is None:
        raise ValueError(f"{system.name}: its right-hand side or force input is not a "
                         "module-level function of bayeshopf.simulators, so nothing can be "
                         "stored for it")
    return save_arrays(_arrays(system, key), stored_path(system, Path(folder)))


def main(argv: list[str] | None = None) -> int:
    """``python -m bayeshopf.simulators.ship [system ...]``: write the shipped files again."""
    from bayeshopf.inference.cache import configure_xla_cpu
    from bayeshopf.simulators.registry import get_system

    configure_xla_cpu()        # as the CLI runs
    for name in (argv if argv else SHIPPED):
        path = write_stored(get_system(name))
        print(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
