"""``bayeshopf`` console script.

Errors in the input or the output folder are reported as one line on stderr
(which file or field, what was expected, what was found) with exit code 2 and
no traceback; ``--debug`` shows the traceback of unexpected errors.
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import sys
import textwrap
import time
import traceback
from pathlib import Path

from bayeshopf.cli import design as _next
from bayeshopf.cli import discrepancy as _discrepancy
from bayeshopf.cli import simulate as _simulate

EXIT_USAGE = 2
EXIT_ERROR = 1

#: Published data sets of ``fit --dataset`` and ``download``.
DATASETS = ("flutter_cbc",)


def _version() -> str:
    from bayeshopf import __version__

    return __version__


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
    p.add_argument("--ci", type=float, default=0.9,
                   help="probability mass of the printed and saved intervals and of the "
                   "figures' outer band (default 0.9; the convergence checks stay at 90%%)")
    p.add_argument("--inference", choices=("nuts", "svi"), default="nuts",
                   help="posterior: NUTS (default) or SVI with a full-rank Gaussian guide")
    p.add_argument("--extrapolation-scale", type=float, default=None, metavar="S",
                   help="half-normal scale of the model error away from the recordings, in "
                   "log orbit size (default: per posterior draw 0.1, or 0.7 where the fit's "
                   "relative model error is above 2%%; none with --discrepancy): it widens "
                   "new measurements' bands between and beyond the recordings only")
    p.add_argument("--discrepancy", action="store_true",
                   help="fit with the model discrepancy, a Gaussian process over the diagram "
                   "on the orbits' fundamental whose scale is sampled with the Hopf point and "
                   "the fold (docs/model_discrepancy.md; not yet the default)")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    ap = argparse.ArgumentParser(
        prog="bayeshopf",
        description="Bayesian hybrid normal-form models of Hopf bifurcations from "
        "limit-cycle-oscillation recordings.",
    )
    ap.add_argument("--debug", action="store_true", help="show tracebacks of internal errors")
    ap.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    d = sub.add_parser("demo", help="fit simulated recordings of the 3-DOF aeroelastic aerofoil",
                       description="Simulate stable and unstable LCO recordings of the paper's "
                       "3-DOF aeroelastic aerofoil in-process (4 + 4 orbits, 1% noise, sensor "
                       "offsets; no download), fit the model blind, print the Hopf point, a2 and "
                       "the fold with 90% intervals next to the simulator's own values, and "
                       "write the figures with the true bifurcation diagram.")
    d.add_argument("--out", default="bayeshopf-demo", help="output folder (default bayeshopf-demo)")
    _add_fit_options(d)

    f = sub.add_parser("fit", help="fit recordings in a folder",
                       description="Fit a folder of CBC .mat files or an interchange folder "
                       "(manifest.csv + one CSV per recording), or a published data set "
                       "(--dataset). Writes DIR/summary.json, DIR/posterior.nc, DIR/model.json "
                       "and DIR/figures/*.png.")
    f.add_argument("data", nargs="?", default=None,
                   help="folder of .mat files, or interchange folder (or use --dataset)")
    f.add_argument("--dataset", choices=tuple(DATASETS), default=None,
                   help="a published data set instead of DATA: flutter_cbc, the wind-tunnel "
                   "rig's 7 CBC recordings ($BAYESHOPF_FLUTTER_CBC if set, else downloaded "
                   "once, 11 MB, SHA-256 checked)")
    f.add_argument("--out", required=True, help="output folder (refused if not empty)")
    f.add_argument("--criticality", choices=("sub", "super", "auto"), default="sub",
                   help="normal form: subcritical (default), supercritical, or auto "
                   "(decided from the data)")
    f.add_argument("--exact-loo", action="store_true",
                   help="with --criticality auto: refit each model without every recording "
                   "whose PSIS Pareto k exceeds 0.7 and use its exact leave-one-out density "
                   "(one fit per refit)")
    f.add_argument("--leave-one-out", action="store_true",
                   help="also refit without each recording in turn and predict it (one fit "
                   "per recording): summary.json's leave_one_out and a warning when too few "
                   "held-out amplitudes lie inside their 90%% predictive bands")
    f.add_argument("--planar", nargs=2, metavar=("Z1", "Z2"), default=None,
                   help="channels of the planar pair (default: the first two)")
    f.add_argument("--rig", metavar="FILE", default=None,
                   help="rig description (TOML or JSON) of DATA's .mat files: rows, scales, "
                   "time, mu, what a sensor writes without a reading (default: DATA/rig.toml "
                   "if present, else the built-in flutter_cbc rig)")
    ctl = f.add_mutually_exclusive_group()
    ctl.add_argument("--control", metavar="CHANNEL", default=None,
                     help="the channel holding the CBC controller's output (actuator command): "
                     "its residual fundamental becomes a measured input of the model (default: "
                     "the rig description's 'control'; for interchange folders, a column name)")
    ctl.add_argument("--no-control", action="store_true",
                     help="leave out the orbits' response to the CBC controller's residual "
                     "fundamental (in the model by default where the rig description names a "
                     "control channel, as the built-in flutter_cbc rig does)")
    _add_fit_options(f)

    p = sub.add_parser("predict", help="amplitude and frequency at μ from a saved fit",
                       description="Amplitude and frequency (median and credible interval) "
                       "at one or several μ on a branch, from a folder written by "
                       "'bayeshopf fit' or 'bayeshopf demo'.")
    p.add_argument("fit_dir", help="folder written by 'bayeshopf fit'")
    p.add_argument("--mu", nargs="+", required=True, metavar="MU",
                   help="values of the bifurcation parameter, or START:STOP:STEP "
                   "(STOP included), e.g. --mu 15 15.5 16 or --mu 14:17:0.5")
    p.add_argument("--ci", type=float, default=0.9,
                   help="probability mass of the intervals (default 0.9)")
    p.add_argument("--branch", choices=("stable", "unstable"), default="stable")
    p.add_argument("--predictive", action="store_true",
                   help="band of a new measurement instead of the curve (adds the model "
                   "error, which grows away from the recordings, and the measurement error)")
    p.add_argument("--json", action="store_true",
                   help="print JSON (an object for one μ, a list for several)")
    p.add_argument("--csv", action="store_true", help="print CSV, one row per μ")

    g = sub.add_parser("download", help="download a published data set",
                       description="Download a published data set with its pinned SHA-256 "
                       "hashes and print the folder that holds it (files already there are "
                       "not fetched again). flutter_cbc: the wind-tunnel rig's 7 CBC "
                       "recordings (11 MB) from github.com/Kyounghyunlee/ML_Hopf, or from "
                       "$BAYESHOPF_FLUTTER_CBC_URL.")
    g.add_argument("dataset", choices=tuple(DATASETS))
    g.add_argument("--to", default=None,
                   help="folder to download into (default: the user cache, "
                   "$BAYESHOPF_DATA_DIR/flutter_cbc if set)")

    pl = sub.add_parser("plot", help="draw a saved fit's figures again, without refitting",
                        description="Draw the figures of a folder written by 'bayeshopf fit' "
                        "or 'bayeshopf demo' again into DIR/figures (replacing files of the "
                        "same name once all are drawn), without refitting: the diagram, the "
                        "predictive check and the frequency; with --recordings also the phase "
                        "portraits and time series.")
    pl.add_argument("fit_dir", help="folder written by 'bayeshopf fit'")
    pl.add_argument("--format", choices=("png", "pdf", "svg"), default="png",
                    help="file format (default png; pdf and svg are vector)")
    pl.add_argument("--recordings", metavar="DATA", default=None,
                    help="the recordings the fit was made from (folder, as for 'fit'), for "
                    "the phase portraits and time series")
    pl.add_argument("--ci", type=float, default=0.9,
                    help="probability mass of the bands and intervals (default 0.9)")
    pl.add_argument("--length-unit", default="auto",
                    help="unit of lengths: m, cm, mm, µm, or auto (default: the one in which "
                    "the largest amplitude reads 1-1000)")
    pl.add_argument("--offsets", choices=("remove", "keep"), default="remove",
                    help="remove (default) or keep each recording's mean in the phase "
                    "portraits and time series")
    pl.add_argument("--dpi", type=int, default=300, help="resolution of png files (default 300)")

    _simulate.add_parser(sub)
    _discrepancy.add_parser(sub)
    _next.add_parser(sub)
    for s in sub.choices.values():   # --debug after the subcommand as well as before it
        s.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                       help="show tracebacks of internal errors")
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
    level = summary.get("ci", 0.9)
    key, pct = f"ci{round(100 * level)}", f"{100 * level:g}%"
    hdr = (f"{'':8s} {'median':>10s} {pct + ' interval':>24s}"
           + (f" {'true':>10s}" if truth else ""))
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
        print(f"{k:8s} {v['median']:10.4g} [{v[key][0]:10.4g}, {v[key][1]:10.4g}]{t}{unit}")
    if curved:
        print("(curved unfolding β(μ) = (exp(b(μ−μ0)) − 1)/b, w = b(μ0 − μ_fold); a2 is its "
              "cubic coefficient, β(μ_fold) = −a2²/4)")
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
    print(f"{r['file'][:28]:28s} {r['mu']:8.4g} {r['branch']:>9s} {measured:10.4g} "
          f"{predicted['median']:10.4g} [{lo:8.4g}, {hi:8.4g}]{'' if inside else '  OUTSIDE'}")


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
    errs = [e["relative"] for e in diag["fit"]["orbit_error"] if e["relative"] is not None]
    if errs:
        print(f"orbit errors (posterior-median orbit against the measured mean orbit): "
              f"{100 * min(errs):.1f}–{100 * max(errs):.1f}% of the orbit size")
    disc = diag["fit"].get("discrepancy")
    if disc:
        eta = disc["eta"]
        lo, hi = next(v for k, v in eta.items() if k.startswith("ci"))
        print(f"model discrepancy (smooth, of the fundamental): {100 * eta['median']:.2g}% "
              f"[{100 * lo:.2g}, {100 * hi:.2g}] of the orbit size; it is in the posterior, "
              "so the intervals and bands include it")
    away = diag["fit"].get("extrapolation_scale")
    if away:
        from bayeshopf.model import collapsed as cm

        why = ("as set" if away["chosen_by"] == "setting" else
               f"the rms over the draws: {cm.EXTRAPOLATION_SCALE_MISFIT:g} in the "
               f"{100 * away['p_above_limit']:.0f}% whose relative model error is above the "
               f"{100 * cm.SIGMA_REL_LIMIT:g}% limit, {cm.EXTRAPOLATION_SCALE:g} in the others")
        print(f"bands of new measurements away from the recordings: model-error scale "
              f"{away['scale']:.2g} ({why})")
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
    """``fit``/``demo``: :func:`~bayeshopf.posterior.fit_hybrid` (or ``fit_auto``), saved.

    The figures' process starts first, so that it imports Matplotlib while the fit runs.
    """
    from bayeshopf import report
    from bayeshopf.errors import FitError

    if getattr(args, "nuts_check", False) and args.inference != "svi":
        raise FitError("--nuts-check compares SVI with NUTS and needs --inference svi; got "
                       "--inference nuts (the default), whose R̂ and ESS are reported anyway")
    if not 0 < args.ci < 1:
        raise FitError(f"--ci {args.ci:g}: a probability mass between 0 and 1 expected "
                       "(e.g. 0.9)")
    scale = getattr(args, "extrapolation_scale", None)
    if scale is not None and not (math.isfinite(scale) and scale > 0):
        raise FitError(f"--extrapolation-scale {scale:g}: a positive number expected (by "
                       "default per draw 0.1, or 0.7 where the relative model error is above "
                       "2%)")
    report.check_output_folder(out, args.force)
    worker = None
    if not args.no_figures:   # bayeshopf._preload: imports beside NUTS, a figure process
        from bayeshopf import _preload

        _preload.request("bayeshopf.plotting")
        if _preload.available_cores() > 1:   # on one core it would only add its start
            worker = _preload.figure_worker()
    try:
        return _fit_and_save(rs, criticality, args, out, truth, extra, worker)
    finally:
        if worker is not None:
            worker.shutdown(cancel_futures=True)


def _fit_and_save(rs, criticality, args, out, truth, extra, worker):
    from dataclasses import replace

    from bayeshopf import report
    from bayeshopf.inference.collapsed import CollapsedSettings
    from bayeshopf.posterior import fit_hybrid

    progress = not args.quiet
    if progress:
        control = getattr(rs, "control", None)
        control = (f"; the control channel '{control}' as a measured input"
                   if control and not getattr(args, "no_control", False) else "")
        print(f"features: {len(rs)} recordings ({int(rs.is_unstable.sum())} unstable), "
              f"phase-aligned harmonics{control}", file=sys.stderr)
    t0 = time.perf_counter()
    settings = CollapsedSettings.fast() if args.fast else CollapsedSettings()
    settings = replace(settings, inference=args.inference,
                       control=not getattr(args, "no_control", False),
                       discrepancy=bool(getattr(args, "discrepancy", False)))
    if getattr(args, "extrapolation_scale", None) is not None:
        settings = replace(settings, extrapolation_scale=args.extrapolation_scale)
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
    loo = None
    if getattr(args, "leave_one_out", False):
        from bayeshopf import validation

        if progress:
            print(f"leave-one-out: {post.features.n_recordings} refits, each without one "
                  "recording, which it then predicts", file=sys.stderr)
        loo = validation.leave_one_out(post.features, post.criticality, methods=("bayes",),
                                       seed=args.seed, settings=settings,
                                       keep_fits=not args.no_figures, progress=progress)
        extra = {**(extra or {}), "leave_one_out": loo.report()}
    if progress:
        print(f"checks and files: posterior predictive check, "
              f"{'' if args.no_figures else 'figures, '}writing {out}", file=sys.stderr)
    ppc = post.ppc(args.ci)
    figures = None
    if not args.no_figures:
        from bayeshopf.plotting import start_figures

        def figures(folder):   # returns while the figure process finishes
            pending = start_figures(post, rs, folder, truth=truth, zoom=truth is not None,
                                    ci=args.ci, executor=worker)
            if loo is not None:    # meanwhile, here: the folds' fits are in this process
                from bayeshopf.plotting._io import save_figure
                from bayeshopf.plotting._units import readable_length
                from bayeshopf.plotting.validation import plot_leave_one_out

                unit = readable_length(post.amplitude_units,    # as start_figures's "auto"
                                       float(abs(post.features.amplitude).max()))
                save_figure(plot_leave_one_out(loo, post.features, mu_label=post.mu_label,
                                               mu_units=post.mu_units,
                                               amplitude_units=post.amplitude_units,
                                               length_unit=unit),
                            folder / "leave_one_out.png")
            return pending

    report.save_hybrid(post, out, force=args.force, figures=figures, ppc=ppc,
                       extra_summary=extra, ci=args.ci)
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


def _recordings(args):
    """``fit``'s recordings (DATA or ``--dataset``), with ``--control`` applied."""
    from dataclasses import replace

    from bayeshopf.errors import DataError

    rs = _read_recordings(args)
    name = getattr(args, "control", None)
    if name is None:
        return rs
    try:
        return replace(rs, control=name)
    except DataError as exc:
        raise DataError(f"--control: {exc}") from None


