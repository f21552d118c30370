# ruff: noqa: E501
"""Writes notebooks/01_quickstart.ipynb (unexecuted); run it with nbclient to store outputs.

    python notebooks/_src/build_01.py
    python -c "import nbformat, nbclient; p='notebooks/01_quickstart.ipynb'; \\
        nb=nbformat.read(p, 4); nbclient.NotebookClient(nb, timeout=3600, \\
        resources={'metadata': {'path': 'notebooks'}}).execute(); nbformat.write(nb, p)"
"""

from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

cells = [
    new_markdown_cell("""# Quick start: a Hopf bifurcation from limit-cycle recordings

This notebook walks through a complete `bayeshopf` analysis on **synthetic recordings of a
system whose truth we know**, so every estimate can be checked against the planted value.

The system is a flutter-rig-like *subcritical* Hopf bifurcation in the airspeed μ (m/s):
the normal form

$$\\dot r = (\\mu-\\mu_0)\\,r + a_2 r^3 - r^5,\\qquad \\dot\\theta = \\Omega(r, \\mu),$$

observed through a nonlinear map to two physical channels, heave $h$ (m) and pitch
$\\alpha$ (rad). With $a_2>0$ there are two branches of limit-cycle oscillations (LCOs):
a **stable** branch and an **unstable** branch (measurable in a wind tunnel with
control-based continuation), which meet at the **fold** $\\mu_{\\rm fold}=\\mu_0-a_2^2/4$.

The analysis is the one `bh.fit` (and `bayeshopf fit`) runs:

1. **recordings**: time series of LCOs, each held at a fixed μ;
2. **features**: each recording reduced to the time-Fourier coefficients of both channels
   over a common phase origin, with their standard errors over segments of five periods;
3. **MAP**: a deterministic start and L-BFGS. The map's coefficients enter the features
   linearly, so they are integrated out exactly, and only a handful of nonlinear
   parameters remain;
4. **posterior**: draws from the MAP's Laplace approximation weighted by the posterior
   (importance sampling, with its check; NUTS where the check fails); one exact draw of
   the map per posterior draw. The model includes a **discrepancy** between the normal
   form plus map and the system, learned with the rest, so the intervals widen where
   the recordings disagree with the model;
5. **bands**: intervals of μ0, a2 and μ_fold, the bifurcation diagram with credible
   bands, predictive checks, frequencies, time series and predictions at new μ.

Set the environment variable `BAYESHOPF_FAST=1` before starting the kernel for a quick run
(a shorter MAP; the checks may then warn). The stored outputs come
from a run with the default settings."""),
    new_code_cell("""import os

FAST = os.environ.get("BAYESHOPF_FAST", "0") == "1"

import tempfile
import warnings
from pathlib import Path

warnings.filterwarnings("ignore", message="IProgress not found")  # tqdm without ipywidgets

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Markdown, display

import bayeshopf as bh
import bayeshopf.data.synthetic  # loads bh.data.synthetic (the planted demo system)

%matplotlib inline
print(f"bayeshopf {bh.__version__}; fast mode: {FAST}")"""),
    new_markdown_cell("""## 1. The recordings

`demo_system` simulates four stable and three unstable LCOs of the planted system with
measurement noise and returns them as a `RecordingSet` together with the truth
(`PlantedHopf`). With real data you would instead read them,
`bh.read_recordings("path/to/folder")` (an interchange folder, its manifest, or `.mat`
files) or `bh.read_recordings("flutter_cbc", download=True)` (the paper's rig)."""),
    new_code_cell("""rs, truth = bh.data.synthetic.demo_system(seed=0, fast=FAST)

rows = ["| recording | μ (m/s) | branch | duration (s) | sampling (Hz) |",
        "|---|---:|---|---:|---:|"]
for r in rs:
    rows.append(f"| {r.name} | {r.mu:g} | {r.branch} | {r.duration:.1f} | {1 / r.dt:.0f} |")
display(Markdown("\\n".join(rows)))
print(f"planar pair (z1, z2) = {rs.planar}, units {rs.units}")
print(f"truth: mu0 = {truth.mu0:g}, a2 = {truth.a2:g}, mu_fold = {truth.mu_fold:.3f} m/s")"""),
    new_markdown_cell("""Each recording is a steady oscillation. On the left, the first two seconds of the heave
signal; on the right, every recording in the $(h, \\alpha)$ phase plane. The unstable LCOs
(dashed) are smaller than the stable ones at the same μ and shrink towards the Hopf point
as μ grows, while the stable LCOs grow with μ."""),
    new_code_cell("""fig, (ax_t, ax_p) = plt.subplots(1, 2, figsize=(11, 4.2))
cmap = plt.get_cmap("viridis")
mu_lo, mu_hi = rs.mus.min(), rs.mus.max()
for r in rs:
    colour = cmap((r.mu - mu_lo) / (mu_hi - mu_lo))
    ls = "--" if r.branch == "unstable" else "-"
    z = r.planar(rs.planar)
    keep = r.t <= r.t[0] + 2.0
    ax_t.plot(r.t[keep], z[keep, 0], ls=ls, color=colour, lw=1, label=f"{r.mu:g} m/s ({r.branch})")
    ax_p.plot(z[:, 0], z[:, 1], ls=ls, color=colour, lw=0.6)
ax_t.set(xlabel="time (s)", ylabel=f"{rs.planar[0]} ({rs.units[0]})", title="heave, first 2 s")
ax_p.set(xlabel=f"{rs.planar[0]} ({rs.units[0]})", ylabel=f"{rs.planar[1]} ({rs.units[1]})",
         title="phase plane")
ax_t.legend(fontsize=7, ncol=2, loc="upper right")
fig.tight_layout()
plt.show()"""),
    new_markdown_cell("""## 2. Features

The model is not fitted to raw samples. Each recording's frequency is measured, the record
is cut into segments of five periods, and both channels of each segment are expanded in
a short Fourier series about a common phase origin (the crest of $z_1$'s fundamental),
in a common whitened frame. The mean coefficients over the segments, with the standard
error of that mean, are the data; the frequency is one more datum per recording. A record
of a few periods is one segment, and its least-squares standard errors take the place of
the spread. `bh.fit` does this itself; here we look at the features directly."""),
    new_code_cell("""features = bh.features.extract_harmonics(rs)
rows = ["| recording | μ (m/s) | branch | amplitude (m) | frequency (Hz) | segments |",
        "|---|---:|---|---:|---:|---:|"]
for i, name in enumerate(features.names):
    rows.append(
        f"| {name} | {features.mu[i]:g} | {'unstable' if features.unstable[i] else 'stable'} "
        f"| {features.amplitude[i]:.4f} | {features.frequency_hz[i]:.4f} "
        f"| {features.n_segments[i]} |"
    )
display(Markdown("\\n".join(rows)))
print(f"{features.n_harmonics} harmonics -> {features.coeffs.shape[-1]} coefficients per "
      "channel and recording")"""),
    new_markdown_cell("""## 3–4. MAP, then the posterior

`bh.fit` runs the whole chain: features, a grid over the two gaps (from the data to
the fold and to the Hopf point) as a deterministic start, L-BFGS to the MAP, then
importance sampling on the few nonlinear parameters (the gaps, the unfolding's
curvature `w`, the map's prior scales, the discrepancy's scale and length, the model
errors): Student-t draws about the MAP weighted by the posterior, Pareto-smoothed, and
checked (`inference="nuts"` runs NUTS instead). Nothing is random in the start, and
everything is reproducible from `seed`. The first fit in a
fresh environment spends part of its time compiling; JAX's persistent compilation cache
makes later fits start faster. The result, a `bh.Fit`, is immutable."""),
    new_code_cell("""settings = bh.Settings.fast() if FAST else bh.Settings()
fit = bh.fit(rs, settings, criticality="subcritical", seed=0, progress=False)
print("settings:", settings)
print("seconds per stage:", {k: round(v, 1) for k, v in fit.timings.items()})"""),
    new_markdown_cell("""### Did it converge?

`fit.diagnostics` holds the checks that `summary.json` gets, one status per check (the
MAP's gradient norm, the posterior's check (importance sampling's Pareto k̂ and
effective draws, or NUTS's R̂ and bulk ESS of the quantities of interest), each
recording's orbit error, the predictive checks, the model error) and one warning line per
failed check (the CLI prints them); `fit.diagnostics.details` holds their numbers."""),
    new_code_cell("""print(fit.diagnostics)
d = fit.diagnostics.details
print(f"\\nMAP: gradient norm {d['map']['grad_norm']:.2g} after {d['map']['steps']} L-BFGS steps "
      f"(converged: {d['map']['converged']})")
post = d["posterior"]
if post["method"] == "importance":
    print(f"importance sampling: Pareto k̂ {post['pareto_k']:.2f} (at most {post['k_max']}), "
          f"{post['ess']:.0f} effective of {post['proposals']} draws")
else:
    rows = ["| site | R̂ | bulk ESS | ok |", "|---|---:|---:|---|"]
    for name, v in post["sites"].items():
        rows.append(f"| {name} | {v['r_hat']:.3f} | {v['ess_bulk']:.0f} | {'yes' if v['ok'] else '**no**'} |")
    display(Markdown("\\n".join(rows)))
    print(f"{post['divergences']} divergent transitions")"""),
    new_markdown_cell("""## 5. Bands

### The Hopf point, the cubic coefficient and the fold

Posterior medians and 90 % equal-tailed credible intervals (`fit.interval`), next to the
planted values."""),
    new_code_cell("""true = {"mu0": truth.mu0, "a2": truth.a2, "mu_fold": truth.mu_fold}
rows = ["| quantity | median | 90% interval | true | inside? |", "|---|---:|---|---:|---|"]
for name, value in true.items():
    iv = fit.interval(name)
    rows.append(f"| {name} | {iv.median:.3f} | [{iv.lo:.3f}, {iv.hi:.3f}] | {value:.3f} "
                f"| {'yes' if iv.contains(value) else '**no**'} |")
display(Markdown("\\n".join(rows)))
w = fit.interval("w_unfold")
print(f"unfolding curvature w = {w.median:.2f} [{w.lo:.2f}, {w.hi:.2f}] (0: the paper's μ − μ0)")"""),
    new_markdown_cell("""### The bifurcation diagram

Amplitude (peak-to-peak heave) against airspeed (`fit.plot.bifurcation`, which also takes
`ax=` to draw into a figure of your own): posterior median of each branch, 50 % and 90 %
credible bands, the 90 % predictive band of a new recording (dotted), the measured
amplitudes, and the planted truth (thin black). The predictive band includes a model
error that is zero at the recordings and grows away from them, so it pinches at each
recording and widens between and beyond them. The inset magnifies the diagram about the
largest stable recording."""),
    new_code_cell("""display(fit.plot.bifurcation(truth=truth))
diagram = fit.diagram(bh.plotting.diagram_grid(fit))
print(f"Hopf point {diagram.mu0.median:.3f} m/s [{diagram.mu0.lo:.3f}, {diagram.mu0.hi:.3f}]; "
      f"fold {diagram.mu_fold.median:.3f} m/s [{diagram.mu_fold.lo:.3f}, {diagram.mu_fold.hi:.3f}] "
      f"at amplitude {diagram.fold_amplitude.median:.4f} m")"""),
    new_markdown_cell("""### Phase portraits

Each recording's measured orbit (grey) over posterior orbit draws at its μ and branch
(thin coloured lines) and their median (bold); the planted orbit is the thin black line.
`fit.orbit_error()` gives each median orbit's RMS distance from the measured mean orbit,
relative to the orbit's size."""),
    new_code_cell("""display(bh.plotting.plot_phase_portraits(fit, rs, truth=lambda mu, branch: truth.orbit(mu, branch)))
print("orbit errors (%):", [round(100 * e["relative"], 2) for e in fit.orbit_error()])"""),
    new_markdown_cell("""### Posterior predictive check

Would the fitted model produce recordings like the ones we measured? Left: each
recording's predictive amplitude (median and 90 % interval) against the measured one;
right: standardised residuals of every Fourier coefficient (a value beyond ±2 is a
coefficient the model reproduces poorly)."""),
    new_code_cell("""display(fit.plot.ppc())
ppc = fit.ppc()
rows = ["| recording | μ | branch | measured | predicted median | 90% interval | p-value "
        "| inside |",
        "|---|---:|---|---:|---:|---|---:|---|"]
for i, name in enumerate(ppc.names):
    iv = ppc.predictive[i]
    rows.append(
        f"| {name} | {ppc.mu[i]:g} | {'unstable' if ppc.unstable[i] else 'stable'} "
        f"| {ppc.measured[i]:.4f} | {iv.median:.4f} | [{iv.lo:.4f}, {iv.hi:.4f}] "
        f"| {ppc.amplitude_p[i]:.2f} | {'yes' if ppc.covered[i] else '**no**'} |"
    )
display(Markdown("\\n".join(rows)))
print(f"{int(ppc.covered.sum())}/{ppc.covered.size} measured amplitudes inside their 90% "
      f"predictive intervals; {100 * ppc.coeff_coverage:.0f}% of the Fourier coefficients "
      f"inside theirs; largest |standardised residual| {np.abs(ppc.coeff_z).max():.2f}")"""),
    new_markdown_cell("""### Frequency and time series

Each recording's frequency is the phase speed $\\Omega(r, \\mu)$ of its orbit; its
coefficients are integrated out like the map's. First the frequency against μ with curve
and predictive bands and the measured frequencies; then the predicted heave over four
periods of each recording, started at the recording's phase, with its 90 % band."""),
    new_code_cell("""display(fit.plot.frequency())
display(fit.plot.time_series(rs))"""),
    new_markdown_cell("""## Predicting at a new airspeed

`fit.predict(mu, branch)` returns an `xarray.Dataset` over μ: the median and 90 % interval
of a new recording's amplitude (the model curve's, plus the model error, larger away from
the recordings, and the measurement error) and frequency, and `p_exists`, the share of
posterior draws in which the branch exists there (the values are `nan` where it exists in
fewer than half of them, e.g. the stable branch below the fold); `predictive=False` gives
the model curve's. μ = 17 m/s lies between the recordings; 20.5 m/s is beyond the largest
one (an extrapolation, with a wider band)."""),
    new_code_cell("""rows = ["| μ (m/s) | branch | curve median | curve 90% | new-recording 90% | exists | true "
        "| frequency (Hz) |",
        "|---:|---|---:|---|---|---:|---:|---|"]
for mu, branch in [(17.0, "stable"), (17.0, "unstable"), (20.5, "stable")]:
    c = fit.predict([mu], branch, predictive=False).sel(mu=mu)
    n = fit.predict([mu], branch).sel(mu=mu)
    rows.append(
        f"| {mu:g} | {branch} | {float(c.amplitude):.4f} "
        f"| [{float(c.amplitude_lo):.4f}, {float(c.amplitude_hi):.4f}] "
        f"| [{float(n.amplitude_lo):.4f}, {float(n.amplitude_hi):.4f}] "
        f"| {100 * float(c.p_exists):.0f}% | {float(truth.amplitude(mu, branch)):.4f} "
        f"| {float(c.frequency):.4f} [{float(c.frequency_lo):.4f}, {float(c.frequency_hi):.4f}] |"
    )
display(Markdown("\\n".join(rows)))"""),
    new_markdown_cell("""## Saving the fit and loading it back

`fit.save(folder, recordings=rs)` writes a folder (`summary.json` with the `diagnostics`
block, `posterior.nc` with the draws as ArviZ InferenceData, `model.json`, and the
figures) atomically; `bh.load_fit(folder)` reads it back as a `Fit` that predicts without
refitting. The command line does the same: `bayeshopf fit DATA --out DIR`, then
`bayeshopf predict DIR --mu 17 --json`."""),
    new_code_cell("""workdir = Path(tempfile.mkdtemp(prefix="bayeshopf-quickstart-"))
folder = fit.save(workdir / "demo-fit", recordings=rs).folder
print("wrote:", sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()))

saved = bh.load_fit(folder)
before = fit.predict([17.0], "stable", predictive=False).sel(mu=17.0)
after = saved.predict([17.0], "stable", predictive=False).sel(mu=17.0)
print(f"stable amplitude at 17 m/s: in memory {float(before.amplitude):.5f} "
      f"[{float(before.amplitude_lo):.5f}, {float(before.amplitude_hi):.5f}], loaded "
      f"{float(after.amplitude):.5f} [{float(after.amplitude_lo):.5f}, {float(after.amplitude_hi):.5f}]")
p15 = float(saved.predict([15.0], "stable", predictive=False).p_exists[0])
print(f"P(stable LCO exists at 15 m/s) = {p15:.2f} (true fold at {truth.mu_fold:.2f} m/s)")"""),
    new_code_cell("""import shutil

shutil.rmtree(workdir)  # the example's files were temporary"""),
    new_markdown_cell("""## Next steps

* Real wind-tunnel data: `rs = bh.read_recordings("path/to/flutter_cbc")` (or
  `bh.read_recordings("flutter_cbc", download=True)`) and the same `bh.fit(rs)`; or from a
  shell, `bayeshopf fit path/to/flutter_cbc --out my-fit` (notebook 03).
* `bayeshopf demo` fits the paper's 3-DOF aeroelastic aerofoil, simulated in-process, the
  same way, and prints the intervals next to the simulator's own values (notebook 02).
* Unsure whether the bifurcation is sub- or supercritical? `bh.fit(rs, criticality="auto")`
  fits both normal forms and keeps the one the data prefer (two distinct orbits at one μ
  mean a fold; otherwise the leave-one-out ELPD of both), with the comparison in
  `fit.evidence`.
* `bh.next_measurements(fit, target="fold")` says where to measure next (notebook 05), and
  `bh.discrepancy.analyse` what a simulator of the rig lacks (notebook 04)."""),
]

nb = new_notebook(cells=cells, metadata={
    "kernelspec": {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"},
    "language_info": {"name": "python", "version": "3.11.7"},
})
nbformat.write(nb, Path(__file__).parents[1] / "01_quickstart.ipynb")
