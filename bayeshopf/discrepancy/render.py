"""``report.md`` of a discrepancy analysis: Markdown tables of its ``report.json``.

:func:`markdown` renders the report of
:func:`~bayeshopf.discrepancy.analysis.analyse`, with or without calibration;
:func:`stage_rows` is the table of the fit stages of a calibrated report,
shared with the command's printout.
"""

from __future__ import annotations

__all__ = ["STAGE_TITLES", "markdown", "stage_rows", "verdict_probability"]


def verdict_probability(v: dict) -> str:
    """``"probability P"`` of a verdict, and its named model's where that is smaller.

    A verdict's ``probability`` is its class's, shared by every model of the class;
    where the verdict names a term, the model it names has its own
    ``model_probability`` (the class's less its rivals'), the number to read as how
    sure the analysis is of the term it names.
    """
    out = f"probability {v['probability']:.2f}"
    m = v.get("model_probability")
    if m is not None and f"{m:.2f}" != f"{v['probability']:.2f}":
        out += f"; {m:.2f} for the model named"
    return out


def markdown(d: dict) -> str:
    """``report.md`` of a ``report.json`` (with calibration when it has ``"calibration"``)."""
    return _markdown_calibrated(d) if "calibration" in d else _markdown(d)


def _notes(d: dict) -> list[str]:
    """The report's notes as a Markdown section (none without notes)."""
    return ["", "## Notes", ""] + [f"* {n}" for n in d["notes"]] if d["notes"] else []


def _hybrid_markdown(h: dict) -> list[str]:
    lines = ["", "## Bayesian hybrid fit of the recordings", ""]
    for k in ("hopf", "fold"):
        if h.get(k):
            lines.append(f"* {k}: {h[k]['median']:.3f} (90% {h[k]['ci90'][0]:.3f} – "
                         f"{h[k]['ci90'][1]:.3f})")
    s, c = h.get("settings") or {}, h.get("convergence") or {}
    if c.get("method") == "nuts":
        lines.append(f"* NUTS, {s.get('num_chains')} chains × {s.get('num_samples')} draws "
                     f"({s.get('num_warmup')} warm-up): largest R̂ {c['r_hat']:.3f} "
                     f"(limit {c['r_hat_limit']}), smallest bulk ESS {c['ess_bulk']:.0f} "
                     f"(limit {c['ess_limit']}), {c['divergences']} divergences"
                     if c.get("r_hat") is not None else
                     f"* NUTS, {s.get('num_chains')} chain(s): R̂ not computed")
    elif c.get("method") == "importance" and c.get("pareto_k") is not None:
        lines.append(f"* importance sampling from the MAP's Laplace approximation: Pareto k̂ "
                     f"{c['pareto_k']:.2f}, {c['ess']:.0f} effective draws")
    elif c.get("method") == "svi":
        lines.append(f"* SVI, {s.get('svi_steps')} steps: ELBO "
                     + ("at a plateau" if c.get("elbo_plateau") else "still falling"))
    if c:
        lines.append(f"* converged: {'yes' if c.get('ok') else '**no**'}")
    for w in h.get("warnings", []):
        lines.append(f"* warning: {w}")
    return lines


def _markdown(d: dict) -> str:
    v = d["verdict"]
    lines = [f"# Discrepancy analysis: {d['simulator']}", "", f"**Verdict ({v['kind']}).** "
             f"{v['sentence']}", "", "## Candidates (most probable first)", "",
             "| model | probability | coefficient median | 90% interval | units |",
             "|---|---:|---:|---|---|"]
    for c in d["candidates"][:8]:
        co = c["coefficient"]
        if co is None:
            lines.append(f"| none | {c['probability']:.3g} | | | |")
        else:
            lines.append(f"| {c['name']} | {c['probability']:.3g} | {co['median']:.4g} | "
                         f"{co['ci90'][0]:.4g} – {co['ci90'][1]:.4g} | {co['units']} |")
    fb, fa = d["fit"]["before"], d["fit"]["after"]

    def g(x, pct=False):
        if x is None:
            return "–"
        return f"{100 * x:.2f}%" if pct else f"{x:.4g}"

    def ci(v):
        return "" if not v else f" (90% {v[0]:.4g} – {v[1]:.4g})"

    lines += ["", f"## Fit before and after adding {fa['term']}", "",
              "| quantity | before | after |", "|---|---:|---:|"]
    for c in fb["rms_orbit_error"]:
        lines.append(f"| RMS orbit error {c} | {g(fb['rms_orbit_error'][c], True)} | "
                     f"{g(fa['rms_orbit_error'][c], True)} |")
        lines.append(f"| amplitude error {c} | {g(fb['amplitude_error'][c], True)} | "
                     f"{g(fa['amplitude_error'][c], True)} |")
    lines += [f"| frequency error | {g(fb['frequency_error'], True)} | "
              f"{g(fa['frequency_error'], True)} |",
              f"| Hopf point | {g(fb['hopf'])} | {g(fa['hopf'])}{ci(fa.get('hopf_ci90'))} |",
              f"| fold | {g(fb['fold'])} | {g(fa['fold'])}{ci(fa.get('fold_ci90'))} |",
              f"| chi² / features | {fb['chi2']:.1f} / {fb['dof']} | {fa['chi2']:.1f} / "
              f"{fa['dof']} |"]
    if fa.get("elpd_difference") is not None:
        lines.append(f"| ELPD after − before | | {fa['elpd_difference']:.1f} ± "
                     f"{fa['elpd_difference_se']:.1f} |")
    if d.get("hybrid"):
        lines += _hybrid_markdown(d["hybrid"])
    lines += ["", "## Where the simulator disagrees (before)", ""]
    lines += _mismatch_table(d["mismatch"]["by_recording"]) + _notes(d)
    return "\n".join(lines) + "\n"