def _read_recordings(args):
    """``fit``'s recordings: the folder DATA or the published data set ``--dataset``."""
    from bayeshopf.errors import DataError

    if (args.data is None) == (args.dataset is None):
        found = "both" if args.data is not None else "neither"
        raise DataError(f"DATA: a folder of recordings or --dataset {'|'.join(DATASETS)} "
                        f"expected (one of the two); found {found}")
    planar = tuple(args.planar) if args.planar else None
    if args.data is not None:
        from bayeshopf.data import load_recordings
        from bayeshopf.data.io import dropped_report

        rs = load_recordings(args.data, planar=planar, rig=args.rig)
        for line in [] if args.quiet else dropped_report(rs):
            print(f"data: {line}", file=sys.stderr)
        return rs
    if args.rig is not None:
        raise DataError(f"--rig: describes the .mat files of DATA; --dataset {args.dataset} "
                        "has its own description (drop --rig)")
    from dataclasses import replace

    from bayeshopf.data.datasets import flutter_cbc

    if not args.quiet:
        print(f"data: {args.dataset} (downloaded once into the user cache unless "
              "$BAYESHOPF_FLUTTER_CBC names a folder)", file=sys.stderr)
    rs = flutter_cbc(download=True)
    if planar is None:
        return rs
    return replace(rs, planar=planar, control=None if rs.control in planar else rs.control)


