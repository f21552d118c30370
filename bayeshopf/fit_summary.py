"""The ``summary.json`` of a fit: its intervals, recordings, checks, settings and timings."""

from __future__ import annotations

import math

import numpy as np

from bayeshopf._version import __version__
from bayeshopf.diagnostics.summaries import CI, interval
from bayeshopf.hybrid_posterior import RIG

__all__ = ["COLLAPSED_CORE", "summary_hybrid"]


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None



#: ``model.json``'s ``core`` for fits of :func:`bayeshopf.posterior.fit_hybrid`.
COLLAPSED_CORE = "collapsed"


def _normal_form_points(post, ci: float) -> dict | None:
    """The normal form's own Hopf point and fold, where the discrepancy in μ moved the fit's."""
    if "mu0" + RIG not in post.samples:
        return None
    return {k: interval(post.samples[k], ci).to_json() for k in ("mu0", "mu_fold")
            if k in post.samples}


def summary_hybrid(post, ppc=None, extra: dict | None = None, ci: float = CI) -> dict:
    """The ``summary.json`` content of a :class:`~bayeshopf.posterior.HybridPosterior`.

    ``ci`` is the mass of the intervals of μ0, a2, the fold and each
    recording's predicted amplitude (keys ``ci90`` at the default 0.9, ``ci95``
    at 0.95, …; ``ppc`` must be at the same level). The convergence and fit
    checks in ``diagnostics`` stay at 90%. An ``extra`` ``leave_one_out``
    (:meth:`bayeshopf.validation.LeaveOneOut.report`) adds its check to
    ``diagnostics`` (``leave_one_out``, and its warning when it fails).
    """
    ppc = post.ppc(ci) if ppc is None else ppc
    inside = f"inside_ci{round(100 * ppc.ci)}"
    diag = post.diagnostics
    errors = {e["name"]: e for e in diag["fit"]["orbit_error"]}
    f = post.features
    freq = diag["fit"].get("frequency")
    recs = []
    for i, name in enumerate(f.names):
        recs.append({
            "file": name, "mu": float(f.mu[i]),
            "branch": "unstable" if f.unstable[i] else "stable",
            "amplitude": float(f.amplitude[i]), "amplitude_sd": float(f.amplitude_sd[i]),
            "n_segments": int(f.n_segments[i]),
            "predicted": ppc.predictive[i].to_json(), "curve": ppc.curve[i].to_json(),
            inside: bool(ppc.covered[i]),
            "frequency_hz": float(f.frequency_hz[i]),
            "frequency_predicted": freq[i]["predicted"] if freq else None,
            "frequency_inside_ci90": freq[i]["inside_ci90"] if freq else None,
            "orbit_error": {k: errors[name][k] for k in ("relative", "spread", "ok",
                                                         "by_harmonic")},
            "control_fundamental": (None if f.control is None
                                    else np.asarray(f.control[i], float).tolist()),
        })

    def iv(name):
        v = post.interval(name, ci)
        return None if v is None else v.to_json()

    out = {
        "core": COLLAPSED_CORE,
        "mu0": iv("mu0"), "a2": iv("a2"), "a4": iv("a4"), "mu_fold": iv("mu_fold"),
        "w_unfold": iv("w_unfold"),
        "normal_form_points": _normal_form_points(post, ci),
        "criticality": post.criticality, "unfolding": post.spec.unfolding,
        "mu_label": post.mu_label, "mu_units": post.mu_units,
        "amplitude_units": post.amplitude_units,
        "amplitude_definition": "peak-to-peak of z1 over the orbit, from its K-harmonic "
        "reconstruction",
        "planar_channels": list(post.spec.frame.names),
        "control": post.control_gain(ci),
        "recordings": recs,
        "orbit_error": [errors[n] for n in f.names],
        "ppc": {f"amplitudes_{inside}": int(ppc.covered.sum()),
                "frequencies_inside_ci90": (sum(e["inside_ci90"] for e in freq)
                                            if freq else None),
                "n_recordings": int(ppc.covered.size),
                f"coefficients_{inside}": ppc.coeff_coverage},
        "map": {k: _finite_or_none(float(np.asarray(post.map_point.params[k])))
                for k in ("mu0", "a2", "a4", "mu_fold", "w_unfold")
                if k in post.map_point.params},
        "diagnostics": diag,
        "seed": post.seed,
        "settings": dict(post.settings.__dict__),
        "n_draws": int(np.shape(post.samples["mu0"])[0]),
        "timings_s": {k: round(v, 3) for k, v in post.timings.items()},
        "ci": ci,
        "bayeshopf_version": __version__,
    }
    if extra:
        out.update(extra)
    loo = out.get("leave_one_out")
    if loo is not None:   # bayeshopf.validation's held-out check joins the fit's checks
        chk = loo["check"]
        out["diagnostics"] = {**diag, "leave_one_out": {k: v for k, v in chk.items()
                                                        if k != "warning"},
                              "warnings": [*diag["warnings"],
                                           *([chk["warning"]] if chk["warning"] else [])]}
    return out