def _mismatch_table(rows: list[dict]) -> list[str]:
    """Markdown table of :func:`~bayeshopf.discrepancy.locate.locate`'s rows."""
    lines = ["| recording | μ | branch | worst channel | amplitude error | frequency error | "
             "phase range (°) | where | phase to reference: simulated − measured (°) | "
             "significant |", "|---|---:|---|---|---:|---:|---|---|---|---|"]
    for r in rows:
        if r["channel"] is None:
            lines.append(f"| {r['file']} | {r['mu']:g} | {r['branch']} | – | – | – | – | "
                         f"{r['where']} | – | yes |")
            continue
        lines.append(f"| {r['file']} | {r['mu']:g} | {r['branch']} | {r['channel']} | "
                     f"{100 * r['amplitude_error']:.2f}% | {100 * r['frequency_error']:.3f}% | "
                     f"{r['phase_range'][0]:.0f}–{r['phase_range'][1]:.0f} | {r['where']} | "
                     + ", ".join(f"{c} {v['phase_to_reference_deg']['error']:+.1f}"
                                 for c, v in r["channels"].items()
                                 if v.get("phase_to_reference_deg")) + " | "
                     f"{'yes' if r['significant'] else 'no'} |")
    return lines


#: Column titles of the fit stages with calibration.
STAGE_TITLES = {"before": "nominal", "calibrated": "calibrated", "after": "calibrated + term"}


def _pct_or_dash(x, digits: int = 2) -> str:
    return "–" if x is None else f"{100 * x:.{digits}f}%"


def _num_or_dash(x) -> str:
    return "–" if x is None else f"{x:.4g}"


def stage_rows(d: dict) -> tuple[list[str], list[tuple[str, list[str]]]]:
    """The fit stages of a calibrated report as a table: titles and ``(quantity, cells)`` rows.

    Args:
        d: ``report.json`` of an analysis with calibration.

    Returns:
        The stage titles (``nominal``, ``calibrated``, ``calibrated + <term>``
        where a term was added) and, per quantity, one formatted cell per stage:
        amplitude and RMS orbit error per channel, frequency error, Hopf point,
        fold, χ² / degrees of freedom and recordings without an orbit.
    """
    fit = d["fit"]
    keys = [k for k in STAGE_TITLES if k in fit]
    titles = [STAGE_TITLES[k] if k != "after" else f"calibrated + {fit['after']['term']}"
              for k in keys]
    st = [fit[k] for k in keys]
    rows = []
    for c in st[0]["amplitude_error"]:
        rows.append((f"amplitude error {c}", [_pct_or_dash(s["amplitude_error"][c]) for s in st]))
    for c in st[0]["rms_orbit_error"]:
        rows.append((f"RMS orbit error {c}", [_pct_or_dash(s["rms_orbit_error"][c]) for s in st]))
    rows += [("frequency error", [_pct_or_dash(s["frequency_error"], 3) for s in st]),
             ("Hopf point", [_num_or_dash(s["hopf"]) for s in st]),
             ("fold", [_num_or_dash(s["fold"]) for s in st]),
             ("chi² / dof", [f"{s['chi2']:.4g} / {s['dof']:.4g}" for s in st]),
             ("recordings without orbit",
              [str(len(s["recordings_without_orbit"])) for s in st])]
    return titles, rows


