"""Convergence and fit checks of a fitted hybrid model, one warning line per failed check.

:func:`diagnose` reads a :class:`~bayeshopf.hybrid_posterior.HybridPosterior`
(its MAP point, its posterior run, its predictive check and orbit errors) and
returns the record kept as its ``diagnostics``.
"""

from __future__ import annotations

import numpy as np

from bayeshopf.diagnostics.ppc import PosteriorPredictiveCheck
from bayeshopf.diagnostics.summaries import interval
from bayeshopf.features.harmonics import reconstruct
from bayeshopf.inference import nuts, optimum, svi
from bayeshopf.model import collapsed as cm
from bayeshopf.model import horizontal as hz

#: Orbit error (relative RMS distance) a recording's posterior-median orbit may have.
ORBIT_ERROR_MAX = 0.05
#: ... or this many times its measured segment spread.
ORBIT_SPREAD_FACTOR = 2.0
#: Model error σ_c above this many times the median measured standard error of
#: the channel's leading coefficients is reported as "the scatter is large
#: against the measured spread".
SIGMA_RATIO_MAX = 10.0
#: ... when it is also above this fraction of the orbit scale ρ (a model error of
#: 0.2% of the orbit is no misfit worth a warning, however clean the data).
SIGMA_ORBIT_FRACTION = 0.01
#: Relative model error above which the fit is reported as missing the orbits'
#: sizes: σ_rel, or with the model discrepancy ``√(η² + σ_rel²)``; σ_rel's prior
#: scale (2% of each harmonic).
SIGMA_REL_MAX = cm.SIGMA_REL_PRIOR
#: What that warning adds about μ0 and the fold: their intervals carry the normal
#: form's extrapolation, not the misfit (``docs/limits.md`` has the simulated rigs).
HOPF_FOLD_CAVEAT = ("the Hopf and fold intervals do not carry this misfit, and on simulated "
                    "rigs whose fits warned so they mostly missed the truth (docs/limits.md)")
#: ... and with the discrepancy in μ (``mu_discrepancy > 0``), which moves both
#: points by the model's error there: they carry it, but dry friction and other
#: effects below the smallest recorded orbit can still hide the Hopf point.
HOPF_FOLD_CAVEAT_MOVED = (
    "the Hopf and fold intervals carry it through the discrepancy in μ, but on simulated "
    "rigs whose fits warned so the Hopf point's interval often missed the truth where an "
    "effect below the smallest recorded orbit (dry friction) hides it (docs/limits.md)")
#: With the window at the fold (``unfolding="window"``): a posterior median of
#: its depth ``|A|`` above this many prior SDs is reported as the recordings
#: near the fold disagreeing with the normal form by more than its prior allows.
WINDOW_DEPTH_SDS_MAX = 2.0


def orbit_error_parts(model, data) -> np.ndarray:
    r"""The RMS distance between two orbits, split into the centre and each harmonic.

    For orbits given by their coefficients ``[a_0, a_1..a_K, b_1..b_K]`` on each
    axis, shape ``(2, 2K+1)``, Parseval's identity over one period gives the
    mean squared distance as

    .. math::  \overline{|Δz(φ)|^2} = \sum_{axes} \Big[Δa_0^2
               + \tfrac12 \sum_{k=1}^{K} (Δa_k^2 + Δb_k^2)\Big],

    so the parts ``e_0 = (Σ Δa_0²)^{1/2}`` and ``e_k = (½ Σ (Δa_k² + Δb_k²))^{1/2}``
    have squares that add up to the squared RMS distance.

    Returns:
        ``(e_0, e_1, …, e_K)``, in the coefficients' units.
    """
    d = np.asarray(model, float) - np.asarray(data, float)
    K = (d.shape[-1] - 1) // 2
    parts = [np.sum(d[:, 0] ** 2)]
    parts += [0.5 * np.sum(d[:, k] ** 2 + d[:, K + k] ** 2) for k in range(1, K + 1)]
    return np.sqrt(np.array(parts))


def harmonic_name(k: int) -> str:
    """``"the centre"``, ``"the fundamental"``, ``"harmonic k"``."""
    return {0: "the centre", 1: "the fundamental"}.get(k, f"harmonic {k}")


def fold_window_check(depth, width) -> tuple[dict, str | None]:
    """The window at the fold against its prior: the record and a warning line, if any.

    ``depth`` and ``width``: :class:`~bayeshopf.diagnostics.summaries.Interval`
    of ``A`` and ``λ``. Warns when ``|median A|`` exceeds
    :data:`WINDOW_DEPTH_SDS_MAX` prior SDs (:data:`~bayeshopf.model.horizontal.WINDOW_DEPTH_PRIOR`).
    """
    sds = abs(depth.median) / hz.WINDOW_DEPTH_PRIOR
    record = {"depth": depth.to_json(), "width": width.to_json(),
              "depth_prior_sd": hz.WINDOW_DEPTH_PRIOR, "depth_in_prior_sds": sds,
              "limit_in_prior_sds": WINDOW_DEPTH_SDS_MAX}
    if sds <= WINDOW_DEPTH_SDS_MAX:
        return record, None
    shape = "flatter" if depth.median > 0 else "sharper"
    return record, (
        f"fit: the fold's window has depth {depth.median:.2g} [{depth.lo:.2g}, {depth.hi:.2g}], "
        f"{sds:.1f} prior SDs from 0 (limit {WINDOW_DEPTH_SDS_MAX:g}): the recordings ask for "
        f"a fold far {shape} than the normal form's, more than its prior allows; the Hopf "
        "and fold intervals may miss (record closer to the fold, or check them by "
        "leave-one-out: bayeshopf.validation.leave_one_out)")