def cmd_fit(args) -> int:
    """``bayeshopf fit``."""
    crit = {"sub": "subcritical", "super": "supercritical", "auto": "auto"}[args.criticality]
    if args.exact_loo and crit != "auto":
        from bayeshopf.errors import FitError

        raise FitError(f"--exact-loo compares the two normal forms and needs --criticality "
                       f"auto; got --criticality {args.criticality}")
    rs = _recordings(args)
    summary = _run_hybrid(rs, crit, args, args.out)
    _print_table(summary)
    print(f"\nwrote {args.out}/summary.json, posterior.nc, model.json and figures/ "
          f"in {summary['total_s']:.0f} s")
    return 0


def _mu_values(tokens: list[str]) -> list[float]:
    """``--mu`` values: numbers and ``START:STOP:STEP`` ranges (STOP included)."""
    import numpy as np

    from bayeshopf.errors import DataError

    out: list[float] = []
    for tok in tokens:
        parts = tok.split(":")
        try:
            nums = [float(x) for x in parts]
        except ValueError:
            nums = []
        if len(parts) == 1 and nums:
            out.append(nums[0])
        elif len(nums) == 3 and nums[2] > 0 and nums[1] >= nums[0]:
            n = int(np.floor((nums[1] - nums[0]) / nums[2] + 1e-9)) + 1
            out.extend(float(v) for v in np.round(nums[0] + nums[2] * np.arange(n), 12))
        else:
            raise DataError(f"--mu {tok}: a number or START:STOP:STEP with STEP > 0 and "
                            f"STOP >= START expected; found {tok!r}")
    return out


