"""A saved fit's ``summary.json`` as ``fit`` and ``demo`` print it: table or JSON.

The summary's intervals are keyed by their mass (``ci90``: ``[lo, hi]``); the
table writes each through :func:`bayeshopf.cli._format.format_interval` and the
JSON through :mod:`bayeshopf.cli._schema`.
"""

from __future__ import annotations

import textwrap

from bayeshopf._format import format_interval, format_number, format_values
from bayeshopf.cli import _schema

#: The normal form's parameters in the order printed.
PARAMETERS = ("mu0", "a2", "a4", "mu_fold", "w_unfold")
#: Those measured in units of μ.
MU_PARAMETERS = ("mu0", "mu_fold")


def _key(level: float) -> str:
    """The summary's key of a ``level`` interval: ``ci90`` for 0.9."""
    return f"ci{round(100 * level)}"


def print_table(summary: dict, truth: dict | None = None) -> None:
    """The parameters, the recordings against their predicted bands, checks and warnings."""
    u, au = summary["mu_units"], summary["amplitude_units"]
    curved = summary.get("unfolding") == "curved"
    if truth and curved:  # a2 of a curved unfolding is not the linear one's 2√(μ0 − μ_SN)
        truth = {**truth, "a2": None}
    print(f"criticality: {summary['criticality']}")
    evidence = summary.get("criticality_evidence")
    if evidence and "statement" in evidence:
        print(textwrap.fill(evidence["statement"], 88))
    level = summary.get("ci", 0.9)
    key, pct = _key(level), f"{100 * level:g}%"
    print(f"{'':8s} {'median':>10s} {pct + ' interval':>24s}" + (f" {'true':>10s}" if truth
                                                                   else ""))
    for k in PARAMETERS:
        v = summary.get(k)
        if v is None:
            continue
        if k == "a2" and summary.get("a4") is not None:
            print(f"{k:8s} {format_number(v['median']):>10s}   (fixed by the supercritical "
                  "gauge; a4 is free)")
            continue
        lo, hi = v[key]
        m, a, b = format_interval(v["median"], lo, hi)
        t = ("" if not truth or truth.get(k) is None
             else f" {format_values([truth[k]], hi - lo)[0]:>10s}")
        unit = f" {u}" if k in MU_PARAMETERS else ""
        print(f"{k:8s} {m:>10s} [{a:>10s}, {b:>10s}]{t}{unit}")
    if curved:
        print("(curved unfolding β(μ) = (exp(b(μ−μ0)) − 1)/b, w = b(μ0 − μ_fold); a2 is its "
              "cubic coefficient, β(μ_fold) = −a2²/4)")
    own = summary.get("normal_form_points")
    if own:
        shown = {k: format_interval(v["median"], *v[key]) for k, v in own.items()}
        parts = [f"{k} {m} [{a}, {b}]" for k, (m, a, b) in shown.items()]
        kappa = summary.get("settings", {}).get("mu_discrepancy")
        phi = summary.get("settings", {}).get("mu_discrepancy_floor", 0.0)
        print(textwrap.fill(
            f"(mu0 and mu_fold are the rig's: the normal form's own points, {'; '.join(parts)} "
            f"{u}, moved by the discrepancy in μ, κ = {kappa:g}, φ = {phi:g}; "
            "docs/model_discrepancy.md)", 88))
    print()
    print(f"{'recording':28s} {'mu':>8s} {'branch':>9s} {'measured':>10s} "
          f"{'predicted (' + pct + ')':>30s}  [{au}]")
    for r in summary["recordings"]:
        _print_row(r, r["amplitude"], r["predicted"], key, r[f"inside_{key}"])
    ppc = summary["ppc"]
    print(f"\n{ppc[f'amplitudes_inside_{key}']}/{ppc['n_recordings']} measured amplitudes "
          f"inside their {pct} predictive intervals; "
          f"{100 * ppc[f'coefficients_inside_{key}']:.0f}% of the Fourier coefficients inside "
          "theirs.")
    if ppc.get("frequencies_inside_ci90") is not None:
        freqs = [r["frequency_predicted"] for r in summary["recordings"]]
        lo = min(f["ci90"][0] for f in freqs if f)
        hi = max(f["ci90"][1] for f in freqs if f)
        print(f"{ppc['frequencies_inside_ci90']}/{ppc['n_recordings']} measured frequencies "
              f"inside their 90% predictive intervals (Ω(r, μ); bands span {lo:.4g}–{hi:.4g} Hz).")
    _print_nuts_check(summary)
    _print_leave_one_out(summary)
    _print_diagnostics(summary)


def _print_row(r: dict, measured: float, predicted: dict, key: str, inside: bool) -> None:
    """One recording's line of a table: measured amplitude against its predicted band."""
    lo, hi = predicted[key]
    x, m, a, b = format_values([measured, predicted["median"], lo, hi], hi - lo)
    print(f"{r['file'][:28]:28s} {r['mu']:8g} {r['branch']:>9s} {x:>10s} "
          f"{m:>10s} [{a:>8s}, {b:>8s}]{'' if inside else '  OUTSIDE'}")


