"""What ``fit`` and ``demo`` share: their fit options, the fit itself, and saving it.

The figures are drawn in a separate process that imports Matplotlib while the
fit runs (:mod:`bayeshopf._preload`); the plotting code is therefore imported
here only where a figure is drawn in this process, not at the top.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

from bayeshopf import _preload, fit_folder, posterior, validation
from bayeshopf.cli._checks import check_ci, check_out
from bayeshopf.errors import FitError
from bayeshopf.inference import collapsed as inference


@dataclass(frozen=True)
class FitGroups:
    """The sections of ``fit``'s and ``demo``'s ``--help``, each an argument group."""

    model: argparse._ArgumentGroup
    inference: argparse._ArgumentGroup
    outputs: argparse._ArgumentGroup


def fit_groups(p: argparse.ArgumentParser) -> FitGroups:
    """``p``'s sections model, inference and outputs, in that order."""
    return FitGroups(
        model=p.add_argument_group("model", "the normal form, its map and its model error"),
        inference=p.add_argument_group("inference", "how the posterior is computed and checked"),
        outputs=p.add_argument_group("outputs", "the output folder and what is printed"))


def add_fit_options(g: FitGroups) -> None:
    """The options ``fit`` and ``demo`` share, each in its section."""
    g.inference.add_argument("--inference", choices=("importance", "nuts", "svi"),
                             default="importance",
                             help="posterior: importance sampling from the MAP's Laplace "
                             "approximation, Pareto-smoothed, with NUTS where its check fails "
                             "(default); NUTS; or SVI with a full-rank Gaussian guide")
    g.inference.add_argument("--nuts-check", action="store_true",
                             help="with --inference importance or svi: also run NUTS on the "
                             "same model and report whether the 90%% intervals match NUTS's "
                             "(summary.json 'nuts_check')")
    g.inference.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    g.inference.add_argument("--fast", action="store_true",
                             help="short optimisation runs (smoke tests, CI); intervals less "
                             "converged")

    g.model.add_argument("--nn-width", default=None, metavar="H",
                         help="hidden units of the map's network, or 'inf' (the default) for "
                         "its limit of infinite width, a Gaussian process with the network's "
                         "kernel that has no hidden layer to draw (docs/model.md)")
    g.model.add_argument("--no-discrepancy", dest="discrepancy", action="store_false",
                         help="fit without the model discrepancy (docs/model_discrepancy.md): "
                         "the normal form and map exact up to a relative model error of each "
                         "coefficient, the Hopf point and the fold the normal form's own "
                         "(best with --inference nuts, docs/inference.md)")
    g.model.add_argument("--mu-discrepancy", type=float, default=None, metavar="K",
                         help="κ of the discrepancy's twin in μ, which moves the Hopf point "
                         "and the fold by the model's error beyond the recordings (default 2; "
                         "0 reports the normal form's own points)")
    g.model.add_argument("--mu-discrepancy-floor", type=float, default=None, metavar="PHI",
                         help="φ, the floor on the discrepancy's scale η in that error, "
                         "κ√(η² + φ²) times the fold–Hopf gap (default 0.05; 0: none)")
    g.model.add_argument("--extrapolation-scale", type=float, default=None, metavar="S",
                         help="half-normal scale of an extra model error away from the "
                         "recordings, in log orbit size, that widens new measurements' bands "
                         "between and beyond the recordings only (default: none; 0.1 with "
                         "--no-discrepancy)")

    g.outputs.add_argument("--force", action="store_true",
                           help="write into a non-empty output folder (replaces bayeshopf's "
                           "files only)")
    g.outputs.add_argument("--ci", type=float, default=0.9,
                           help="probability mass of the printed and saved intervals and of "
                           "the figures' outer band (default 0.9; the convergence checks stay "
                           "at 90%%)")
    g.outputs.add_argument("--no-figures", action="store_true", help="skip the figures")
    g.outputs.add_argument("--json", action="store_true",
                           help="print the results as JSON (schema of bayeshopf.cli._schema) "
                           "instead of the table")
    g.outputs.add_argument("--quiet", action="store_true", help="no progress lines")


def run_hybrid(rs, criticality, args, out, truth=None, extra=None) -> dict:
    """``fit``/``demo``: :func:`~bayeshopf.posterior.fit_hybrid` (or ``fit_auto``), saved.

    The figures' process starts first, so that it imports Matplotlib while the
    fit runs. Returns the saved ``summary.json`` with ``total_s``, the wall time.

    Raises:
        FitError: For options that do not go together or out of range, by flag.
        OutputError: When ``--out`` is not empty without ``--force``.
    """
    if getattr(args, "nuts_check", False) and args.inference == "nuts":
        raise FitError("--nuts-check compares importance sampling or SVI with NUTS and needs "
                       "--inference importance (the default) or svi; got --inference nuts, "
                       "whose R̂ and ESS are reported anyway")
    check_ci(args.ci, error=FitError)
    scale = getattr(args, "extrapolation_scale", None)
    if scale is not None and not (math.isfinite(scale) and scale > 0):
        raise FitError(f"--extrapolation-scale {scale:g}: a positive number expected (by "
                       "default none, 0.1 with --no-discrepancy)")
    if getattr(args, "nn_width", None) is not None:
        _nn_width(args.nn_width)
    for flag, default in (("mu_discrepancy", "default 2; 0: the normal form's own Hopf point "
                           "and fold"), ("mu_discrepancy_floor", "default 0.05; 0: none")):
        k, opt = getattr(args, flag, None), "--" + flag.replace("_", "-")
        if k is not None and not (math.isfinite(k) and k >= 0):
            raise FitError(f"{opt} {k:g}: a finite number ≥ 0 expected ({default})")
        if k is not None and not getattr(args, "discrepancy", True):
            raise FitError(f"{opt} sets the discrepancy in μ, which --no-discrepancy removes")
    check_out(out, args.force)
    worker = None
    if not args.no_figures:   # imports beside NUTS, and a figure process
        _preload.request("bayeshopf.plotting")
        if _preload.available_cores() > 1:   # on one core it would only add its start
            worker = _preload.figure_worker()
    try:
        return _fit_and_save(rs, criticality, args, out, truth, extra, worker)
    finally:
        if worker is not None:
            worker.shutdown(cancel_futures=True)


