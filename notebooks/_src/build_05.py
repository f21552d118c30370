# ruff: noqa: E501
"""Writes notebooks/05_experimental_design.ipynb (unexecuted); run it with nbclient to store outputs.

    python notebooks/_src/build_05.py
    python -c "import nbformat, nbclient; p='notebooks/05_experimental_design.ipynb'; \\
        nb=nbformat.read(p, 4); nbclient.NotebookClient(nb, timeout=3600, \\
        resources={'metadata': {'path': 'notebooks'}}).execute(); nbformat.write(nb, p)"
"""

from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

cells = [
    new_markdown_cell("""# Which measurement next: a sequential CBC campaign on the simulator

A CBC experiment is slow: each unstable orbit takes minutes of wind-tunnel time to hold and record.
After a first few recordings, `bayeshopf next` (or `bh.next_measurements`) says where
the next one is expected to shrink the interval of a target most: here the **fold** μ_SN, where the
stable and unstable branches meet and below which the rig cannot flutter.

This notebook walks through a campaign on the 3-DOF aerofoil simulator (`flutter3dof`, Hopf point
18.2747 m/s, fold 14.9362 m/s, both from the simulator's eigenvalues and the continuation of its
periodic orbits), where the truth is known:

1. start from 2 stable and 2 unstable recordings, far from the fold, and fit them;
2. ask `bh.next_measurements` for the best (μ, branch); show the table and the figure;
3. "measure" there (simulate the recording the rig would give, with 1 % noise and sensor offsets);
4. refit with the new recording, and repeat.

How the gain is computed (no refit: the fit's posterior draws are reweighted by each possible
measured amplitude) is in `docs/experimental_design.md`; the comparison with a uniform sweep and
random points over 10 noise seeds is in `benchmarks/design.md`. Set `BAYESHOPF_FAST=1` before starting
the kernel for a quick run (short records, short chains, one step)."""),
    new_code_cell("""%matplotlib inline
import os

FAST = os.environ.get("BAYESHOPF_FAST", "0") == "1"

import warnings

warnings.filterwarnings("ignore", message="IProgress not found")  # tqdm without ipywidgets

from IPython.display import Markdown, display

import bayeshopf as bh
# the modules below are loaded here so that bh.<package>.<module> reaches them
import bayeshopf.plotting.design
import bayeshopf.plotting.truth
import bayeshopf.simulators.truth

START = ((16.0, "stable"), (17.4, "stable"), (16.4, "unstable"), (17.4, "unstable"))
STEPS = 1 if FAST else 4
SEED = 42   # the noise, phases and offsets of this campaign (not a seed of the benchmark)
settings = bh.Settings.fast() if FAST else bh.Settings()   # the defaults of `bayeshopf fit`
print(f"bayeshopf {bh.__version__}; fast mode: {FAST}")"""),
    new_markdown_cell("""## 1. The first four recordings

Two stable and two CBC-held unstable orbits between 16 and 17.4 m/s: well above the fold, so the
fold is an extrapolation and its interval is wide."""),
    new_code_cell("""rs, truth = bh.simulators.truth.flutter_experiment(seed=SEED, fast=FAST, plan=START, held_out=())
print(f"true fold {truth.mu_fold:.4f} m/s, true Hopf point {truth.mu0:.4f} m/s")
for r in rs:
    print(f"  {r.name}: {r.mu:g} m/s, {r.branch}")

history = []

def record_state(fit, added):
    fold, hopf = fit.interval("mu_fold"), fit.interval("mu0")
    history.append({"recordings": len(fit.features.mu), "added": added,
                    "fold": (fold.median, fold.lo, fold.hi), "hopf": (hopf.median, hopf.lo, hopf.hi)})
    print(f"{len(fit.features.mu)} recordings: fold {fold.median:.3f} [{fold.lo:.3f}, {fold.hi:.3f}] m/s "
          f"(width {fold.hi - fold.lo:.3f}, truth {'inside' if fold.contains(truth.mu_fold) else 'OUTSIDE'}); "
          f"Hopf {hopf.median:.3f} [{hopf.lo:.3f}, {hopf.hi:.3f}] m/s")

fit = bh.fit(rs, settings, criticality="subcritical", seed=0, progress=False)
record_state(fit, "start (2 stable + 2 unstable)")"""),
    new_markdown_cell("""## 2. Ask where to measure, measure there, refit

Each step prints the three best candidates (μ, branch, the probability that the branch exists
there, the predicted amplitude with its 90 % band, the fold's expected 90 % width after the
measurement and the gain), shows the figure (the diagram with the recommended points starred above,
the expected gain of each branch against μ below), then simulates the recording at the best
candidate and refits. Candidates where the branch may not exist (below the fold's band) are skipped
and counted. The table's "now" width comes from the 500 posterior draws the bands use, so it
differs slightly from the fit's interval printed after each refit (from all the draws)."""),
    new_code_cell("""def show(d):
    df = d.to_dataframe()
    top = df[df["rank"].notna()].sort_values("rank")
    rows = ["| rank | μ (m/s) | branch | P(exists) | amplitude (mm) [90%] | fold width now → after (m/s) | gain |",
            "|---:|---:|---|---:|---|---|---:|"]
    for _, c in top.iterrows():
        rows.append(f"| {int(c['rank'])} | {c['mu']:.2f} | {c['branch']} | {c['p_exists']:.2f} | "
                    f"{1e3 * c['amplitude']:.1f} [{1e3 * c['amplitude_lo']:.1f}, {1e3 * c['amplitude_hi']:.1f}] | "
                    f"{c['width_now']:.3f} → {c['width_after']:.3f} | {c['gain']:.3f} |")
    skipped = df[df["skipped"] != ""]
    display(Markdown("\\n".join(rows) + f"\\n\\n{len(skipped)} of {len(df)} candidates skipped "
                     "(the branch may not exist there)."))

recs = list(rs)
for step in range(1, STEPS + 1):
    d = bh.next_measurements(fit, target="fold", n=3, seed=step)
    print(f"step {step}: where to measure next")
    show(d)
    display(bh.plotting.design.plot_design(d, fit))
    best = d.recommended[0]
    try:
        new = bh.simulate(truth.system, [best.mu], [best.branch], noise=truth.noise,
                          offsets=truth.offsets, duration_s=truth.duration_s,
                          sample_rate_hz=truth.sample_rate_hz, seed=1000 + step,
                          diagram=truth.diagram)[0]
    except bh.simulators.SimulationError as err:   # CBC would not find the orbit either: the point is lost
        print(f"  no {best.branch} orbit at {best.mu:.2f} m/s: {err}")
        continue
    recs.append(new)
    rs_now = bh.RecordingSet(tuple(recs), rs.planar, rs.mu_label, rs.mu_units)
    fit = bh.fit(rs_now, settings, criticality="subcritical", seed=0, progress=False)
    record_state(fit, f"{best.branch} at {best.mu:.2f} m/s")"""),
    new_markdown_cell("""## 3. The campaign

The fold's and the Hopf point's 90 % intervals after each recording, against the truth. The fold
narrows fastest once a recording sits near it: there both branches nearly meet, and one amplitude
pins where they do."""),
    new_code_cell("""rows = ["| recordings | added | fold median [90%] (m/s) | width | Hopf median [90%] (m/s) | width |",
        "|---:|---|---|---:|---|---:|"]
for h in history:
    f, o = h["fold"], h["hopf"]
    rows.append(f"| {h['recordings']} | {h['added']} | {f[0]:.3f} [{f[1]:.3f}, {f[2]:.3f}] | {f[2] - f[1]:.3f} | "
                f"{o[0]:.3f} [{o[1]:.3f}, {o[2]:.3f}] | {o[2] - o[1]:.3f} |")
display(Markdown("\\n".join(rows) + f"\\n\\nTruth: fold {truth.mu_fold:.4f} m/s, Hopf point {truth.mu0:.4f} m/s."))
display(bh.plotting.truth.plot_diagram_vs_truth(fit, truth, title="after the campaign: posterior against the continuation"))"""),
    new_markdown_cell("""**When the recommended orbit is not there.** Candidates are ranked by the current fit. When
that fit's fold is off, the best candidate can lie below the true fold, where the orbit does not
exist: the simulator raises, as CBC would find nothing. The attempt costs a recording and adds
nothing, and the unchanged fit recommends the same point again; `next` does not learn from a failed
attempt. The stored run above found every orbit, and every fold interval held the truth. The
same campaign with the model that was the default before session 78 (no model discrepancy) lost
its seventh recording this way: after the sixth its fold interval [14.265, 14.924] m/s ended just
below the true 14.936 m/s, and the recommended 14.87 m/s had no orbit on either branch. An
experimenter would move to the next candidate above the failed μ. The ten campaigns of
`benchmarks/design.md` (seeds 100–109, that model) lost no recording this way (`docs/limits.md`,
"Which measurement next")."""),
    new_markdown_cell("""On the command line the same step is one call on a saved fit:

```bash
bayeshopf fit my-recordings --out my-fit
bayeshopf next my-fit --target fold --n 3
```

which prints the table above and writes `my-fit/figures/next_fold.png`. After the new recording is
added to the manifest, `bayeshopf fit` again, and ask again."""),
]

nb = new_notebook(cells=cells, metadata={
    "kernelspec": {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"},
    "language_info": {"name": "python", "version": "3.11.7"},
})
nbformat.write(nb, Path(__file__).parents[1] / "05_experimental_design.ipynb")
