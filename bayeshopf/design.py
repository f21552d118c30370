r"""Which measurement next: expected shrinkage of the fold, the Hopf point or the diagram.

For a candidate recording at ``(μ, branch)`` the fit's posterior predicts what
the experimenter would measure. Every posterior draw ``θ_s`` (``s = 1…S``)
predicts the candidate's amplitude ``A_s`` (peak-to-peak of z1), and a new
recording scatters about it with the fit's own predictive error: the model
error ``σ_c, σ_rel`` of that draw, the measurement error of a recording of
similar amplitude (its segments' standard error) and the model discrepancy.
Write ``τ_s`` for that scatter's standard deviation (estimated from
:data:`N_REPLICATES` replicates per draw).

The extra model error away from the recordings enters at the fit's own scale
(:attr:`~bayeshopf.posterior.HybridPosterior.extrapolation_scale`: none with
the model discrepancy, :data:`~bayeshopf.model.collapsed.EXTRAPOLATION_SCALE`
without it, or the scale the fit was given). With the model discrepancy
(:mod:`bayeshopf.model.discrepancy`) each draw's amplitude instead includes a
draw of the discrepancy at the candidate, the same that ``predict`` and the
diagram's bands use.

The posterior of a target ``T`` (``μ_fold``, ``μ0``, or the amplitude at
each μ of the diagram) after measuring ``y`` is the current posterior
reweighted by the likelihood of ``y`` (importance sampling; no refit):

.. math::

    w_s(y) \propto \mathcal{N}(y;\, \bar A_s,\, τ_s^2)\,[\text{branch exists in } θ_s],

with ``Ā_s`` the mean of the draw's replicates. Its expectation over what
would be measured takes ``y_m`` from the predictive of each draw ``m`` (nested
Monte Carlo over the same draws). By the law of total variance the expected
posterior variance is below the current one; the expected ``ci`` width after
the measurement is the current width scaled by the square root of that ratio,

.. math::

    \mathbb{E}[\text{width}] = \text{width}_{90\%}(T)\,
    \sqrt{\frac{\frac{1}{M}\sum_m \mathrm{Var}_{w(y_m)}(T)}{\mathrm{Var}(T)}},

averaged over the diagram's μ grid (both branches) for ``"diagram"``.

The *gain* of a candidate is the current 90% width of ``T`` less that
expectation. Only the amplitude enters ``y``: a new recording also carries its
orbit's shape, which a refit also uses, so a refit may shrink the target more
than predicted. A candidate is skipped, and never recommended, where fewer
than ``min_p_exists`` of the draws have the branch (the orbit may not be there
to measure) or where its predicted median amplitude is below ``min_amplitude``
(an orbit too small for the rig to hold or resolve).
Observing the orbit rules out the draws without it, which is why candidates
near the fold can inform the fold.

The reweighting is trustworthy while the weights do not collapse onto a few
draws: the table reports each candidate's mean effective sample size
``(Σ w)² / Σ w²``.

The expectation over outcomes is an average over ``M`` simulated
measurements, so the gain carries a Monte Carlo standard error. With
``v_{mg} = \mathrm{Var}_{w(y_m)}(T_g)``, ``r_g = \bar v_g / \mathrm{Var}(T_g)``
and ``W_g`` the current width of column ``g`` (one column unless ``"diagram"``),
the expected width is ``\frac1G \sum_g W_g \sqrt{r_g}``; linearised in the
outcomes (delta method), each outcome contributes

.. math::

    L_m = \frac{1}{G}\sum_g \frac{W_g}{2\sqrt{r_g}\,\mathrm{Var}(T_g)}\, v_{mg},
    \qquad \mathrm{se} = \mathrm{sd}_m(L_m) / \sqrt{M}.

It is the error of the outer average only (the draws held fixed), the part
that a new ``seed`` changes. Since the expected posterior variance cannot
exceed the current one, the expected width after is clipped at the current
width and the gain at zero; a gain within :data:`NO_GAIN_SE` standard errors
of zero is reported as "no gain".

A *resolution* ``δμ`` (the smallest airspeed step the rig sets and holds)
merges candidates: on one branch, a recommended candidate suppresses every
other within ``δμ`` of it (the best of each cluster is kept, greedily by
gain), and for the fold and the Hopf point a gain below ``δμ`` is flagged as
below the tunnel's resolution: it narrows the interval by less than the rig
can tell apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayeshopf.diagnostics.summaries import CI
from bayeshopf.errors import FitError
from bayeshopf.predictive import N_BAND_DRAWS as N_DRAWS  # the bands' draws, aligned

__all__ = ["Candidate", "DesignResult", "NO_GAIN_SE", "TARGETS", "candidate_grid",
           "next_measurements"]

#: What a design can target: the fold ``μ_SN``, the Hopf point ``μ0``, the diagram's band.
TARGETS = ("fold", "hopf", "diagram")
#: Predictive replicates per draw used to estimate the measurement scatter ``τ_s``.
N_REPLICATES = 16
#: A gain within this many Monte Carlo standard errors of zero is reported as "no gain".
NO_GAIN_SE = 2.0
#: Note of a gain below the resolution in μ.
BELOW_RESOLUTION = "below the tunnel's resolution"


@dataclass(frozen=True)
class Candidate:
    """One candidate measurement and what it is expected to do (immutable).

    Attributes:
        mu: Where.
        branch: ``"stable"`` or ``"unstable"``.
        p_exists: Posterior probability that the branch exists there.
        amplitude: Predicted amplitude (median, lower, upper of the ``ci`` band), or
            NaN when skipped.
        width_now: The target's current ``ci`` width (μ units; amplitude units
            for ``"diagram"``: the mean band width over the diagram).
        width_after: Its expected width after the measurement (NaN when skipped).
        gain: ``width_now − width_after``, never negative (NaN when skipped).
        ess: Mean effective sample size of the importance weights.
        skipped: Why the candidate was skipped (``""`` when it was not).
        gain_mcse: Monte Carlo standard error of ``gain`` (NaN when skipped).
        note: What limits the gain: ``"no gain"`` (within :data:`NO_GAIN_SE`
            standard errors of zero), :data:`BELOW_RESOLUTION`, or
            ``"merged into μ = …"`` (within the resolution of a better
            candidate on its branch); ``""`` otherwise.
    """

    mu: float
    branch: str
    p_exists: float
    amplitude: tuple[float, float, float]
    width_now: float
    width_after: float
    gain: float
    ess: float
    skipped: str = ""
    gain_mcse: float = float("nan")
    note: str = ""


@dataclass(frozen=True)
class DesignResult:
    """Candidates ranked by expected gain (immutable; :func:`next_measurements`).

    Attributes:
        target: ``"fold"``, ``"hopf"`` or ``"diagram"``.
        candidates: Every candidate, in grid order (both branches).
        recommended: The ``n`` best, best first.
        width_now: The target's current width.
        ci: Mass of the intervals.
        mu_label: Name of μ.
        mu_units: Unit of μ.
        amplitude_units: Unit of the amplitude.
        amplitude_label: What the amplitude is (``"peak-to-peak of h"``: the
            fit's first planar channel).
        min_p_exists: Share of draws a candidate's branch must exist in.
        min_amplitude: Smallest predicted amplitude recommended (0: no limit).
        resolution: Resolution in μ (0: none).
    """

    target: str
    candidates: tuple[Candidate, ...]
    recommended: tuple[Candidate, ...]
    width_now: float
    ci: float
    mu_label: str = "mu"
    mu_units: str = ""
    amplitude_units: str = ""
    amplitude_label: str = "peak-to-peak of z1"
    min_p_exists: float = 0.9
    min_amplitude: float = 0.0
    resolution: float = 0.0

    def ranked(self) -> tuple[Candidate, ...]:
        """Every candidate, best first.

        The recommended by rank, then the rest by gain (highest first), then the
        skipped in grid order.
        """
        rec = {(c.mu, c.branch) for c in self.recommended}
        rest = [c for c in self.candidates if (c.mu, c.branch) not in rec]
        ok = sorted((c for c in rest if not c.skipped), key=lambda c: -np.nan_to_num(
            c.gain, nan=-np.inf))
        return tuple(self.recommended) + tuple(ok) + tuple(c for c in rest if c.skipped)

    def to_dataframe(self):
        """The candidates as a :class:`pandas.DataFrame`, one row each.

        Sorted as :meth:`ranked`: ``rank`` 1…n for the recommended, missing otherwise.
        """
        import pandas as pd

        rank = {(c.mu, c.branch): i + 1 for i, c in enumerate(self.recommended)}
        rows = [{"rank": rank.get((c.mu, c.branch)), "mu": c.mu, "branch": c.branch,
                 "p_exists": c.p_exists, "amplitude": c.amplitude[0],
                 "amplitude_lo": c.amplitude[1], "amplitude_hi": c.amplitude[2],
                 "width_now": c.width_now, "width_after": c.width_after, "gain": c.gain,
                 "gain_mcse": c.gain_mcse, "ess": c.ess, "note": c.note,
                 "skipped": c.skipped}
                for c in self.ranked()]
        df = pd.DataFrame(rows)
        df["rank"] = df["rank"].astype("Int64")
        return df

    def to_json(self) -> dict:
        """A JSON-ready dict (NaN as ``None``)."""
        def fin(x):
            return float(x) if np.isfinite(x) else None

        def row(c: Candidate) -> dict:
            return {"mu": c.mu, "branch": c.branch, "p_exists": c.p_exists,
                    "amplitude": [fin(a) for a in c.amplitude], "width_now": fin(c.width_now),
                    "width_after": fin(c.width_after), "gain": fin(c.gain),
                    "gain_mcse": fin(c.gain_mcse), "ess": fin(c.ess), "note": c.note,
                    "skipped": c.skipped}

        return {"target": self.target, "ci": self.ci, "width_now": fin(self.width_now),
                "mu_label": self.mu_label, "mu_units": self.mu_units,
                "amplitude_units": self.amplitude_units,
                "amplitude_label": self.amplitude_label, "min_p_exists": self.min_p_exists,
                "min_amplitude": self.min_amplitude, "resolution": self.resolution,
                "recommended": [row(c) for c in self.recommended],
                "candidates": [row(c) for c in self.candidates]}


def candidate_grid(fit, n: int = 41) -> np.ndarray:
    """Default candidates: ``n`` μ from the lower end of the fold's band to beyond the data."""
    lo = (float(np.quantile(fit.bifurcation("mu_fold"), 0.05)) if "mu_fold" in fit.samples
          else fit.spec.mu_min)
    hi = max(fit.spec.mu_min + fit.spec.mu_span, float(np.quantile(fit.bifurcation("mu0"), 0.95)))
    return np.linspace(lo, hi, n)


def parse_candidates(text: str) -> np.ndarray:
    """``"MIN:MAX:STEP"`` as a grid (both ends included), or a ``ValueError`` that says why."""
    parts = text.split(":")
    if len(parts) != 3:
        raise ValueError(f"candidates 'MU_MIN:MU_MAX:STEP' expected; found {text!r}")
    lo, hi, step = (float(p) for p in parts)
    if not (np.isfinite([lo, hi, step]).all() and step > 0 and hi >= lo):
        raise ValueError(f"candidates with MU_MIN <= MU_MAX and STEP > 0 expected; found {text!r}")
    n = int(np.floor((hi - lo) / step + 1e-9)) + 1
    if n > 2000:
        raise ValueError(f"at most 2000 candidates expected; {text!r} gives {n}")
    return lo + step * np.arange(n)


def _variances(values: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Current variance ``(G,)`` and each outcome's reweighted variance ``(M, G)``.

    ``values`` ``(S, G)`` (NaN: no branch); ``weights`` ``(M, S)``: one row of
    normalised importance weights per outcome.
    """
    have = np.isfinite(values)
    x = np.where(have, values, 0.0)
    h = have.astype(float)

    def var(w):
        wh = np.maximum(w @ h, 1e-300)
        mean = (w @ x) / wh
        return np.maximum((w @ (x * x)) / wh - mean**2, 0.0)

    return var(np.full((1, values.shape[0]), 1.0 / values.shape[0]))[0], var(weights)


def _expected_var_ratio(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``E_m[Var_{w_m}(x)] / Var(x)`` per column of ``values`` ``(S, G)`` (NaN: no branch).

    ``weights`` ``(M, S)``: one row of normalised importance weights per outcome.
    By the law of total variance the expected posterior variance is below the
    current one; the ratio estimates how much of it a measurement leaves.
    """
    now, v = _variances(values, weights)
    return np.where(now > 0, v.mean(axis=0) / np.where(now > 0, now, 1.0), 1.0)


def _expected_width(values: np.ndarray, widths: np.ndarray,
                    weights: np.ndarray) -> tuple[float, float]:
    """Expected mean width after the measurement and its Monte Carlo standard error.

    ``mean_g W_g sqrt(r_g)`` and ``sd_m(L_m)/sqrt(M)`` of the module docstring
    (delta method over the ``M`` outcomes, the draws held fixed).
    """
    now, v = _variances(values, weights)
    pos = now > 0
    ratio = np.where(pos, v.mean(axis=0) / np.where(pos, now, 1.0), 1.0)
    after = float(np.mean(widths * np.sqrt(ratio)))
    m = v.shape[0]
    if m < 2:
        return after, float("nan")
    slope = np.where(pos & (ratio > 0), widths / (2.0 * np.sqrt(np.maximum(ratio, 1e-300))
                                                  * np.where(pos, now, 1.0)), 0.0)
    influence = v @ slope / v.shape[1]                                      # (M,)
    return after, float(np.std(influence, ddof=1) / np.sqrt(m))


def _band_widths(values: np.ndarray, ci: float) -> tuple[np.ndarray, np.ndarray]:
    """Current ``ci`` width of each column of ``values`` ``(S, G)`` and whether it counts.

    A column counts where at least half of the draws have a value (the branch exists).
    """
    keep = np.isfinite(values).mean(axis=0) >= 0.5
    q = np.full((2, values.shape[1]), np.nan)
    if keep.any():
        q[:, keep] = np.nanquantile(values[:, keep], [0.5 - ci / 2, 0.5 + ci / 2], axis=0)
    return q[1] - q[0], keep


def _replicates(fit, coeffs, mu, branch: str, se, rng) -> np.ndarray:
    """Predictive amplitudes of a new recording, ``(S, R)`` per draw (NaN: no branch).

    ``coeffs`` are the fit's orbits at μ
    (:meth:`~bayeshopf.posterior.HybridPosterior.orbit_coefficients`, with the
    model discrepancy where the fit has it); the noise is the fit's own
    new-measurement noise (``noise_sd``), the one path every prediction takes.
    """
    from bayeshopf import predictive as pr

    c = np.repeat(coeffs[:, None], N_REPLICATES, axis=1)            # (S, R, 1, 2, 2K+1)
    scale = fit.extrapolation_scale
    if fit.settings.extrapolation and scale > 0:
        f = fit.features
        mu_data = f.mu[f.unstable == (branch == "unstable")]
        factor = pr.extrapolation_factor([mu], mu_data, fit.spec.mu_span,
                                         c.shape[0] * N_REPLICATES, int(rng.integers(2**31)),
                                         scale=scale)
        c = pr.scale_orbits(c.reshape((-1,) + c.shape[2:]), factor).reshape(c.shape)
    if fit.spec.has_discrepancy:
        sd = fit.noise_sd(coeffs, se, [mu], branch)[:, None]         # (S, 1, 1, 2, 2K+1)
    else:
        idx = pr.draw_indices(len(fit.samples["sigma"]), N_DRAWS)
        sd = pr.noise_sd(c, np.asarray(fit.samples["sigma"])[idx],
                         np.asarray(fit.samples["sigma_rel"])[idx], se)
    return pr.amplitude_of(fit.spec, c + sd * rng.standard_normal(c.shape))[..., 0]


def _similar_se(fit, amplitude: float) -> np.ndarray:
    """Standard errors of the training recording whose amplitude is closest to ``amplitude``."""
    f = fit.features
    i = int(np.argmin(np.abs(np.asarray(f.amplitude) - amplitude)))
    return np.asarray(f.coeffs_se[i])


def next_measurements(fit, *, target: str = "fold", candidates=None,
                      branch: str = "both", n: int = 3, ci: float = CI,
                      min_p_exists: float = 0.9, min_amplitude: float = 0.0,
                      resolution: float = 0.0, seed: int = 0) -> DesignResult:
    """Rank candidate ``(μ, branch)`` measurements by the expected shrinkage of a target.

    See the module docstring for the method.

    Args:
        fit: A :class:`~bayeshopf.posterior.HybridPosterior` (or a loaded fit's
            ``.posterior``).
        target: ``"fold"`` (``μ_SN``), ``"hopf"`` (``μ0``) or ``"diagram"`` (the
            mean sd of the amplitude over the diagram's μ range, both branches).
        candidates: μ values (default :func:`candidate_grid`).
        branch: ``"stable"``, ``"unstable"`` or ``"both"``.
        n: How many to recommend.
        ci: Mass of the intervals (0.9).
        min_p_exists: Skip a candidate whose branch exists in a smaller share of
            the draws.
        min_amplitude: Skip a candidate whose predicted median amplitude (the
            fit's amplitude units) is below it; 0 (default) skips none.
        resolution: Resolution in μ (μ units; 0, the default, for none): on one
            branch, recommended candidates lie more than ``resolution`` apart,
            and for ``"fold"`` and ``"hopf"`` a gain below it is noted
            (:data:`BELOW_RESOLUTION`).
        seed: Seed of the simulated measurements.

    Returns:
        A :class:`DesignResult`.

    Raises:
        FitError: For an unknown target or branch, a ``"fold"`` target on a fit
            without a fold (supercritical), no candidate, or a ``min_p_exists``
            outside ``[0, 1]``, a negative ``min_amplitude`` or ``resolution``.
    """
    from bayeshopf import predictive as pr

    if target not in TARGETS:
        raise FitError(f"target must be one of {', '.join(TARGETS)}; got {target!r}")
    if branch not in ("stable", "unstable", "both"):
        raise FitError(f"branch must be 'stable', 'unstable' or 'both'; got {branch!r}")
    if not 0 < ci < 1:
        raise FitError(f"ci must lie strictly between 0 and 1; got {ci!r}")
    if n < 1:
        raise FitError(f"n must be at least 1; got {n!r}")
    if not 0 <= min_p_exists <= 1:
        raise FitError(f"min_p_exists must lie in [0, 1]; got {min_p_exists!r}")
    for name, v in (("min_amplitude", min_amplitude), ("resolution", resolution)):
        if not (np.isfinite(v) and v >= 0):
            raise FitError(f"{name} must be finite and at least 0; got {v!r}")
    if target == "fold" and "mu_fold" not in fit.samples:
        raise FitError("target 'fold' needs a subcritical fit (this one has no fold); "
                       "use target='hopf' or 'diagram'")
    branches = ("stable", "unstable") if branch == "both" else (branch,)
    if fit.criticality == "supercritical":
        branches = tuple(b for b in branches if b == "stable")
        if not branches:
            raise FitError("a supercritical fit has no unstable branch to measure")
    mu = candidate_grid(fit) if candidates is None else np.atleast_1d(
        np.asarray(candidates, dtype=float))
    if mu.size == 0 or not np.all(np.isfinite(mu)):
        raise FitError(f"finite candidate μ expected; got {mu!r}")

    idx = pr.draw_indices(len(fit.samples["mu0"]), N_DRAWS)
    rng = np.random.default_rng([seed, 22])
    if target == "diagram":
        grid = fit.default_mu_grid(60)
        values = np.concatenate([fit.amplitude(grid, b) for b in fit_branches(fit)], axis=1)
    else:
        values = fit.bifurcation("mu_fold" if target == "fold" else "mu0")[idx, None]
    widths, keep = _band_widths(values, ci)
    values, widths = values[:, keep], widths[keep]
    width_now = float(np.mean(widths))

    rows = []
    for b in branches:
        coeffs = fit.orbit_coefficients(mu, b, N_DRAWS)                  # (S, n_mu, 2, 2K+1)
        amp = pr.amplitude_of(fit.spec, coeffs)                           # (S, n_mu)
        for j, m in enumerate(mu):
            a = amp[:, j]
            have = np.isfinite(a)
            p = float(have.mean())
            why = ""
            if p < min_p_exists or not have.any():
                why = (f"the {b} branch exists in {100 * p:.0f}% of the draws "
                       f"(< {100 * min_p_exists:.0f}%)")
            elif float(np.median(a[have])) < min_amplitude:
                why = (f"predicted amplitude {float(np.median(a[have])):.4g} "
                       f"{fit.amplitude_units} below the minimum {min_amplitude:.4g} "
                       f"{fit.amplitude_units}").replace("  ", " ")
            if why:
                rows.append(Candidate(float(m), b, p, (np.nan,) * 3, width_now, np.nan, np.nan,
                                      np.nan, why))
                continue
            se = _similar_se(fit, float(np.median(a[have])))
            reps = _replicates(fit, coeffs[:, j:j + 1], float(m), b, se, rng)   # (S, R)
            # each draw's predictive mean and scatter (the peak-to-peak of a noisy
            # orbit is biased up, so the mean of the replicates, not A_s)
            centre, t = np.zeros(a.shape), np.ones(a.shape)
            centre[have] = np.mean(reps[have], axis=1)
            t[have] = np.std(reps[have], axis=1, ddof=1)
            y = reps[have, 0]                                    # outcomes, one per draw
            q = np.nanquantile(reps[have].ravel(), [0.5, 0.5 - ci / 2, 0.5 + ci / 2])
            logw = np.where(have[None], -0.5 * ((y[:, None] - centre[None]) / t[None]) ** 2
                            - np.log(t)[None], -np.inf)
            w = np.exp(logw - logw.max(axis=1, keepdims=True))
            w /= w.sum(axis=1, keepdims=True)
            ess = float(np.mean(1.0 / np.sum(w**2, axis=1)))
            after, mcse = _expected_width(values, widths, w)
            after = min(after, width_now)          # E[Var after] <= Var now: clip the noise
            gain = width_now - after
            note = ("no gain" if not gain > NO_GAIN_SE * mcse
                    else BELOW_RESOLUTION if target != "diagram" and gain < resolution else "")
            rows.append(Candidate(float(m), b, p, (float(q[0]), float(q[1]), float(q[2])),
                                  width_now, after, gain, ess, "", mcse, note))
    if not rows:
        raise FitError("no candidate to rank")
    rows, recommended = _recommend(rows, n, mu, resolution)
    return DesignResult(target, tuple(rows), recommended, width_now, ci,
                        fit.mu_label, fit.mu_units, fit.amplitude_units,
                        f"peak-to-peak of {fit.spec.frame.names[0]}", float(min_p_exists),
                        float(min_amplitude), float(resolution))


def fit_branches(fit) -> tuple[str, ...]:
    """The branches a fit has: both for a subcritical fit, the stable one otherwise."""
    return ("stable", "unstable") if fit.criticality == "subcritical" else ("stable",)


def _recommend(rows: list[Candidate], n: int, mu: np.ndarray,
               resolution: float = 0.0) -> tuple[list[Candidate], tuple[Candidate, ...]]:
    """The ``n`` best by gain, and the rows with the merged ones noted.

    On one branch, the kept candidates lie at least two grid steps apart and
    more than ``resolution`` apart: greedily by gain, each kept candidate
    suppresses the others within that distance (noted ``"merged into μ = …"``
    when the distance is within ``resolution``).
    """
    from dataclasses import replace

    u = np.unique(mu)
    step = float(np.min(np.diff(u))) if u.size > 1 else 0.0
    ok = sorted((i for i, c in enumerate(rows) if not c.skipped and np.isfinite(c.gain)),
                key=lambda i: -rows[i].gain)
    rows = list(rows)
    kept: list[int] = []
    for i in ok:
        c = rows[i]
        near = [rows[k] for k in kept if rows[k].branch == c.branch
                and abs(rows[k].mu - c.mu) <= resolution + 1e-12]
        if near:
            rows[i] = replace(c, note="; ".join(
                x for x in (c.note, f"merged into μ = {near[0].mu:.6g}") if x))
            continue
        if len(kept) < n and all(rows[k].branch != c.branch
                                 or abs(rows[k].mu - c.mu) >= 2 * step - 1e-12 for k in kept):
            kept.append(i)
    return rows, tuple(rows[k] for k in kept)