def diagnose(post, ppc: PosteriorPredictiveCheck | None = None) -> dict:
    """Convergence and fit checks of ``post``, with one warning line per failed check.

    ``post``: a :class:`~bayeshopf.hybrid_posterior.HybridPosterior`.

    * ``map``: gradient norm at the MAP and whether it is below the tolerance.
    * ``posterior``: NUTS R̂ and bulk ESS of μ0, a2, the fold (and ``w``) with
      the thresholds, divergences; SVI: the ELBO-plateau test.
    * ``fit``: each recording's orbit error (``orbit_error``), whether its
      amplitude lies in its 90% predictive band, and each channel's model error
      σ against the measured standard errors; with the frequency model, whether
      each measured frequency lies in its 90% predictive band.
    """
    warnings = []
    mp = post.map_point
    d = {"map": {"grad_norm": mp.grad_norm, "converged": mp.converged, "steps": mp.n_steps,
                 "polish_evaluations": mp.polish_evaluations, "tolerance": optimum.MAP_GTOL}}
    if not mp.converged:
        warnings.append(f"MAP: gradient norm {mp.grad_norm:.2g} after {mp.n_steps} L-BFGS steps "
                        f"and {mp.polish_evaluations} of the root find "
                        f"(tolerance {optimum.MAP_GTOL:g})")
    run = post.run
    if run.method == "nuts":
        conv = nuts.convergence(run.chains)
        d["posterior"] = {"method": "nuts", "chains": int(next(iter(run.chains.values())).shape[0]),
                          "divergences": run.divergences, "r_hat_max": nuts.RHAT_MAX,
                          "ess_min": nuts.ESS_MIN, "sites": conv, **run.sampler}
        for k, v in conv.items():
            if not v["ok"]:
                warnings.append(f"NUTS: {k} has R̂ {v['r_hat']:.3f} and bulk ESS "
                                f"{v['ess_bulk']:.0f} (need R̂ ≤ {nuts.RHAT_MAX}, "
                                f"ESS ≥ {nuts.ESS_MIN}) "
                                f"after {run.sampler.get('draws_per_chain', '?')} draws per chain "
                                f"(max_samples {post.settings.max_samples})")
        if run.divergences:
            warnings.append(f"NUTS: {run.divergences} divergent transitions")
        fell_back = run.sampler.get("importance")
        if fell_back:
            warnings.append(f"importance sampling: not used ({fell_back['fallback']}); the "
                            "posterior is NUTS's")
    elif run.method == "importance":
        d["posterior"] = {"method": "importance", **run.sampler}
    else:
        pl = svi.elbo_plateau(run.losses)
        d["posterior"] = {"method": "svi", "elbo_plateau": pl, "steps": int(run.losses.size)}
        if not pl["plateau"]:
            warnings.append(f"SVI: the −ELBO still falls ({pl['drop']:.3g} over the last 10% of "
                            f"the steps, ±{pl['se']:.2g})")
    ppc = ppc or post.ppc()
    errs = post.orbit_error()
    covered = ppc.covered
    sigma = np.median(np.asarray(post.samples["sigma"]), axis=0)
    se = np.median(post.features.coeffs_se[:, :, [1, 1 + post.spec.n_harmonics]], axis=(0, 2))
    ratio = sigma / se
    d["fit"] = {
        "orbit_error": errs,
        "amplitude_covered": [bool(c) for c in covered],
        "sigma": sigma.tolist(), "sigma_over_measured_se": ratio.tolist(),
        "sigma_over_orbit_scale": (sigma / post.spec.orbit_scale).tolist(),
        "sigma_rel": float(np.median(post.samples["sigma_rel"])),
    }
    if post.spec.has_discrepancy:
        total = np.hypot(np.asarray(post.samples["eta"]), np.asarray(post.samples["sigma_rel"]))
        d["fit"]["discrepancy"] = {
            "eta": post.interval("eta").to_json(), "ell": post.interval("ell").to_json(),
            "sigma_rel": post.interval("sigma_rel").to_json(),
            "relative": interval(total).to_json()}
        d["fit"]["sigma_rel"] = float(np.median(total))
    if post.spec.unfolding == "window":
        d["fit"]["fold_window"], line = fold_window_check(post.interval("depth_h"),
                                                          post.interval("width_h"))
        if line:
            warnings.append(line)
    if post.spec.samples_nu_mu:
        d["fit"]["nn_mu_scale"] = post.interval("nu_mu").to_json()
    if post.settings.extrapolation and post.extrapolation_scale > 0:
        d["fit"]["extrapolation_scale"] = {
            "scale": post.extrapolation_scale,
            "chosen_by": ("setting" if post.settings.extrapolation_scale is not None
                          else "model without the discrepancy")}
    for e in errs:
        if not e["ok"]:
            rel = "none" if e["relative"] is None else f"{100 * e['relative']:.1f}%"
            spread = "n/a" if e["spread"] is None else f"{100 * e['spread']:.1f}%"
            where = ""
            if e["by_harmonic"] is not None:
                parts = e["by_harmonic"]
                k = int(np.argmax(parts))
                where = f"; the largest part in {harmonic_name(k)}, {100 * parts[k]:.1f}%"
            warnings.append(f"fit: {e['name']}: orbit error {rel} of its size (limit "
                            f"{100 * ORBIT_ERROR_MAX:.0f}% or {ORBIT_SPREAD_FACTOR:g}× its "
                            f"segment spread {spread}){where}")
    for name, c in zip(post.features.names, covered, strict=True):
        if not c:
            warnings.append(f"fit: {name}: measured amplitude outside its 90% predictive band")
    for ch, r, sg in zip(post.spec.frame.names, ratio, sigma, strict=True):
        if r > SIGMA_RATIO_MAX and sg > SIGMA_ORBIT_FRACTION * post.spec.orbit_scale:
            warnings.append(f"fit: model error of {ch} is {r:.0f}× its measured standard error: "
                            "the map does not fit the orbits, the bands are wide for that reason")
    if post.has_frequency:
        d["fit"]["frequency"] = post.frequency_check()
        for e in d["fit"]["frequency"]:
            if not e["inside_ci90"]:
                warnings.append(f"fit: {e['name']}: measured frequency {e['measured_hz']:.4g} Hz "
                                "outside its 90% predictive band")
    rel = d["fit"]["sigma_rel"]
    if rel > SIGMA_REL_MAX and post.spec.has_discrepancy:
        warnings.append(
            f"fit: relative model error {100 * rel:.1f}% (limit {100 * SIGMA_REL_MAX:.0f}%): "
            "the model misses the orbits by that fraction; the model discrepancy carries it "
            "into the bands, which may still be too narrow (check them by leave-one-out: "
            "bayeshopf.validation.leave_one_out); "
            + (HOPF_FOLD_CAVEAT_MOVED if post.settings.mu_discrepancy > 0 else HOPF_FOLD_CAVEAT))
    elif rel > SIGMA_REL_MAX:
        warnings.append(f"fit: relative model error {100 * rel:.1f}% (limit "
                        f"{100 * SIGMA_REL_MAX:.0f}%): the model misses the orbits by that "
                        "fraction, and the predictive bands are that wide for that reason; "
                        "without the model discrepancy, bands of new measurements away from "
                        "the recordings are not calibrated for such a fit (check them by "
                        "leave-one-out: bayeshopf.validation.leave_one_out); "
                        + HOPF_FOLD_CAVEAT)
    if run.method == "importance" and not post.spec.has_discrepancy:
        warnings.append("posterior: importance sampling of a model without the discrepancy "
                        "can miss the long upper tail of μ0's posterior, which its check "
                        "cannot see; compare with NUTS (fit --nuts-check, or --inference "
                        "nuts; docs/inference.md)")
    elif rel > SIGMA_REL_MAX and run.method == "importance":
        warnings.append("posterior: importance sampling draws about the MAP, and the posterior "
                        "of a fit that misses the orbits this much can hold mass the draws do "
                        "not reach, which its check cannot see; compare with NUTS (fit "
                        "--nuts-check, or --inference nuts; docs/inference.md)")
    d["warnings"] = warnings
    return d


