"""``bayeshopf`` console script.

Errors in the input or the output folder are reported as one line on stderr
(which file or field, what was expected, what was found) with exit code 2 and
no traceback; ``--debug`` shows the traceback of unexpected errors.
"""

from __future__ import annotations

import argparse
import json
import sys
import textwrap
import time
import traceback
from pathlib import Path

from bayeshopf.cli import discrepancy as _discrepancy
from bayeshopf.cli import simulate as _simulate

EXIT_USAGE = 2
EXIT_ERROR = 1


def _add_fit_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--force", action="store_true",
                   help="write into a non-empty output folder (replaces bayeshopf's files only)")
    p.add_argument("--fast", action="store_true",
                   help="short optimisation runs (smoke tests, CI); intervals less converged")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--nuts-check", action="store_true",
                   help="with --inference svi: also run NUTS on the same model and report "
                   "whether SVI's 90%% intervals match NUTS's (summary.json 'nuts_check')")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument("--inference", choices=("nuts", "svi"), default="nuts",
                   help="posterior: NUTS (default) or SVI with a full-rank Gaussian guide")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    ap = argparse.ArgumentParser(
        prog="bayeshopf",
        description="Bayesian hybrid normal-form models of Hopf bifurcations from "
        "limit-cycle-oscillation recordings.",
    )
    ap.add_argument("--debug", action="store_true", help="show tracebacks of internal errors")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    d = sub.add_parser("demo", help="fit simulated recordings of the 3-DOF aeroelastic aerofoil",
                       description="Simulate stable and unstable LCO recordings of the paper's "
                       "3-DOF aeroelastic aerofoil in-process (4 + 4 orbits, 1%% noise, sensor "
                       "offsets; no download), fit the model blind, print the Hopf point, a2 and "
                       "the fold with 90%% intervals next to the simulator's own values, and "
                       "write the figures with the true bifurcation diagram.")
    d.add_argument("--out", default="bayeshopf-demo", help="output folder (default bayeshopf-demo)")
    _add_fit_options(d)

    f = sub.add_parser("fit", help="fit recordings in a folder",
                       description="Fit a folder of CBC .mat files or an interchange folder "
                       "(manifest.csv + one CSV per recording). Writes DIR/summary.json, "
                       "DIR/posterior.nc, DIR/model.json and DIR/figures/*.png.")
    f.add_argument("data", help="folder of .mat files, or interchange folder")
    f.add_argument("--out", required=True, help="output folder (refused if not empty)")
    f.add_argument("--criticality", choices=("sub", "super", "auto"), default="sub",
                   help="normal form: subcritical (default), supercritical, or auto "
                   "(decided from the data)")
    f.add_argument("--exact-loo", action="store_true",
                   help="with --criticality auto: refit each model without every recording "
                   "whose PSIS Pareto k exceeds 0.7 and use its exact leave-one-out density "
                   "(one fit per refit)")
    f.add_argument("--planar", nargs=2, metavar=("Z1", "Z2"), default=None,
                   help="channels of the planar pair (default: the first two)")
    _add_fit_options(f)

    p = sub.add_parser("predict", help="amplitude at μ from a saved fit",
                       description="Amplitude median and 90%% interval at μ on a branch, "
                       "from a folder written by 'bayeshopf fit' or 'bayeshopf demo'.")
    p.add_argument("fit_dir", help="folder written by 'bayeshopf fit'")
    p.add_argument("--mu", type=float, required=True, help="value of the bifurcation parameter")
    p.add_argument("--branch", choices=("stable", "unstable"), default="stable")
    p.add_argument("--predictive", action="store_true",
                   help="band of a new measurement instead of the curve (adds the model "
                   "error, which grows away from the recordings, and the measurement error)")
    p.add_argument("--json", action="store_true", help="print JSON")

    _simulate.add_parser(sub)
    _discrepancy.add_parser(sub)
    return ap


