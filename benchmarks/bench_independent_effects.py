"""How much each hidden effect of ``tests/testbed/independent_effects.py`` changes the LCOs.

The effects are written without the term library (the blind tests' truths). This
script measures, at a few sizes, the change of the stable LCO amplitudes at three
airspeeds and of the unstable ones at two, and writes
``benchmarks/independent_effects.{md,json}`` (names of effects as arguments measure
only those and merge them into the stored table)::

    .venv/bin/python benchmarks/bench_independent_effects.py [EFFECT ...]
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Mapping
from pathlib import Path

from _common import RESULTS_DIR, atomic_write
from testbed.independent_effects import (
    EFFECTS,
    PERTURBATIONS,
    PeriodicOrbit,
    SimulationError,
    System,
    stable_orbit,
    tracked_orbit,
)

# --------------------------------------------------------------------------- measurement

#: Airspeeds (m/s) of the stable and of the unstable LCOs measured by the script.
MEASURE_STABLE = (15.5, 16.5, 17.5)
MEASURE_UNSTABLE = (16.0, 17.0)
#: Sizes measured per effect (the script's table).
MEASURE_SIZES = {
    "pitch_freeplay": (0.001, 0.002),
    "heave_stribeck_friction": (0.2, 0.5),
    "pitch_stribeck_friction": (0.01, 0.03),
    "stall_saturation": (0.2, 0.15),
    "pitch_cubic_stiffness": (100.0, 200.0),
    "perturb_k_h": (0.05,),
    "perturb_k_alpha": (0.05,),
    "perturb_c_h": (0.05,),
    "perturb_c0": (0.05,),
}


def _hopf_of(system: System) -> str:
    from bayeshopf.simulators import find_hopf

    try:
        return f"{find_hopf(system).mu:.3f}"
    except SimulationError as exc:
        return "none (singular equilibrium)" if "equilibrium" in str(exc) else "none in 12–20"


def _change(o: PeriodicOrbit, o0: PeriodicOrbit) -> dict:
    out = {c: 100.0 * (o.amplitude[c] / o0.amplitude[c] - 1.0) for c in o0.amplitude}
    out["period"] = 100.0 * (o.period / o0.period - 1.0)
    out["stable"] = bool(o.stable)
    return out


def measure(sizes: Mapping[str, tuple[float, ...]] = MEASURE_SIZES,
            stable_mu: tuple[float, ...] = MEASURE_STABLE,
            unstable_mu: tuple[float, ...] = MEASURE_UNSTABLE) -> list[dict]:
    """Amplitude and period changes (%) of each effect's LCOs against the nominal ones.

    Stable LCOs by :func:`stable_orbit` from the nominal stable orbit, unstable
    ones by :func:`tracked_orbit` from the nominal unstable orbit (size 0 → size).
    """
    from bayeshopf.simulators import FLUTTER3DOF, bifurcation_diagram

    base = FLUTTER3DOF
    d = bifurcation_diagram(base)
    nominal = {(m, "stable"): d.orbit_at(m, "stable") for m in stable_mu}
    nominal.update({(m, "unstable"): d.orbit_at(m, "unstable") for m in unstable_mu})
    rows = []
    for name, values in sizes.items():
        build, unit, param = {**EFFECTS, **PERTURBATIONS}[name]
        for v in values:
            t0 = time.perf_counter()
            eff = build(base, v)
            start = float(base.params.get(param, 0.0))
            row = {"effect": name, "size": v, "unit": unit, "hopf": _hopf_of(eff),
                   "stable": {}, "unstable": {}}
            for (m, b), o0 in nominal.items():
                try:
                    o = (stable_orbit(eff, m, o0.x0, o0.period) if b == "stable" else
                         tracked_orbit(eff, param, m, o0.x0, o0.period, start=start,
                                       stable=False))
                except SimulationError as exc:
                    row[b][str(m)] = {"error": str(exc)}
                    continue
                row[b][str(m)] = _change(o, o0)
            row["seconds"] = time.perf_counter() - t0
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def _cell(c: dict | None, branch: str) -> str:
    if c is None:
        return "–"
    if "error" in c:
        return "lost"
    flag = "" if c["stable"] == (branch == "stable") else " (stability changed)"
    return f"{c['h']:+.1f}, {c['alpha']:+.1f}{flag}"


def _table(rows: list[dict], stable_mu, unstable_mu) -> str:
    cols = ([("stable", m) for m in stable_mu] + [("unstable", m) for m in unstable_mu])
    head = ("| effect | size | Hopf point (m/s) | "
            + " | ".join(f"{b} {m:g}" for b, m in cols)
            + " | max \\|Δ\\| stable, unstable | time |")
    out = [head, "|" + "---|" * (5 + len(cols))]
    for r in rows:
        cells = [_cell(r[b].get(str(m)), b) for b, m in cols]
        big = []
        for b in ("stable", "unstable"):
            v = [abs(c[k]) for c in r[b].values() if "error" not in c for k in ("h", "alpha")]
            big.append(f"{max(v):.1f}" if v else "–")
        cells.append(", ".join(big))
        size = (f"{100 * r['size']:+g}%" if r["unit"] == "relative"
                else f"{r['size']:g} {r['unit']}")
        out.append(f"| {r['effect']} | {size} | {r['hopf']} | "
                   + " | ".join(cells) + f" | {r['seconds']:.0f} s |")
    return "\n".join(out)


def _markdown(rows: list[dict]) -> str:
    return (
        "# Independent effects: how much they change the LCOs\n\n"
        "Measured with `benchmarks/bench_independent_effects.py` (flutter3dof at its nominal "
        "parameters, one effect at a time, written without the term library). Each cell: "
        "change of the peak-to-peak amplitude of heave, pitch (%) against the nominal "
        "LCO at the same airspeed U (m/s). Stable LCOs: 40 periods integrated from the "
        "nominal stable orbit, then Newton's method (`stable_orbit`); unstable LCOs: "
        "homotopy in the effect's size from the nominal unstable orbit (`tracked_orbit`, "
        "8 steps, halved where Newton fails), required to stay Floquet-unstable "
        "(\"lost\": not found, or the homotopy reached a stable orbit instead). "
        "Hopf point: of the equilibrium (`find_hopf` over 12–20 m/s; nominal 18.275): "
        "freeplay makes the equilibrium singular (no structural pitch stiffness inside "
        "the gap) at any gap > 0; friction adds a damper of rate F_s/v_r at rest at any "
        "level > 0 (at the levels here: no Hopf point up to 20 m/s). "
        "The `perturb_*` rows change one base parameter by +5% and no effect, "
        "for comparison with the base-parameter errors of the blind sets. "
        "Time: the row on one core, compilation included.\n\n"
        + _table(rows, MEASURE_STABLE, MEASURE_UNSTABLE) + "\n"
    )


def main(argv: list[str] | None = None) -> int:
    """Measure the effects named in ``argv`` (default all), merged into the stored table."""
    here = Path(__file__).resolve().parent
    sys.path.insert(0, str(here))

    names = list(argv if argv is not None else sys.argv[1:]) or list(MEASURE_SIZES)
    unknown = sorted(set(names) - set(MEASURE_SIZES))
    if unknown:
        print(f"independent_effects: effects expected among {', '.join(MEASURE_SIZES)}; "
              f"got {', '.join(unknown)}", file=sys.stderr)
        return 2
    path = RESULTS_DIR / "independent_effects.json"      # raw rows; the table is .md
    old = json.loads(path.read_text())["rows"] if path.exists() else []
    new = measure({n: MEASURE_SIZES[n] for n in names})
    done = {(r["effect"], r["size"]) for r in new}
    merged = [r for r in old if (r["effect"], r["size"]) not in done] + new
    order = {n: i for i, n in enumerate(MEASURE_SIZES)}
    merged.sort(key=lambda r: (order.get(r["effect"], 99),
                               MEASURE_SIZES.get(r["effect"], ()).index(r["size"])
                               if r["size"] in MEASURE_SIZES.get(r["effect"], ()) else 99))
    atomic_write(here / "independent_effects.md", _markdown(merged))
    atomic_write(path, json.dumps({"stable_mu": list(MEASURE_STABLE),
                                   "unstable_mu": list(MEASURE_UNSTABLE), "rows": merged},
                                  indent=1) + "\n")
    print(_table(merged, MEASURE_STABLE, MEASURE_UNSTABLE))
    return 0


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    raise SystemExit(main())