def _prediction(saved, mu: float, args) -> dict:
    """One μ of ``predict``: amplitude (None where the branch does not exist) and frequency."""
    from bayeshopf.errors import DataError

    try:
        amp = saved.predict(mu, args.branch, predictive=args.predictive, ci=args.ci)
    except DataError:
        amp = None
    freq = None if amp is None else saved.frequency(mu, args.branch, args.predictive,
                                                     ci=args.ci)
    return {"mu": mu, "amplitude": amp, "frequency": freq,
            "p_exists": saved.p_exists(mu, args.branch)}


def cmd_predict(args) -> int:
    """``bayeshopf predict``: one μ as a sentence, several as a table (or JSON, CSV)."""
    from bayeshopf.errors import DataError
    from bayeshopf.report import load_fit

    if not 0 < args.ci < 1:
        raise DataError(f"--ci {args.ci:g}: a probability mass between 0 and 1 expected "
                        "(e.g. 0.9)")
    if args.json and args.csv:
        raise DataError("--json and --csv: one output format expected; found both")
    mus = _mu_values(args.mu)
    saved = load_fit(args.fit_dir)
    rows = [_prediction(saved, mu, args) for mu in mus]
    if len(mus) == 1 and rows[0]["amplitude"] is None:   # the fit's own message
        saved.predict(mus[0], args.branch, predictive=args.predictive, ci=args.ci)
    if all(r["amplitude"] is None for r in rows):
        raise DataError(f"--mu {' '.join(args.mu)}: the {args.branch} branch does not exist "
                        "at any of these μ in any posterior draw (Hopf point μ0 ≈ "
                        f"{saved.summary['mu0']['median']:.4g})")
    units = saved.summary.get("amplitude_units", "")
    mu_units = saved.summary.get("mu_units", "")
    level = f"{100 * args.ci:g}%"
    if args.json:
        out = [{"mu": r["mu"], "branch": args.branch, "predictive": args.predictive,
                "amplitude": None if r["amplitude"] is None else r["amplitude"].to_json(),
                "p_exists": r["p_exists"], "units": units,
                **({"frequency_hz": r["frequency"].to_json()} if r["frequency"] else {})}
               for r in rows]
        print(json.dumps(out[0] if len(out) == 1 else out))
    elif args.csv:
        import csv

        w = csv.writer(sys.stdout, lineterminator="\n")
        w.writerow(["mu", "branch", "ci", "p_exists", f"amplitude_median [{units}]",
                    f"amplitude_lo [{units}]", f"amplitude_hi [{units}]",
                    "frequency_median [Hz]", "frequency_lo [Hz]", "frequency_hi [Hz]"])
        for r in rows:
            a, f = r["amplitude"], r["frequency"]
            w.writerow([repr(r["mu"]), args.branch, args.ci, r["p_exists"],
                        *(("", "", "") if a is None else (a.median, a.lo, a.hi)),
                        *(("", "", "") if f is None else (f.median, f.lo, f.hi))])
    elif len(rows) == 1:
        r, u = rows[0], units
        iv, freq = r["amplitude"], r["frequency"]
        print(f"{args.branch} LCO at μ = {r['mu']:g} {mu_units}: "
              f"amplitude {iv.median:.4g} {u}, {level} interval [{iv.lo:.4g}, {iv.hi:.4g}] {u} "
              f"(branch exists in {100 * r['p_exists']:.0f}% of posterior draws)")
        if freq is not None:
            print(f"frequency {freq.median:.4g} Hz, {level} interval "
                  f"[{freq.lo:.4g}, {freq.hi:.4g}] Hz")
    else:
        what = "a new measurement's" if args.predictive else "the curve's"
        print(f"{args.branch} branch, {what} median and {level} interval")
        print(f"{'mu [' + mu_units + ']':>10s} {'P(exists)':>9s} "
              f"{'amplitude [' + units + ']':>14s} {level + ' interval':>22s} "
              f"{'frequency [Hz]':>14s} {level + ' interval':>20s}")
        for r in rows:
            a, f = r["amplitude"], r["frequency"]
            amp = (f"{'—':>14s} {'':22s}" if a is None else
                   f"{a.median:14.4g} [{a.lo:9.4g}, {a.hi:9.4g}]")
            fr = "" if f is None else f" {f.median:14.4g} [{f.lo:8.4g}, {f.hi:8.4g}]"
            print(f"{r['mu']:10.4g} {r['p_exists']:9.2f} {amp}{fr}".rstrip())
    return 0