def _print_table(summary: dict, truth: dict | None = None) -> None:
    u, au = summary["mu_units"], summary["amplitude_units"]
    curved = summary.get("unfolding") == "curved"
    if truth and curved:  # a2 of a curved unfolding is not the linear one's 2√(μ0 − μ_SN)
        truth = {**truth, "a2": None}
    print(f"criticality: {summary['criticality']}")
    evidence = summary.get("criticality_evidence")
    if evidence and "statement" in evidence:
        print(textwrap.fill(evidence["statement"], 88))
    hdr = f"{'':8s} {'median':>10s} {'90% interval':>24s}" + (f" {'true':>10s}" if truth else "")
    print(hdr)
    for k in ("mu0", "a2", "a4", "mu_fold", "w_unfold"):
        v = summary.get(k)
        if v is None:
            continue
        if k == "a2" and summary.get("a4") is not None:
            print(f"{k:8s} {v['median']:10.4g}   (fixed by the supercritical gauge; a4 is free)")
            continue
        t = "" if not truth or truth.get(k) is None else f" {truth[k]:10.4g}"
        unit = "" if k in ("a2", "a4", "w_unfold") else f" {u}"
        print(f"{k:8s} {v['median']:10.4g} [{v['ci90'][0]:10.4g}, {v['ci90'][1]:10.4g}]{t}{unit}")
    if curved:
        print("(curved unfolding β(μ) = (exp(b(μ−μ0)) − 1)/b, w = b(μ0 − μ_fold); a2 is its "
              "cubic coefficient, β(μ_fold) = −a2²/4)")
    print()
    print(f"{'recording':28s} {'mu':>8s} {'branch':>9s} {'measured':>10s} "
          f"{'predicted (90%)':>30s}  [{au}]")
    for r in summary["recordings"]:
        p = r["predicted"]
        flag = "" if r["inside_ci90"] else "  OUTSIDE"
        print(f"{r['file'][:28]:28s} {r['mu']:8.4g} {r['branch']:>9s} {r['amplitude']:10.4g} "
              f"{p['median']:10.4g} [{p['ci90'][0]:8.4g}, {p['ci90'][1]:8.4g}]{flag}")
    ppc = summary["ppc"]
    print(f"\n{ppc['amplitudes_inside_ci90']}/{ppc['n_recordings']} measured amplitudes inside "
          f"their 90% predictive intervals; {100 * ppc['coefficients_inside_ci90']:.0f}% of the "
          "Fourier coefficients inside theirs.")
    if ppc.get("frequencies_inside_ci90") is not None:
        freqs = [r["frequency_predicted"] for r in summary["recordings"]]
        lo = min(f["ci90"][0] for f in freqs if f)
        hi = max(f["ci90"][1] for f in freqs if f)
        print(f"{ppc['frequencies_inside_ci90']}/{ppc['n_recordings']} measured frequencies "
              f"inside their 90% predictive intervals (Ω(r, μ); bands span {lo:.4g}–{hi:.4g} Hz).")
    _print_nuts_check(summary)
    _print_diagnostics(summary)


def _print_diagnostics(summary: dict) -> None:
    """Convergence line and one warning line per failed check."""
    diag = summary.get("diagnostics")
    if not diag:
        return
    post = diag.get("posterior", {})
    if post.get("method") == "nuts" and post.get("sites"):
        worst = max(v["r_hat"] for v in post["sites"].values())
        ess = min(v["ess_bulk"] for v in post["sites"].values())
        print(f"\nNUTS, {post['chains']} chains: R̂ ≤ {worst:.3f}, bulk ESS ≥ {ess:.0f} for "
              f"{', '.join(post['sites'])}; {post['divergences']} divergences")
    errs = [e["relative"] for e in diag["fit"]["orbit_error"] if e["relative"] is not None]
    if errs:
        print(f"orbit errors (posterior-median orbit against the measured mean orbit): "
              f"{100 * min(errs):.1f}–{100 * max(errs):.1f}% of the orbit size")
    for w in diag.get("warnings", []):
        print(f"warning: {w}")


def _print_nuts_check(summary: dict) -> None:
    """One line on the NUTS check, when the summary has one."""
    chk = summary.get("nuts_check")
    if chk is None:
        return
    for k, v in chk["sites"].items():
        lo, hi = v["reference"]
        print(f"NUTS check {k}: NUTS [{lo:.4g}, {hi:.4g}], SVI [{v['other'][0]:.4g}, "
              f"{v['other'][1]:.4g}]: ends differ by {100 * v['end_gap_fraction']:.0f}% of "
              f"NUTS's width ({'agree' if v['agree'] else 'DISAGREE'})")


def _run_hybrid(rs, criticality, args, out, truth=None, extra=None):
    """``fit``/``demo``: :func:`~bayeshopf.posterior.fit_hybrid` (or ``fit_auto``), saved."""
    from dataclasses import replace

    from bayeshopf import report
    from bayeshopf.errors import FitError
    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.posterior import fit_hybrid

    if getattr(args, "nuts_check", False) and args.inference != "svi":
        raise FitError("--nuts-check compares SVI with NUTS and needs --inference svi; got "
                       "--inference nuts (the default), whose R̂ and ESS are reported anyway")
    report.check_output_folder(out, args.force)
    progress = not args.quiet
    t0 = time.perf_counter()
    settings = CollapsedSettings.fast() if args.fast else CollapsedSettings()
    settings = replace(settings, inference=args.inference)
    if criticality == "auto":
        from bayeshopf.posterior import fit_auto

        post, evidence = fit_auto(rs, seed=args.seed, settings=settings, progress=progress,
                                  exact_loo=getattr(args, "exact_loo", False))
        extra = {**(extra or {}), "criticality_evidence": evidence}
    else:
        post = fit_hybrid(rs, criticality, seed=args.seed, settings=settings, progress=progress)
    if getattr(args, "nuts_check", False):
        from bayeshopf.inference.collapsed import compare_with_nuts

        extra = {**(extra or {}), "nuts_check": compare_with_nuts(post, seed=args.seed,
                                                                  progress=progress)}
    ppc = post.ppc()
    figures = None
    if not args.no_figures:
        from bayeshopf.plotting import plot_all

        def figures(folder):
            return plot_all(post, rs, folder, truth=truth, zoom=truth is not None)

    report.save_hybrid(post, out, force=args.force, figures=figures, ppc=ppc,
                       extra_summary=extra)
    summary = json.loads((Path(out) / report.SUMMARY).read_text())
    summary["total_s"] = time.perf_counter() - t0
    return summary