def _print_leave_one_out(summary: dict) -> None:
    """The held-out table of ``fit --leave-one-out``, when the summary has one."""
    loo = summary.get("leave_one_out")
    if loo is None:
        return
    au = summary["amplitude_units"]
    print(f"\nleave-one-out (each recording predicted by a fit without it; 90% predictive "
          f"bands):\n{'held out':28s} {'mu':>8s} {'branch':>9s} {'measured':>10s} "
          f"{'predicted (90%)':>30s}  [{au}]")
    for r in loo["folds"]:
        _print_row(r, r["measured"], r["bayes"], "ci90", r["bayes"]["inside"])
    c, s = loo["check"], loo["summary"]
    print(f"{c['inside_ci90']}/{c['n_folds']} held-out amplitudes inside their bands (P = "
          f"{c['coverage_p']:.2g} if calibrated); mean band width {s['mean_band_width']:.4g} {au}"
          + ("" if s.get("log_predictive_density") is None else
             f"; log predictive density of the held-out amplitudes "
             f"{s['log_predictive_density']:.4g}"))
    if c.get("held_out_scale") is not None:
        print(f"model error away from the recordings: prior scale {c['prior_scale']}; the "
              f"held-out residuals' own {c['held_out_scale']:.2g} (read off these recordings)")


def _print_diagnostics(summary: dict) -> None:
    """Convergence line and one warning line per failed check."""
    diag = summary.get("diagnostics")
    if not diag:
        return
    post = diag.get("posterior", {})
    if post.get("method") == "nuts" and post.get("sites"):
        worst = max(v["r_hat"] for v in post["sites"].values())
        ess = min(v["ess_bulk"] for v in post["sites"].values())
        draws = (f" × {post['draws_per_chain']} draws" if "draws_per_chain" in post else "")
        print(f"\nNUTS, {post['chains']} chains{draws}: R̂ ≤ {worst:.3f}, bulk ESS ≥ {ess:.0f} "
              f"for {', '.join(post['sites'])}; {post['divergences']} divergences")
    elif post.get("method") == "importance" and "pareto_k" in post:
        print(f"\nimportance sampling from the MAP's Laplace approximation: Pareto k̂ "
              f"{post['pareto_k']:.2f} (at most {post['k_max']}), {post['ess']:.0f} effective "
              f"of {post['proposals']} draws")
    errs = [e["relative"] for e in diag["fit"]["orbit_error"] if e["relative"] is not None]
    if errs:
        print(f"orbit errors (posterior-median orbit against the measured mean orbit): "
              f"{100 * min(errs):.1f}–{100 * max(errs):.1f}% of the orbit size")
    disc = diag["fit"].get("discrepancy")
    if disc:
        eta = disc["eta"]
        lo, hi = next(v for k, v in eta.items() if k.startswith("ci"))
        m, a, b = format_interval(100 * eta["median"], 100 * lo, 100 * hi)
        print(f"model discrepancy (smooth, of the fundamental): {m}% [{a}, {b}] of the orbit "
              "size; it is in the posterior, so the intervals and bands include it")
    away = diag["fit"].get("extrapolation_scale")
    if away:
        why = "as set" if away["chosen_by"] == "setting" else "the model without the discrepancy"
        print(f"bands of new measurements away from the recordings: model-error scale "
              f"{away['scale']:.2g} ({why})")
    for w in diag.get("warnings", []):
        # the library names the function; on the command line it is a flag
        w = w.replace("by leave-one-out: bayeshopf.validation.leave_one_out",
                      "with fit --leave-one-out")
        print(f"warning: {w}")


def _print_nuts_check(summary: dict) -> None:
    """One line per site on the NUTS check, when the summary has one."""
    chk = summary.get("nuts_check")
    if chk is None:
        return
    method = {"importance": "importance sampling"}.get(
        summary.get("diagnostics", {}).get("posterior", {}).get("method"), "SVI")
    for k, v in chk["sites"].items():
        lo, hi = v["reference"]
        a, b, c, d = format_values([lo, hi, *v["other"]], min(hi - lo, v["other"][1]
                                                              - v["other"][0]))
        print(f"NUTS check {k}: NUTS [{a}, {b}], {method} [{c}, {d}]: ends differ by "
              f"{100 * v['end_gap_fraction']:.0f}% of NUTS's width "
              f"({'agree' if v['agree'] else 'DISAGREE'})")


def summary_json(command: str, summary: dict, out: str, truth: dict | None = None) -> dict:
    """The fit's results in the command line's JSON schema (:mod:`bayeshopf.cli._schema`)."""
    level = summary.get("ci", 0.9)
    key = _key(level)
    params = {k: _schema.from_summary(summary[k], level) for k in PARAMETERS
              if summary.get(k) is not None and key in summary[k]}
    recordings = [{"file": r["file"], "mu": r["mu"], "branch": r["branch"],
                   "measured": r["amplitude"],
                   "predicted": _schema.from_summary(r["predicted"], level),
                   "inside": bool(r[f"inside_{key}"])} for r in summary["recordings"]]
    ppc = summary["ppc"]
    checks = {"n_recordings": ppc["n_recordings"],
              "amplitudes_inside": ppc[f"amplitudes_inside_{key}"],
              "coefficients_inside": ppc[f"coefficients_inside_{key}"]}
    warnings = list((summary.get("diagnostics") or {}).get("warnings", []))
    extra = {} if truth is None else {"truth": dict(truth)}
    return _schema.document(command, ci=level,
                            units={"mu": summary["mu_units"],
                                   "amplitude": summary["amplitude_units"], "frequency": "Hz"},
                            out=str(out), criticality=summary["criticality"],
                            parameters=params, recordings=recordings, checks=checks,
                            warnings=warnings, **extra)