def _bayes_markdown(v: dict) -> list[str]:
    """Bayes factors of the classes apart from the prior odds, and the prior-scale band."""
    bf = v.get("bayes_factors")
    if not bf:
        return []
    lines = ["", "## Bayes factors (apart from the prior odds)", "",
             "| class | prior probability | log B against nothing wrong | "
             "log B against parameters off |", "|---|---:|---:|---:|"]
    for c, row in bf["log_bayes_factor"].items():
        cells = [f"{row[o]:.1f}" if o in row else "–" for o in ("none", "parameters off")]
        lines.append(f"| {c} | {bf['prior'][c]:.3g} | " + " | ".join(cells) + " |")
    bands = v.get("prior_sensitivity") or []
    lines += [""] if bands else []
    for b in bands:
        vals = [b["log_bayes_factor"], *b["scales"].values()]
        fs = [float(k) for k in b["scales"]]
        lines.append(f"* {b['model']} against parameters off: log B "
                     f"{b['log_bayes_factor']:.1f} [{min(vals):.1f}, {max(vals):.1f}] over "
                     f"prior scales ×{min(fs):g}–×{max(fs):g} ({b['evidence']})")
    return lines


def _markdown_calibrated(d: dict) -> str:
    """``report.md`` of an analysis with calibration."""
    v = d["verdict"]
    prob = f", {verdict_probability(v)}" if v.get("probability") is not None else ""
    lines = [f"# Discrepancy analysis: {d['simulator']}", "",
             f"**Verdict ({v['kind']}{prob}).** {v['sentence']}", "",
             f"## Uncertain parameters ({d['parameters']['model']})", "",
             "| parameter | units | nominal | median | 90% interval | shift | tolerance | off |",
             "|---|---|---:|---:|---|---:|---:|---|"]
    for p in d["parameters"]["table"]:
        lines.append(f"| {p['name']} | {p['units']} | {p['nominal']:.5g} | {p['median']:.5g} | "
                     f"{p['ci90'][0]:.5g} – {p['ci90'][1]:.5g} | {100 * p['shift']:+.2f}% | "
                     f"±{100 * p.get('tolerance', 0.0):.3g}% | "
                     f"{'**yes**' if p['off'] else 'no'} |")
    lines += ["", "## Models (most probable terms)", "",
              "| model | probability | log evidence | coefficient median | 90% interval | "
              "units |",
              "|---|---:|---:|---:|---|---|"]
    for m in d["models"][:7]:
        co = m["coefficient"]
        if m.get("coefficients"):
            cs = m["coefficients"]
            lines.append(f"| {m['label']}{'' if m['refined'] else ' (screened)'} | "
                         f"{m['probability']:.3g} | {m['log_evidence']:.1f} | "
                         + "; ".join(f"{c['median']:.4g}" for c in cs) + " | "
                         + "; ".join(f"{c['ci90'][0]:.4g} – {c['ci90'][1]:.4g}" for c in cs)
                         + " | " + "; ".join(c["units"] for c in cs) + " |")
        elif co is None:
            lines.append(f"| {m['label']} | {m['probability']:.3g} | "
                         f"{m['log_evidence']:.1f} | | | |")
        else:
            lines.append(f"| {m['label']}{'' if m['refined'] else ' (screened)'} | "
                         f"{m['probability']:.3g} | {m['log_evidence']:.1f} | {co['median']:.4g} | "
                         f"{co['ci90'][0]:.4g} – {co['ci90'][1]:.4g} | {co['units']} |")
    lines += _bayes_markdown(v)
    titles, rows = stage_rows(d)
    lines += ["", "## Fit: " + ", ".join(titles), "",
              "| quantity | " + " | ".join(titles) + " |",
              "|---|" + "---:|" * len(titles)]
    lines += [f"| {q} | " + " | ".join(cells) + " |" for q, cells in rows]
    for k in d["fit"]:
        if d["fit"][k].get("note"):
            lines.append(f"\n{STAGE_TITLES.get(k, k)}: {d['fit'][k]['note']}")
    if d.get("hybrid"):
        lines += _hybrid_markdown(d["hybrid"])
    rem = d["mismatch"]["after"]
    lines += ["", f"## What remains ({rem['model']})", "", rem["sentence"], ""]
    lines += _mismatch_table(rem["by_recording"])
    lines += ["", "## Where the nominal simulator disagrees", ""]
    lines += _mismatch_table(d["mismatch"]["by_recording"]) + _notes(d)
    return "\n".join(lines) + "\n"