def cmd_demo(args) -> int:
    """``bayeshopf demo``: the 3-DOF aerofoil of the paper's Section 4.2, fitted blind.

    The recordings come from :func:`bayeshopf.simulators.truth.flutter_experiment`
    (``--fast``: shorter records and :meth:`CollapsedSettings.fast`); the truth printed
    next to the intervals is the simulator's: the Hopf point from the Jacobian,
    the fold from the continuation of the periodic orbits, and
    ``a2 = 2√(μ0 − μ_SN)``, the normal form's a2 with that fold.
    """
    from bayeshopf.simulators.truth import flutter_experiment

    rs, truth = flutter_experiment(seed=args.seed, fast=args.fast)
    summary = _run_hybrid(rs, "subcritical", args, args.out, truth=truth,
                       extra={"truth": truth.to_dict()})
    print(f"bayeshopf demo: {len(rs)} simulated recordings ({int(rs.is_unstable.sum())} "
          "unstable, by control-based continuation) of the 3-DOF aeroelastic aerofoil "
          f"(Lee, Barton & Renson, Section 4.2), {100 * truth.noise:g}% noise, sensor offsets; "
          "'true' is the simulator's continuation\n")
    _print_table(summary, truth.values())
    print(f"\nwrote {args.out}/summary.json, posterior.nc, model.json and figures/ "
          f"in {summary['total_s']:.0f} s")
    return 0


def cmd_fit(args) -> int:
    """``bayeshopf fit``."""
    from bayeshopf.data import load_recordings

    crit = {"sub": "subcritical", "super": "supercritical", "auto": "auto"}[args.criticality]
    if args.exact_loo and crit != "auto":
        from bayeshopf.errors import FitError

        raise FitError(f"--exact-loo compares the two normal forms and needs --criticality "
                       f"auto; got --criticality {args.criticality}")
    rs = load_recordings(args.data, planar=tuple(args.planar) if args.planar else None)
    summary = _run_hybrid(rs, crit, args, args.out)
    _print_table(summary)
    print(f"\nwrote {args.out}/summary.json, posterior.nc, model.json and figures/ "
          f"in {summary['total_s']:.0f} s")
    return 0


def cmd_predict(args) -> int:
    """``bayeshopf predict``."""
    from bayeshopf.report import load_fit

    saved = load_fit(args.fit_dir)
    iv = saved.predict(args.mu, args.branch, predictive=args.predictive)
    p = saved.p_exists(args.mu, args.branch)
    freq = saved.frequency(args.mu, args.branch, args.predictive)
    if args.json:
        out = {"mu": args.mu, "branch": args.branch, "amplitude": iv.to_json(),
               "p_exists": p, "units": saved.summary.get("amplitude_units", "")}
        if freq is not None:
            out["frequency_hz"] = freq.to_json()
        print(json.dumps(out))
    else:
        u = saved.summary.get("amplitude_units", "")
        print(f"{args.branch} LCO at μ = {args.mu:g} {saved.summary.get('mu_units', '')}: "
              f"amplitude {iv.median:.4g} {u}, 90% interval [{iv.lo:.4g}, {iv.hi:.4g}] {u} "
              f"(branch exists in {100 * p:.0f}% of posterior draws)")
        if freq is not None:
            print(f"frequency {freq.median:.4g} Hz, 90% interval [{freq.lo:.4g}, {freq.hi:.4g}] Hz")
    return 0


COMMANDS = {"demo": cmd_demo, "fit": cmd_fit, "predict": cmd_predict, "simulate": _simulate.run,
            "discrepancy": _discrepancy.run}


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit code."""
    args = build_parser().parse_args(argv)
    from bayeshopf.errors import BayesHopfError

    try:
        from bayeshopf.inference.cache import enable_compilation_cache, single_thread_eigen

        single_thread_eigen()       # before any JAX work: XLA's Eigen pool stalls on CPU
        enable_compilation_cache()  # before any JAX work, so every compilation is cached
        return COMMANDS[args.command](args)
    except BayesHopfError as e:
        print(f"bayeshopf {args.command}: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"bayeshopf {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # one line unless --debug
        if args.debug:
            traceback.print_exc()
        else:
            print(f"bayeshopf {args.command}: internal error: {type(e).__name__}: "
                  f"{str(e).splitlines()[0] if str(e) else ''} (rerun with --debug for details)",
                  file=sys.stderr)
        return EXIT_ERROR


if __name__ == "__main__":
    sys.exit(main())
