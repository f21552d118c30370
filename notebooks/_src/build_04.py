# ruff: noqa: E501
"""Writes notebooks/04_missing_physics.ipynb (unexecuted); run it with nbclient to store outputs."""

from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

cells = [
    new_markdown_cell("""# Missing physics: where a simulator disagrees with the recordings, and what it lacks

A test engineer has a simulator of the rig (here the 3-DOF aerofoil `flutter3dof`) and recordings
of its limit cycles, stable and unstable (by control-based continuation). The simulator's
bifurcation diagram does not match. `bayeshopf.discrepancy.analyse`

1. **compares** the recordings with the simulator's periodic orbits at the same airspeeds and
   branches (frequency and Fourier coefficients of every observed channel, sensor offsets
   marginalised),
2. **locates** the mismatch (recording, channel, harmonic, phase along the orbit),
3. **names** the missing term: every candidate of a library (quadratic, cubic, quintic stiffness,
   freeplay, Coulomb friction, quadratic and cubic damping, on heave and on pitch) gets a posterior
   probability and a coefficient in physical units with a 90% interval,
4. **models** it: adds the most probable term and recomputes the orbits, the Hopf point and the fold,
5. and gives the **verdict** in one sentence — `named`, `none` (within noise) or `unexplained`
   (nothing in the library explains it; it never forces a name).

Here it is proven blind: the recordings are simulated with a hidden effect that the analysis is not
told. Set `BAYESHOPF_FAST=1` before starting the kernel for a quick run (shorter records, no hybrid
fit, no intervals of the Hopf point and fold with the term, no wind-tunnel data)."""),
    new_code_cell("""%matplotlib inline
import os

FAST = os.environ.get("BAYESHOPF_FAST", "0") == "1"

import warnings
from pathlib import Path

warnings.filterwarnings("ignore", message="IProgress not found")

import jax

jax.config.update("jax_enable_x64", True)

from IPython.display import Markdown, display

from bayeshopf.discrepancy import analyse, simulate_with_effect
from bayeshopf.plotting.discrepancy import plot_discrepancy_diagram, plot_orbit_residuals
from bayeshopf.simulators import get_system

flutter = get_system("flutter3dof")
PLAN = [(15.75, "stable"), (16.25, "stable"), (16.75, "stable"), (17.25, "stable"),
        (15.75, "unstable"), (16.25, "unstable"), (16.75, "unstable"), (17.25, "unstable")]
KW = dict(noise=0.015, offsets={"h": 0.001, "alpha": -0.004}, duration_s=8.0 if FAST else 20.0)
print(f"fast mode: {FAST}")"""),
    new_markdown_cell("""## 1. Recordings with a hidden effect

Quadratic damping in pitch, 0.05 N m/(rad/s)², a few percent of the rig's forces: it moves the fold
by 1.5% and the amplitudes by 3–6%. The truth is returned separately and not used below."""),
    new_code_cell("""rs, truth = simulate_with_effect(flutter, "alpha_quadratic_damping", 0.05,
                                 [m for m, _ in PLAN], [b for _, b in PLAN], seed=2, **KW)
print(len(rs), "recordings:", ", ".join(r.name for r in rs))"""),
    new_markdown_cell("""## 2. The blind analysis

Only the recordings and the simulator go in. With `hybrid=True` the Bayesian hybrid fit of the
recordings is run too (`bayeshopf.posterior.fit_hybrid`, subcritical, at the default
`CollapsedSettings`: four NUTS chains of 500 draws; a minute or two), for Hopf and fold intervals
that assume no simulator at all. The report records its settings and its convergence (largest R̂,
smallest bulk ESS, divergences, and any warning of the fit's checks) under `"hybrid"`."""),
    new_code_cell("""def show_hybrid(d):
    h = d["hybrid"]
    if h is None:
        print("no hybrid fit (fast mode)")
        return
    c = h["convergence"]
    print("hybrid fit: " + "; ".join(f"{k} {v['median']:.3f} [{v['ci90'][0]:.3f}, {v['ci90'][1]:.3f}]"
                                     for k, v in (("Hopf", h["hopf"]), ("fold", h["fold"]))))
    print(f"  {h['settings']['num_chains']} chains x {h['settings']['num_samples']} draws; "
          f"largest R-hat {c['r_hat']:.3f}, smallest bulk ESS {c['ess_bulk']:.0f}, "
          f"{c['divergences']} divergences; converged: {c['ok']}; {len(h['warnings'])} warning(s)")


report = analyse(rs, flutter, seed=0, hybrid=not FAST, point_intervals=not FAST)
d = report.to_json()
print(d["verdict"]["sentence"])
show_hybrid(d)
display(Markdown(report.to_markdown()))"""),
    new_markdown_cell("""## 3. Figures

The bifurcation diagram of the simulator (black), of the simulator with the named term (green) and
the recordings; then the residual along the orbit of every recording and channel (measured minus
simulated, sensor offsets removed) before and after, with ±2 standard errors in grey."""),
    new_code_cell("""display(plot_discrepancy_diagram(report))
display(plot_orbit_residuals(report))"""),
    new_markdown_cell("""## 4. The other answers: nothing missing, and something outside the library

With no hidden effect the verdict must be `none`. With a lagged aerodynamic pitch moment
(`delayed_aero`, a linear effect with its own state, which moves the Hopf point itself) no library
term can explain the recordings: the verdict must be `unexplained`, with the mismatch located."""),
    new_code_cell("""from bayeshopf.simulators import simulate_recordings

rs0 = simulate_recordings(flutter, [m for m, _ in PLAN], [b for _, b in PLAN], seed=3, **KW)
print("no effect:", analyse(rs0, flutter, hybrid=False).to_json()["verdict"]["sentence"])
if not FAST:  # the fast mode skips it (tests/test_discrepancy.py covers it)
    rs1, _ = simulate_with_effect(flutter, "delayed_aero", 1.0, [m for m, _ in PLAN],
                                  [b for _, b in PLAN], seed=4, **KW)
    print("delayed_aero:", analyse(rs1, flutter, hybrid=False).to_json()["verdict"]["sentence"])"""),
    new_markdown_cell("""## 5. The wind-tunnel recordings

The 7 CBC recordings of the real rig against the `flutter3dof` simulator. There is **no ground truth**:
what the analysis finds is a hypothesis to test on the rig, not a discovery. The hybrid fit of the rig
runs at the default `CollapsedSettings`, as `bayeshopf fit` does. Skipped in fast mode; without a local
copy of the recordings they are downloaded once."""),
    new_code_cell("""DATA = Path(os.environ.get("BAYESHOPF_FLUTTER_CBC", str(Path.cwd().parent / ".." / "shared" / "data" / "flutter_cbc")))
if not FAST:
    from bayeshopf.datasets import flutter_cbc

    rig = flutter_cbc(DATA) if DATA.is_dir() else flutter_cbc(download=True)  # no local copy: downloaded once
    real = analyse(rig, flutter, seed=0, hybrid=True)
    print(real.to_json()["verdict"]["sentence"])
    show_hybrid(real.to_json())
    display(Markdown(real.to_markdown()))
    display(plot_discrepancy_diagram(real))
else:
    print("skipped (fast mode)")"""),
]

nb = new_notebook(cells=cells, metadata={
    "kernelspec": {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"},
    "language_info": {"name": "python", "version": "3.11.7"},
})
nbformat.write(nb, Path(__file__).parents[1] / "04_missing_physics.ipynb")