def cmd_download(args) -> int:
    """``bayeshopf download``: fetch a published data set and print its folder."""
    from bayeshopf.data.datasets import download_flutter_cbc

    print(download_flutter_cbc(args.to))
    return 0


def cmd_plot(args) -> int:
    """``bayeshopf plot``: a saved fit's figures drawn again (``report.redraw_figures``)."""
    from bayeshopf.errors import DataError
    from bayeshopf.plotting._units import LENGTHS
    from bayeshopf.report import load_fit

    if not 0 < args.ci < 1:
        raise DataError(f"--ci {args.ci:g}: a probability mass between 0 and 1 expected "
                        "(e.g. 0.9)")
    if args.length_unit not in ("auto", *LENGTHS):
        raise DataError(f"--length-unit {args.length_unit}: one of auto, "
                        f"{', '.join(LENGTHS)} expected; found {args.length_unit!r}")
    saved = load_fit(args.fit_dir)
    paths = saved.plot(recordings=args.recordings, fmt=args.format, ci=args.ci,
                       length_unit=args.length_unit, offsets=args.offsets, dpi=args.dpi)
    left = "" if args.recordings else " (phase portraits and time series need --recordings)"
    print(f"wrote {', '.join(p.name for p in paths)} into {paths[0].parent}{left}")
    return 0


