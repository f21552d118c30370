# ruff: noqa: E501
"""Writes notebooks/03_wind_tunnel.ipynb (unexecuted); run it with nbclient to store outputs."""

from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

cells = [
    new_markdown_cell("""# The wind-tunnel flutter rig: the paper's experimental result, with bands

Lee, Barton & Renson fitted their hybrid model to **7 limit-cycle recordings of a flutter rig**
measured with control-based continuation (CBC): 4 stable LCOs and 3 unstable ones, with the
airspeed μ as the bifurcation parameter. They reported a Hopf point at **17.67 m/s** and a fold at
**14.66 m/s**, and admitted that their fit overfits: the diagram wiggles between recordings and the
fold moves a lot when one recording is left out.

This notebook fits the Bayesian hybrid model with `bh.fit`, as `bayeshopf fit` does:
1. the recordings and their harmonic features,
2. the fit: μ0, a2 and μ_SN with 90% intervals next to the paper's values, the convergence
   diagnostics, each orbit's error, the bifurcation diagram and the phase portraits,
3. leave-one-out refits: how well the Bayesian fit and a MAP plug-in predict the held-out LCO,
   and a check of the normal form on the stable/unstable pairs without any map,
4. a third channel, the actuator command, regressed on the normal-form state,
5. the frequency of the oscillations and the time series, with bands.

The recordings are the authors' MIT-licensed files (Kyounghyunlee/ML_Hopf), read from the folder
named by `BAYESHOPF_FLUTTER_CBC` (or `../shared/data/flutter_cbc`) if it exists, else downloaded once
(11 MB, SHA-256 checked) by `bh.read_recordings("flutter_cbc", download=True)`. Set `BAYESHOPF_FAST=1`
before starting the kernel for a quick run (short chains, two leave-one-out folds)."""),
    new_code_cell("""%matplotlib inline
import os

FAST = os.environ.get("BAYESHOPF_FAST", "0") == "1"

import warnings
from pathlib import Path

warnings.filterwarnings("ignore", message="IProgress not found")  # tqdm without ipywidgets

import numpy as np
from IPython.display import Markdown, display

import bayeshopf as bh
# the modules below are loaded here so that bh.<package>.<module> reaches them
import bayeshopf.diagnostics.comparison
import bayeshopf.diagnostics.pair_invariant
import bayeshopf.inference.channels
import bayeshopf.plotting.channels
import bayeshopf.plotting.pair_invariant
import bayeshopf.plotting.validation

DATA = Path(os.environ.get("BAYESHOPF_FLUTTER_CBC", str(Path.cwd().parent / ".." / "shared" / "data" / "flutter_cbc")))
settings = bh.Settings.fast() if FAST else bh.Settings()   # the defaults for the full run
print(f"bayeshopf {bh.__version__}; fast mode: {FAST}")"""),
    new_markdown_cell("""## 1. The recordings

Each `.mat` file holds 20 s at 5 kHz. Heave is row 1 (V, 0.18 m/V) and pitch row 4 (rad); the
airspeed comes from `Wind_sped`, the branch from the file name. The unstable records drift slowly
(the CBC loop keeps correcting), so every record is cut into segments of 5 periods; each segment's
orbit is aligned in phase and expanded in K = 4 harmonics per channel in a common planar frame, and
the mean and standard error over the segments enter the likelihood. The whole record is used, not
the paper's 1.2 s."""),
    new_code_cell("""rs = bh.read_recordings(DATA) if DATA.is_dir() else bh.read_recordings("flutter_cbc", download=True)  # no local copy: downloaded once
feats = bh.features.extract_harmonics(rs, n_harmonics=settings.n_harmonics, segment_periods=settings.segment_periods)
rows = ["| recording | μ (m/s) | branch | segments | heave p-p (mm) | frequency (Hz) |",
        "|---|---:|---|---:|---:|---:|"]
for i, r in enumerate(rs):
    rows.append(f"| {r.name} | {r.mu:g} | {r.branch} | {feats.n_segments[i]} | "
                f"{1e3 * feats.amplitude[i]:.1f} ± {1e3 * feats.amplitude_sd[i]:.1f} | "
                f"{feats.frequency_hz[i]:.3f} |")
display(Markdown("\\n".join(rows)))"""),
    new_markdown_cell("""## 2. The fit

**Criticality.** The rig's unstable LCOs were measured by CBC (the controller stabilises them), and
only a *subcritical* Hopf bifurcation has an unstable LCO branch, so the model is subcritical. The
recordings say so without any model too: at 14.9 and at 16.5 m/s there are two orbits of very
different size, each repeatable over its segments, and a supercritical Hopf bifurcation has one LCO
per airspeed:"""),
    new_code_cell("""for p in bh.diagnostics.comparison.coexisting_orbits(feats):
    a, b = p["amplitudes"]
    print(f"{p['mu']:g} m/s: {p['recordings'][0]} {1e3 * a:.1f} mm and {p['recordings'][1]} "
          f"{1e3 * b:.1f} mm, {p['separation']:.0f} segment spreads apart")"""),
    new_markdown_cell("""`bh.fit(rs, criticality="subcritical")` at its default settings: a deterministic start and the MAP
(L-BFGS), then importance sampling (2,000 draws; NUTS where its check fails) on the few nonlinear
parameters with the map's linear coefficients integrated out, and one exact draw of the map per
posterior draw. The model includes a discrepancy between the normal form plus map and the rig,
learned with the rest, and μ0 and the fold are the rig's: the normal form's points moved by that
discrepancy's twin in μ (`docs/model_discrepancy.md`). The posterior medians
and 90% intervals, next to the paper's point estimates:"""),
    new_code_cell("""fit = bh.fit(rs, settings, criticality="subcritical", seed=0, progress=False)
paper = {"mu0": 17.67, "mu_fold": 14.66}
rows = ["| | median | 90% interval | paper |", "|---|---:|---|---:|"]
for name in ("mu0", "a2", "mu_fold"):
    iv = fit.interval(name)
    rows.append(f"| {name} | {iv.median:.2f} | [{iv.lo:.2f}, {iv.hi:.2f}] | {paper.get(name, '–')} |")
display(Markdown("\\n".join(rows)))
print("seconds per stage: " + ", ".join(f"{k} {v:.0f}" for k, v in fit.timings.items()))"""),
    new_markdown_cell("""**Convergence.** The MAP's gradient norm, and the posterior's check: importance sampling's
Pareto k̂ and effective draws (or, where NUTS ran, per site R̂ and bulk ESS against the thresholds,
and the divergent transitions). Any failed check, of convergence or of the fit, is listed as a
warning: `fit.diagnostics` gives each check's status and the warnings, `fit.diagnostics.details`
the numbers."""),
    new_code_cell("""d = fit.diagnostics.details
m, p = d["map"], d["posterior"]
print(f"MAP: gradient norm {m['grad_norm']:.2g} after {m['steps']} L-BFGS steps "
      f"(tolerance {m['tolerance']:g}): {'converged' if m['converged'] else 'NOT converged'}")
if p["method"] == "importance":
    print(f"importance sampling: Pareto k̂ {p['pareto_k']:.2f} (at most {p['k_max']}), "
          f"{p['ess']:.0f} effective of {p['proposals']} draws")
else:
    rows = [f"| site | R̂ (≤ {p['r_hat_max']}) | bulk ESS (≥ {p['ess_min']}) | ok |", "|---|---:|---:|---|"]
    for name, s in p["sites"].items():
        rows.append(f"| {name} | {s['r_hat']:.3f} | {s['ess_bulk']:.0f} | {'yes' if s['ok'] else 'no'} |")
    display(Markdown("\\n".join(rows)))
    print(f"{p['chains']} chains, {p['divergences']} divergent transitions")
print(fit.diagnostics)"""),
    new_markdown_cell("""**Orbit error.** Each recording's posterior-median orbit against its measured mean orbit: the RMS
distance over the orbit relative to the orbit's RMS radius, and the segments' own spread on the same
scale. The bar is 5%, or twice the spread."""),
    new_code_cell("""rows = ["| recording | orbit error | segment spread | within the bar |", "|---|---:|---:|---|"]
for e in fit.orbit_error():
    rows.append(f"| {e['name']} | {100 * e['relative']:.1f}% | {100 * e['spread']:.1f}% | {'yes' if e['ok'] else 'no'} |")
display(Markdown("\\n".join(rows)))
ppc = fit.ppc()
print(f"{int(ppc.covered.sum())}/{ppc.covered.size} training amplitudes inside their 90% predictive bands")"""),
    new_markdown_cell("""**The controller's residual.** CBC holds each orbit with a feedback force. Its search nulls one
scalar measure of that force's fundamental, not the fundamental itself, and the rig records the
actuator command (the rig description's `control` channel). Its fundamental `U` is a measured
input of the model: the pitch axis `w2` of each orbit, relative to the heave, moves by `H U` with a
complex gain `H` integrated out with the map (`docs/validation.md`, "The CBC controller's
residual"). The gain, and the size of `H U` against each recording's fundamental of `w2`:"""),
    new_code_cell("""g = fit.control_gain()
for part in ("re", "im"):
    iv = g["gain"][part]
    print(f"H, {part}: {iv['median']:.0f} [{iv['ci90'][0]:.0f}, {iv['ci90'][1]:.0f}] {g['units']}")
rows = ["| recording | control fundamental (mV) | response / fundamental of w2 |", "|---|---:|---:|"]
for name, u in zip(fit.features.names, fit.features.control):
    rows.append(f"| {name} | {1e3 * np.hypot(*u):.2f} | {100 * g['response'][name]:.1f}% |")
display(Markdown("\\n".join(rows)))"""),
    new_markdown_cell("""The diagram: posterior median, 50% and 90% bands of both branches, and (dotted) the 90% band
of a new measurement, which includes the model discrepancy at that μ (small at the recordings,
growing away from them)."""),
    new_code_cell("""display(fit.plot.bifurcation())"""),
    new_markdown_cell("""The phase portraits: 60 posterior orbits over each measured one."""),
    new_code_cell("""display(bh.plotting.plot_phase_portraits(fit, rs))"""),
    new_markdown_cell("""## 3. Leave-one-out: is the fit robust?

Each recording is held out in turn and the model refitted on the other six
(`bh.validation.leave_one_out`, from the recordings: each refit's frame, the orbits' centre and
scale, is built without the recording it predicts).
Two predictions per fold, both from that fold's fit:
* **Bayesian**: posterior median and the 90% band of a new measurement (the posterior predictive,
  with the held-out recording's own standard errors and the model discrepancy at its μ);
* **MAP plug-in**: the nonlinear parameters at the MAP and the map at its conditional mean, with a
  plug-in band from the fitted noise scales only (no parameter uncertainty).

The paper's maximum-likelihood fit ran on the legacy inference core, which is gone; it is not
repeated here. With seven folds the coverage is coarse: the table's third column is the probability
that calibrated 90% bands hold this few held-out recordings or fewer (binomial, as if the folds were
independent). The figure is the paper's Fig. exp_val with bands; the star is the held-out recording
(filled when inside the Bayesian 90% band). The last panel shows the fold of every fold."""),
    new_code_cell("""folds = rs.names[2:4] if FAST else None
loo = bh.validation.leave_one_out(rs, "subcritical", seed=0, settings=settings, folds=folds,
                                  keep_fits=True, progress=False)
rows = ["| method | held-out inside 90% | P(this few or fewer), calibrated bands | mean held-out error | max error | sd of μ_SN over folds | μ_SN range |",
        "|---|---:|---:|---:|---:|---:|---|"]
for s in loo.summary().values():
    rows.append(f"| {s['label']} | {s['coverage']}/{s['n_folds']} | {s['coverage_p']:.3f} | "
                f"{100 * s['mean_relative_error']:.1f}% | "
                f"{100 * s['max_relative_error']:.1f}% | {s['mu_fold_sd']:.3f} m/s | "
                f"{s['mu_fold_range'][0]:.2f}–{s['mu_fold_range'][1]:.2f} |")
display(Markdown("\\n".join(rows)))
rows = ["| held out | μ | measured (mm) | Bayesian median [90%] (mm) | inside | MAP [90% plug-in] (mm) | μ_SN Bayesian [90%] | μ0 Bayesian [90%] |",
        "|---|---:|---:|---|---|---|---|---|"]
for r in loo.table():
    b, m = r["bayes"], r["map"]
    rows.append(f"| {r['file']} | {r['mu']:g} | {1e3 * r['measured']:.1f} | {1e3 * b['median']:.1f} "
                f"[{1e3 * b['ci90'][0]:.1f}, {1e3 * b['ci90'][1]:.1f}] | {'yes' if b['inside'] else 'no'} | "
                f"{1e3 * m['median']:.1f} [{1e3 * m['ci90'][0]:.1f}, {1e3 * m['ci90'][1]:.1f}] | "
                f"{b['mu_fold']['median']:.2f} [{b['mu_fold']['ci90'][0]:.2f}, {b['mu_fold']['ci90'][1]:.2f}] | "
                f"{b['mu0']['median']:.2f} [{b['mu0']['ci90'][0]:.2f}, {b['mu0']['ci90'][1]:.2f}] |")
display(Markdown("\\n".join(rows)))
display(bh.plotting.validation.plot_leave_one_out(loo, feats))"""),
    new_markdown_cell("""### A check without any map: the stable/unstable pairs

Where both LCOs of the normal form `ṙ = β(μ) r + a2 r³ − r⁵` exist, `r_s² + r_u² = a2` and
`r_s² r_u² = −β(μ)`, so `x = (A_s A_u)²/(A_s² + A_u²)² = −β(μ)/a2²`: 1/4 at the fold and 0 at the
Hopf point. A map that is linear at each μ scales both amplitudes alike and leaves `x` as it is, so
the measured pairs test the normal form with no map fitted (the stable amplitude at 15.7 m/s is
interpolated between 15.6 and 16.5 m/s). With the paper's unfolding `β = μ − μ0`, `x` is a straight
line in μ: the line through all three pairs gives μ0, a2 and the fold, and the dashed lines each
leave one pair out and predict it (open markers). The fit uses a curved unfolding `β(μ)` (one more
parameter, `w`), drawn in blue from its posterior."""),
    new_code_cell("""pairs = bh.diagnostics.pair_invariant.pair_invariants(feats)
line = bh.diagnostics.pair_invariant.invariant_line(pairs)
rows = ["| | map-free line (three pairs) | hybrid fit |", "|---|---|---|"]
for name in ("mu0", "a2", "mu_fold"):
    a, b = line.interval(name), fit.interval(name)
    rows.append(f"| {name} | {a.median:.2f} [{a.lo:.2f}, {a.hi:.2f}] | {b.median:.2f} [{b.lo:.2f}, {b.hi:.2f}] |")
for k, held in enumerate(pairs):
    others = [p for i, p in enumerate(pairs) if i != k]
    pred = bh.diagnostics.pair_invariant.invariant_line(others).unstable_amplitude(held.mu, held.stable_amplitude)
    rows.append(f"| without unstable {held.mu:g} m/s | {1e3 * pred.median:.1f} [{1e3 * pred.lo:.1f}, {1e3 * pred.hi:.1f}] mm "
                f"| measured {1e3 * held.unstable_amplitude:.1f} mm |")
display(Markdown("\\n".join(rows)))
display(bh.plotting.pair_invariant.plot_pair_invariant(pairs, fit=fit))"""),
    new_markdown_cell("""The measured `x` falls faster towards the Hopf point than a straight line: from the pairs at 14.9
and 15.7 m/s the straight line predicts too large an unstable orbit at 16.5 m/s, with or without a
map. The curved unfolding bends through the pairs instead, which is why the normal form's own μ0
lies below the straight line's; the rig's μ0 in the table, moved by the discrepancy's twin in μ,
reaches above it."""),
    new_markdown_cell("""## 4. A third channel: the actuator command

"Mapping to other coordinates": once the map is fitted, every measured sample is placed on its
predicted orbit (the nearest point in the frame, which inverts the map along the LCO and gives its
normal-form phase φ), and the actuator command is regressed on the fitted planar position and μ
(`b = [1, μ̃, w1, w2, μ̃w1, μ̃w2, w1², w1w2, w2², w1³, w2³]`): the channel's and the basis' Fourier
coefficients in φ, fitted across recordings by a conjugate Bayesian regression and repeated over
posterior draws of the fit. The bands carry both uncertainties."""),
    new_code_cell("""channel = bh.inference.channels.fit_channel(fit, rs, "actuator", n_draws=40 if FAST else 100)
amp = np.array([np.nanquantile(channel.amplitude(fit, [m], "unstable" if u else "stable", predictive=True)[:, 0],
                               [0.05, 0.95]) for m, u in zip(feats.mu, feats.unstable, strict=True)])
inside = (channel.measured_amplitude >= amp[:, 0]) & (channel.measured_amplitude <= amp[:, 1])
print(f"actuator peak-to-peak inside its 90% band for {inside.sum()}/{inside.size} recordings")
display(bh.plotting.channels.plot_channel(channel, fit))"""),
    new_markdown_cell("""## 5. How fast the oscillations run: frequency and time series

By the rotational symmetry of the normal form the phase speed depends on r and μ only, so each
recording's frequency is one number, `ω_i = Ω(r_i, μ_i)`. The collapsed core fits `Ω` as a
polynomial in `r̃²` and `μ̃` about the mean measured frequency, with its coefficients integrated out
like the map's and a model error σ_ω. Two bands for the frequency: the **curve** band (Ω's
posterior) and the **predictive** band of a new recording (adding σ_ω and the recording's standard
error)."""),
    new_code_cell("""rows = ["| recording | μ (m/s) | measured (Hz) | predictive median [90%] (Hz) | inside |", "|---|---:|---:|---|---|"]
check = fit.frequency_check()
for e, mu in zip(check, feats.mu, strict=True):
    p = e["predicted"]
    rows.append(f"| {e['name']} | {mu:g} | {e['measured_hz']:.4f} | {p['median']:.4f} [{p['ci90'][0]:.4f}, {p['ci90'][1]:.4f}] | "
                f"{'yes' if e['inside_ci90'] else 'no'} |")
display(Markdown("\\n".join(rows)))
print(f"{sum(e['inside_ci90'] for e in check)}/{len(check)} measured frequencies inside their 90% predictive bands")"""),
    new_markdown_cell("""The frequency against airspeed (curve bands shaded, a new recording's band dotted, the
recordings as markers), and the paper's Fig. ts_exp with bands: the first periods of each record,
each predicted orbit traversed at its own frequency from the recording's phase at its first sample."""),
    new_code_cell("""display(fit.plot.frequency())
ts = fit.time_series_bands(rs, n_periods=3.0)
display(bh.plotting.plot_time_series([ts[i] for i in (0, 3, 4, 6)], mu_label="airspeed", mu_units="m/s"))"""),
]

nb = new_notebook(cells=cells, metadata={
    "kernelspec": {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"},
    "language_info": {"name": "python", "version": "3.11.7"},
})
nbformat.write(nb, Path(__file__).parents[1] / "03_wind_tunnel.ipynb")