def orbit_errors(post, n_phi: int) -> list[dict]:
    """:meth:`~bayeshopf.posterior.HybridPosterior.orbit_error` of ``post``, at ``n_phi`` phases."""
    f = post.features
    phi = np.linspace(0, 2 * np.pi, n_phi, endpoint=False)
    out = []
    for i, c in enumerate(post.training_coefficients):
        c = c[np.all(np.isfinite(c), axis=(1, 2))]
        data = reconstruct(f.coeffs[i], phi)
        radius = float(np.sqrt(np.mean(np.sum((data - data.mean(0)) ** 2, -1))))
        if c.shape[0] == 0:
            out.append({"name": f.names[i], "relative": None, "spread": None, "ok": False,
                        "by_harmonic": None})
            continue
        median = np.median(c, axis=0)
        model = reconstruct(median, phi)
        rel = float(np.sqrt(np.mean(np.sum((model - data) ** 2, -1)))) / radius
        spread = float(f.segment_rms[i]) / radius
        out.append({"name": f.names[i], "relative": rel, "spread": spread,
                    "ok": bool(rel <= ORBIT_ERROR_MAX or rel <= ORBIT_SPREAD_FACTOR * spread),
                    "by_harmonic": (orbit_error_parts(median, f.coeffs[i]) / radius).tolist()})
    return out