COMMANDS = {"demo": cmd_demo, "fit": cmd_fit, "predict": cmd_predict, "simulate": _simulate.run,
            "discrepancy": _discrepancy.run, "download": cmd_download, "plot": cmd_plot,
            "next": _next.run}


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit code."""
    args = build_parser().parse_args(argv)
    from bayeshopf.errors import BayesHopfError

    try:
        from bayeshopf._preload import available_cores
        from bayeshopf._x64 import ensure_x64
        from bayeshopf.inference.cache import configure_xla_cpu, enable_compilation_cache

        # one OpenBLAS thread (NumPy's and SciPy's), whose busy-waiting workers
        # would otherwise take the cores from NUTS's devices, set before the
        # inference core's import loads SciPy's (bayeshopf.inference.cache)
        configure_xla_cpu()
        from bayeshopf.inference.collapsed import CollapsedSettings

        # before any JAX work: a CPU device per core, up to NUTS's chains, which
        # then run two by two on two cores
        configure_xla_cpu(host_devices=min(available_cores(), CollapsedSettings.num_chains))
        enable_compilation_cache()  # before any JAX work, so every compilation is cached
        ensure_x64()                # bayeshopf computes in float64
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


def run() -> None:
    """The console script ``bayeshopf``: :func:`main`, then exit with its code.

    Before the interpreter's teardown it moves every object to the garbage
    collector's permanent generation (:func:`gc.freeze`), so that the teardown's
    collections do not trace the heap of JAX, NumPyro, Matplotlib and ArviZ once
    more. Every file is written and closed by then, and the exit handlers still
    run (the time it saves: ``docs/changelog.md``).
    """
    code = main()
    gc.freeze()
    sys.exit(code)


if __name__ == "__main__":
    run()