def _settings(args) -> inference.CollapsedSettings:
    """The inference settings the options ask for."""
    settings = inference.CollapsedSettings.fast() if args.fast else inference.CollapsedSettings()
    settings = replace(settings, inference=args.inference,
                       control=not getattr(args, "no_control", False),
                       discrepancy=bool(getattr(args, "discrepancy", True)))
    if getattr(args, "extrapolation_scale", None) is not None:
        settings = replace(settings, extrapolation_scale=args.extrapolation_scale)
    for flag in ("mu_discrepancy", "mu_discrepancy_floor"):
        if getattr(args, flag, None) is not None:
            settings = replace(settings, **{flag: getattr(args, flag)})
    width = getattr(args, "nn_width", None)
    if width is not None:
        settings = replace(settings, nn_width=_nn_width(width))
    return settings


def _nn_width(text: str) -> int | None:
    """``--nn-width``: a positive whole number, or ``inf`` (``None``: infinite width)."""
    if text.strip().lower() in ("inf", "infinite", "∞"):
        return None
    if not text.strip().isdigit() or int(text) < 1:
        raise FitError(f"--nn-width {text}: a positive whole number of hidden units, or 'inf', "
                       "expected")
    return int(text)


def _fit_and_save(rs, criticality, args, out, truth, extra, worker) -> dict:
    progress = not args.quiet
    if progress:
        control = getattr(rs, "control", None)
        control = (f"; the control channel '{control}' as a measured input"
                   if control and not getattr(args, "no_control", False) else "")
        print(f"features: {len(rs)} recordings ({int(rs.is_unstable.sum())} unstable), "
              f"phase-aligned harmonics{control}", file=sys.stderr)
    t0 = time.perf_counter()
    settings = _settings(args)
    if criticality == "auto":
        post, evidence = posterior.fit_auto(rs, seed=args.seed, settings=settings,
                                            progress=progress,
                                            exact_loo=getattr(args, "exact_loo", False))
        extra = {**(extra or {}), "criticality_evidence": evidence}
    else:
        post = posterior.fit_hybrid(rs, criticality, seed=args.seed, settings=settings,
                                    progress=progress)
    if getattr(args, "nuts_check", False):
        extra = {**(extra or {}), "nuts_check": inference.compare_with_nuts(
            post, seed=args.seed, progress=progress)}
    loo = None
    if getattr(args, "leave_one_out", False):
        if progress:
            print(f"leave-one-out: {post.features.n_recordings} refits, each without one "
                  "recording, which it then predicts", file=sys.stderr)
        # from the recordings: each refit's frame is built without the one it predicts
        loo = validation.leave_one_out(rs, post.criticality, methods=("bayes",),
                                       seed=args.seed, settings=settings,
                                       keep_fits=not args.no_figures, progress=progress)
        extra = {**(extra or {}), "leave_one_out": loo.report()}
    if progress:
        print(f"checks and files: posterior predictive check, "
              f"{'' if args.no_figures else 'figures, '}writing {out}", file=sys.stderr)
    ppc = post.ppc(args.ci)
    figures = None if args.no_figures else _figures(post, rs, truth, loo, args.ci, worker)
    fit_folder.save_hybrid(post, out, force=args.force, figures=figures, ppc=ppc,
                       extra_summary=extra, ci=args.ci)
    summary = json.loads((Path(out) / fit_folder.SUMMARY).read_text())
    summary["total_s"] = time.perf_counter() - t0
    return summary


def _figures(post, rs, truth, loo, ci, worker):
    """``figures(folder)`` for :func:`~bayeshopf.fit_folder.save_hybrid`: the fit's figures.

    It returns while the figure process finishes; the leave-one-out figure is drawn
    meanwhile here, where the folds' fits are.
    """
    def figures(folder):
        # loaded beside NUTS (_preload), not at the top
        from bayeshopf.plotting import start_figures
        from bayeshopf.plotting._io import save_figure
        from bayeshopf.plotting._units import readable_length
        from bayeshopf.plotting.validation import plot_leave_one_out

        pending = start_figures(post, rs, folder, truth=truth, zoom=True,
                                ci=ci, executor=worker)
        if loo is not None:

            unit = readable_length(post.amplitude_units,    # as start_figures's "auto"
                                   float(abs(post.features.amplitude).max()))
            save_figure(plot_leave_one_out(loo, post.features, mu_label=post.mu_label,
                                           mu_units=post.mu_units,
                                           amplitude_units=post.amplitude_units,
                                           length_unit=unit),
                        folder / "leave_one_out.png")
        return pending

    return figures
