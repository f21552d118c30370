"""The fitted hybrid model: its record and what it predicts.

A :class:`HybridPosterior` holds the posterior draws of the normal form and the
hyperparameters, one exact draw of the map per draw, the convergence
diagnostics, and methods for orbits, amplitudes, the bifurcation diagram, the
posterior predictive check and each recording's orbit error, all through the
one prediction path (:mod:`bayeshopf.predictive`).
:func:`~bayeshopf.posterior.fit_hybrid` builds it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from bayeshopf.data.recording import RecordingSet
from bayeshopf.diagnostics.bands import FrequencyBand, TimeSeriesBand, time_series_bands
from bayeshopf.diagnostics.bifurcation import BranchBand, DiagramBands, quantiles
from bayeshopf.diagnostics.bifurcation import levels as band_levels
from bayeshopf.diagnostics.control import control_gain
from bayeshopf.diagnostics.fit_checks import orbit_errors
from bayeshopf.diagnostics.ppc import PosteriorPredictiveCheck
from bayeshopf.diagnostics.summaries import CI, Interval, interval
from bayeshopf.errors import FitError
from bayeshopf.features.harmonics import HarmonicFeatures, reconstruct, time_design
from bayeshopf.inference import collapsed as ci
from bayeshopf.model import collapsed as cm
from bayeshopf.model import normal_form
from bayeshopf.model.normal_form import branch_sign
from bayeshopf.predictive import (
    N_BAND_DRAWS,
    _common_over_mu,
    amplitude_of,
    discrepancy_draws,
    draw_indices,
    extrapolation_factor,
    frequency_draws,
    frequency_noise,
    network_draws,
    noise_sd,
    orbit_coefficients,
    scale_orbits,
)

#: Phases per predicted orbit.
N_PHI = 64
#: Suffix of the rig's Hopf point and fold among the draws (``mu0_rig``,
#: ``mu_fold_rig``): the normal form's moved by the discrepancy in μ
#: (:func:`~bayeshopf.posterior.with_rig_bifurcations`).
RIG = "_rig"


@dataclass(frozen=True)
class HybridPosterior:
    """A fitted Bayesian hybrid model on the collapsed core (immutable).

    Attributes:
        spec: Structure and data constants of the model.
        features: The training features.
        map_point: The MAP stage.
        run: The posterior stage (draws, map draws, diagnostics inputs).
        settings: Settings used.
        seed: Seed used.
        mu_label: Name of μ.
        mu_units: Unit of μ.
        amplitude_units: Unit of the amplitude (z1's).
        timings: Seconds per stage.
        diagnostics: Convergence and fit checks
            (:func:`~bayeshopf.diagnostics.fit_checks.diagnose`).
    """

    spec: cm.CollapsedSpec
    features: HarmonicFeatures
    map_point: ci.MapPoint
    run: ci.PosteriorRun
    settings: ci.CollapsedSettings
    seed: int
    mu_label: str
    mu_units: str
    amplitude_units: str
    timings: dict = field(default_factory=dict, compare=False)
    diagnostics: dict = field(default_factory=dict, compare=False)

    @property
    def criticality(self) -> str:
        """``"subcritical"`` or ``"supercritical"``."""
        return self.spec.criticality

    @property
    def samples(self) -> dict:
        """Posterior draws of every site, chains pooled."""
        return self.run.samples

    @property
    def theta(self) -> dict:
        """Draws of the nonlinear parameters the map and orbits need."""
        return {k: v for k, v in self.samples.items()
                if not k.startswith("marginal") and not k.endswith(RIG)}

    def bifurcation(self, name: str) -> np.ndarray:
        """Draws of the Hopf point (``"mu0"``) or the fold (``"mu_fold"``) of the rig.

        With the discrepancy in μ, the normal form's points moved by it
        (``mu0_rig``, ``mu_fold_rig``); else the normal form's own.
        """
        s = self.samples
        return np.asarray(s.get(name + RIG, s[name]))

    @property
    def extrapolation_scale(self) -> float:
        """The scale ``S`` of the extra model error away from the recordings.

        ``settings.extrapolation_scale`` when it is set (a user's override);
        otherwise 0 with the discrepancy, whose Gaussian process already widens the
        bands away from the recordings, and
        :data:`~bayeshopf.model.collapsed.EXTRAPOLATION_SCALE` without it.
        """
        s = self.settings.extrapolation_scale
        if s is not None:
            return float(s)
        return 0.0 if self.spec.has_discrepancy else cm.EXTRAPOLATION_SCALE

    def interval(self, name: str, mass: float = 0.9) -> Interval | None:
        """Median and central interval of a site (``mu0``, ``a2``, ``mu_fold``, …), or None.

        ``mu0`` and ``mu_fold`` are the rig's (:meth:`bifurcation`); ``mu0_rig``
        and ``mu_fold_rig`` name them too where the discrepancy in μ moved them.
        """
        if name not in self.samples:
            return None
        if name in ("mu0", "mu_fold"):
            return interval(self.bifurcation(name), mass)
        return interval(self.samples[name], mass)

    # ----------------------------------------------------------------- orbits
    def _draw_indices(self, n: int | None) -> np.ndarray:
        return draw_indices(self.run.betas.shape[0], n)

    @cached_property
    def _branch_knots(self) -> dict | None:
        """Where each branch of the rig lies, per draw, or ``None`` without the rig's points.

        :func:`~bayeshopf.model.bifurcation_shift.branch_knots`; without the
        discrepancy in μ the branches are the model's own.
        """
        s = self.samples
        if "mu0" + RIG not in s:
            return None
        import jax

        from bayeshopf.model.bifurcation_shift import branch_knots

        f = self.features
        rig = {k: s[k + RIG] for k in ("mu0", "mu_fold") if k + RIG in s}
        return branch_knots(self.spec, self.theta, rig, f.mu, np.where(f.unstable, -1.0, 1.0),
                            self.settings.mu_discrepancy,
                            jax.random.fold_in(jax.random.PRNGKey(self.seed), 1),
                            floor=self.settings.mu_discrepancy_floor)

    def model_mu(self, mu, branch: str = "stable", n_draws: int | None = N_BAND_DRAWS):
        """The model's μ of the point the rig has at each ``mu`` on ``branch``, ``(n, n_mu)``.

        With the discrepancy in μ, each branch of the rig is the model's moved
        along μ (:func:`~bayeshopf.model.bifurcation_shift.branch_knots`: the
        same at the recordings, ending at the rig's Hopf point and fold), so a
        prediction at μ is the model's at this μ; without it, ``mu`` itself
        for every draw.
        """
        from bayeshopf.model.bifurcation_shift import model_mu

        mu = np.atleast_1d(np.asarray(mu, dtype=float))
        idx = self._draw_indices(n_draws)
        knots = self._branch_knots
        if knots is None:
            return np.broadcast_to(mu, (idx.size, mu.size))
        model, rig = knots[branch_sign(branch)]
        return model_mu(mu, model[idx], rig[idx])

    def orbit_coefficients(self, mu, branch: str = "stable", n_draws: int | None = N_BAND_DRAWS,
                           control=None):
        """Harmonic coefficients of the predicted orbits in the frame, ``(n, n_mu, 2, 2K+1)``.

        The model orbit at μ, projected on the K harmonics the data have, plus,
        with the model discrepancy, a draw of the discrepancy there
        (:func:`discrepancy_draws`: the rig's orbit, not the normal form's
        alone; ``nan`` where the branch does not exist in a draw), and at
        infinite width the network's spread away from the recordings
        (:func:`network_draws`); with ``control``
        ``(n_mu, 2)`` (a recording's control fundamental), the orbit held with
        that control, else the uncontrolled system's. With the discrepancy in
        μ, all of it at the model's point that the rig has at μ (:meth:`model_mu`).
        Computed once per μ, branch, draws and control, and shared (read-only).
        """
        def compute(theta, idx, mu):
            at = self.model_mu(mu, branch, n_draws)
            c = orbit_coefficients(self.spec, theta, self.run.betas[idx], at,
                                   branch_sign(branch), per_draw=True, control=control)
            if self.spec.nn_training is not None:
                c = c + network_draws(self.spec, theta, at, branch_sign(branch), self.seed)
            if self.spec.has_discrepancy:
                c = c + self._discrepancy(mu, branch, n_draws)[0]
            c.flags.writeable = False         # shared by every caller (memo)
            return c

        return self._memo("orbits", mu, branch, n_draws, compute, control)

    @cached_property
    def _draw_memo(self) -> dict:
        return {}

    def _memo(self, what: str, mu, branch: str, n_draws: int | None, compute, control=None):
        """``compute(θ of the draws, their indices, μ)``, once per what, μ, branch, draws, control.

        The figures, the predictive check and the summary share them.
        """
        mu = np.atleast_1d(np.asarray(mu, dtype=float))
        key = (what, mu.tobytes(), branch, n_draws, np.asarray(control, float).tobytes())
        memo = self._draw_memo
        if key not in memo:
            if len(memo) >= 64:
                memo.clear()
            idx = self._draw_indices(n_draws)
            memo[key] = compute({k: v[idx] for k, v in self.theta.items()}, idx, mu)
        return memo[key]

    def _discrepancy(self, mu, branch: str, n_draws: int | None = N_BAND_DRAWS):
        """:func:`discrepancy_draws` at μ for the draws of ``n_draws``, once per μ and branch.

        A prediction needs both its parts (the draw for the orbit, the
        independent variance for the noise); they come from one computation.
        """
        return self._memo("discrepancy", mu, branch, n_draws, lambda theta, idx, mu:
                          discrepancy_draws(self.spec, theta, self.run.betas[idx], self.features,
                                            self.model_mu(mu, branch, n_draws),
                                            branch_sign(branch), self.seed))

    def recording_control(self, i: int):
        """Recording ``i``'s control fundamental ``(1, 2)`` with the control term, else None."""
        if self.spec.control_scale is None or self.features.control is None:
            return None
        return np.asarray(self.features.control)[i][None]

    def noise_sd(self, coeffs, coeffs_se=None, mu=None, branch: str = "stable"):
        """Predictive sd of a new recording's coefficients (model error + se), as ``coeffs``.

        The one noise every prediction of a new recording takes (``predict``,
        the checks, ``next``). With the discrepancy, its independent part ``σ_rel g`` at ``mu`` (the
        μ of ``coeffs``' second axis, or of a training recording for ``coeffs``
        of one μ) replaces ``σ_rel c``.
        """
        idx = self._draw_indices(N_BAND_DRAWS)
        se = np.median(self.features.coeffs_se, axis=0) if coeffs_se is None else coeffs_se
        sigma = np.asarray(self.samples["sigma"])[idx]
        if not self.spec.has_discrepancy:
            return noise_sd(coeffs, sigma, np.asarray(self.samples["sigma_rel"])[idx], se)
        nugget = self._discrepancy(mu, branch)[1].reshape(np.shape(coeffs))
        extra = (1,) * (np.ndim(coeffs) - 3)
        s2 = sigma.reshape((-1,) + extra + (2, 1)) ** 2
        return np.sqrt(np.asarray(se) ** 2 + s2 + nugget)

    def orbits(self, mu: float, branch: str = "stable", n_draws: int | None = N_BAND_DRAWS,
               control=None):
        """Predicted orbits in physical units at one μ, ``(n, N_PHI, 2)``.

        ``control`` ``(1, 2)``: a recording's control fundamental
        (:meth:`recording_control`), for the orbit as it was held.
        """
        c = self.orbit_coefficients([mu], branch, n_draws, control=control)[:, 0]
        phi = np.linspace(0, 2 * np.pi, N_PHI, endpoint=False)
        return self.spec.frame.from_frame(reconstruct(c, phi))

    def _amplitude_of(self, coeffs):
        return amplitude_of(self.spec, coeffs)

    def amplitude(self, mu, branch: str = "stable", predictive: bool = False,
                  coeffs_se=None, control=None) -> np.ndarray:
        """Amplitude draws (peak-to-peak of z1) at μ, ``(n, n_mu)``; ``nan`` where no LCO.

        ``predictive=True`` gives a new recording's amplitude: the model's
        coefficients plus Gaussian noise with the model error σ and the
        standard error ``coeffs_se`` (by default the training recordings'
        median), one set of standard normals per draw for every μ, so that each
        μ's column is that μ's prediction alone and a band over μ is smooth.
        ``control`` ``(n_mu, 2)``: a new recording's measured control
        fundamental (:meth:`orbit_coefficients`).
        """
        c = self.orbit_coefficients(mu, branch, control=control)
        if predictive:
            c = self._away_from_data(c, mu, branch)
            rng = np.random.default_rng(self.seed)
            c = c + self.noise_sd(c, coeffs_se, mu, branch) * _common_over_mu(rng, c.shape)
        return self._amplitude_of(c)

    def _away_from_data(self, coeffs, mu, branch: str) -> np.ndarray:
        """Predicted orbits with the model error away from the recordings (when enabled).

        :func:`extrapolation_factor` from this branch's training μ; zero at them.
        """
        if not self.settings.extrapolation or self.extrapolation_scale == 0:
            return coeffs
        f = self.features
        mu_data = f.mu[f.unstable == (branch == "unstable")]
        return scale_orbits(coeffs, extrapolation_factor(
            mu, mu_data, self.spec.mu_span, np.shape(coeffs)[0], self.seed,
            scale=self.extrapolation_scale))

    def control_gain(self, ci: float = CI) -> dict | None:
        """The orbits' response to the control's fundamental, or ``None`` without the term.

        :func:`~bayeshopf.diagnostics.control.control_gain` of this fit's draws.
        """
        return control_gain(self.spec, self.run.betas, self.features, ci)

    # ----------------------------------------------------------------- frequency
    @property
    def has_frequency(self) -> bool:
        """Whether the model includes the frequency ``Ω(r, μ)``."""
        return self.run.gammas is not None

    def frequency(self, mu, branch: str = "stable", predictive: bool = False,
                  omega_se: float | None = None, n_draws: int | None = N_BAND_DRAWS
                  ) -> np.ndarray:
        """Frequency draws (Hz) at μ, ``(n, n_mu)``; ``nan`` where the branch does not exist.

        The curve is ``Ω(r(μ), μ)/2π`` (:func:`~bayeshopf.model.collapsed.frequency`);
        ``predictive=True`` adds a new recording's error ``N(0, σ_ω² + se²)``, with
        ``omega_se`` its standard error (rad/s; by default the training median);
        the curve is computed once per μ, branch and draws, and shared (read-only).

        Raises:
            FitError: For a fit without the frequency model.
        """
        if not self.has_frequency:
            raise FitError("this fit has no frequency model (fitted with frequency=False)")
        def curve(theta, idx, mu):
            hz = frequency_draws(self.spec, theta, self.run.gammas[idx],
                                 self.model_mu(mu, branch, n_draws), branch_sign(branch))
            hz.flags.writeable = False        # shared by every caller (memo)
            return hz

        hz = self._memo("frequency", mu, branch, n_draws, curve)
        if not predictive:
            return hz
        se = float(np.median(self.features.omega_se)) if omega_se is None else omega_se
        idx = self._draw_indices(n_draws)
        return frequency_noise({"sigma_omega": self.theta["sigma_omega"][idx]}, hz, se,
                               self.seed)

    def frequency_band(self, mu, branch: str = "stable", predictive: bool = False,
                       ci: float = CI) -> FrequencyBand:
        """Median and ``ci`` band (90% by default) of the frequency (Hz) on a μ grid.

        ``nan`` where fewer than half the draws have the branch.
        """
        mu = np.atleast_1d(np.asarray(mu, dtype=float))
        return FrequencyBand.from_draws(branch, mu, self.frequency(mu, branch, predictive), ci)

    def time_series(self, mu: float, branch: str, t, phase0: float = 0.0,
                    n_draws: int | None = N_BAND_DRAWS, control=None) -> np.ndarray:
        """Predicted planar channels (physical units) at times ``t``, ``(n, n_t, 2)``.

        The orbit of each draw traversed at its own frequency,
        ``w(Ω t + φ_0)``, with ``φ_0`` the phase at ``t = 0`` relative to the crest
        of z1's fundamental (the features' phase origin). ``control`` ``(1, 2)``: a
        recording's control fundamental (:meth:`recording_control`), for the
        orbit as it was held.
        """
        c = self.orbit_coefficients([mu], branch, n_draws, control=control)[:, 0]
        om = 2 * np.pi * self.frequency([mu], branch, n_draws=n_draws)[:, 0]  # (n,)
        phi = om[:, None] * np.asarray(t, dtype=float)[None] + phase0        # (n, n_t)
        K = self.spec.n_harmonics
        X = time_design(phi.reshape(-1), 1.0, K).reshape(phi.shape + (2 * K + 1,))
        return self.spec.frame.from_frame(np.einsum("ntk,nck->ntc", X, c))

    def time_series_bands(self, recordings: RecordingSet, n_periods: float = 4.0,
                          channel: int = 0, ci: float = CI) -> list[TimeSeriesBand]:
        """Median and ``ci`` band (90%) of a channel over the first ``n_periods`` of each recording.

        Each prediction starts at the recording's phase at its first sample (the
        crest of z1's fundamental, fitted over the window at the measured
        frequency); the band then holds the frequency's and the orbit's uncertainty.
        ``recordings`` are the training recordings, in the order of the features.
        """
        return time_series_bands(self, recordings, n_periods, channel, ci)

    def frequency_check(self) -> list[dict]:
        """Each recording's measured frequency against its 90% predictive band (Hz)."""
        f = self.features
        out = []
        for i in range(f.n_recordings):
            x = self.frequency([f.mu[i]], "unstable" if f.unstable[i] else "stable",
                               predictive=True, omega_se=float(f.omega_se[i]))[:, 0]
            x = x[np.isfinite(x)]
            iv = interval(x) if x.size else None
            out.append({"name": f.names[i], "measured_hz": float(f.frequency_hz[i]),
                        "predicted": None if iv is None else iv.to_json(),
                        "inside_ci90": bool(iv is not None and iv.contains(f.frequency_hz[i]))})
        return out

    # ----------------------------------------------------------------- summaries
    def default_mu_grid(self, n: int = 120) -> np.ndarray:
        """μ from below the fold (or the Hopf point) to beyond the data."""
        mu0 = self.bifurcation("mu0")
        lo = min(self.spec.mu_min, float(np.quantile(mu0, 0.01)))
        if "mu_fold" in self.samples:
            lo = min(lo, float(np.quantile(self.bifurcation("mu_fold"), 0.01)))
        hi = max(self.spec.mu_min + self.spec.mu_span, float(np.quantile(mu0, 0.99)))
        pad = 0.05 * (hi - lo)
        return np.linspace(lo - pad, hi + pad, n)

    def _band(self, mu, branch, ci: float = CI) -> BranchBand:
        at = band_levels(ci)
        c = self.orbit_coefficients(mu, branch)
        amp = self._amplitude_of(c)
        rng = np.random.default_rng(self.seed)
        ce = self._away_from_data(c, mu, branch)
        amp_p = self._amplitude_of(ce + self.noise_sd(ce, None, mu, branch)
                                   * _common_over_mu(rng, c.shape))
        q, p = quantiles(amp, at)
        qp, _ = quantiles(amp_p, at)
        to_hopf = p_to_hopf = None
        sub = self.criticality == "subcritical"
        if sub == (branch == "unstable"):      # this branch shrinks into the Hopf point
            mu0 = self.bifurcation("mu0")[self._draw_indices(N_BAND_DRAWS)][:, None]
            past = (np.asarray(mu)[None] > mu0) if sub else (np.asarray(mu)[None] < mu0)
            to_hopf, p_to_hopf = quantiles(np.where(np.isnan(amp) & past, 0.0, amp), at)
        return BranchBand(int(branch_sign(branch)), np.asarray(mu), q, p, qp, at, to_hopf,
                          p_to_hopf)

    def diagram(self, mu=None, ci: float = CI) -> DiagramBands:
        """The posterior bifurcation diagram with curve and predictive bands.

        Args:
            mu: μ grid (default :meth:`default_mu_grid`).
            ci: Mass of the outer bands and of the Hopf and fold intervals
                (the 50% band and the median are always stored).
        """
        mu = self.default_mu_grid() if mu is None else np.asarray(mu, float)
        stable = self._band(mu, "stable", ci)
        if self.criticality == "subcritical":
            unstable = self._band(mu, "unstable", ci)
            idx = self._draw_indices(N_BAND_DRAWS)
            c = orbit_coefficients(self.spec, {k: v[idx] for k, v in self.theta.items()},
                                   self.run.betas[idx], self.samples["mu_fold"][idx][:, None],
                                   normal_form.STABLE, per_draw=True)
            fold_amp = self._amplitude_of(c)[:, 0]
            fold = interval(self.bifurcation("mu_fold"), ci)
            fold_iv = interval(fold_amp, ci)
        else:
            unstable, fold, fold_iv = None, None, None
        return DiagramBands(stable, unstable, interval(self.bifurcation("mu0"), ci), fold, fold_iv)

    @cached_property
    def training_coefficients(self) -> tuple[np.ndarray, ...]:
        """Predicted coefficient draws at each training recording, each ``(n, 2, 2K+1)``.

        Computed once and shared by :meth:`ppc` and :meth:`orbit_error`.
        """
        f = self.features
        out = [None] * f.n_recordings
        for branch in ("stable", "unstable"):        # one computation per branch
            idx = np.flatnonzero(np.asarray(f.unstable, bool) == (branch == "unstable"))
            if idx.size == 0:
                continue
            held = [self.recording_control(i) for i in idx]
            control = None if held[0] is None else np.concatenate(held)
            c = self.orbit_coefficients(f.mu[idx], branch, control=control)
            for j, i in enumerate(idx):   # each μ's orbits are its own: remembered one by one
                mu_i, one = [f.mu[i]], c[:, j:j + 1]
                self._memo("orbits", mu_i, branch, N_BAND_DRAWS, lambda *_, one=one: one,
                           held[j])
                out[i] = one[:, 0]
        return tuple(out)

    def ppc(self, ci: float = CI) -> PosteriorPredictiveCheck:
        """Posterior predictive check of each training recording (amplitudes and coefficients).

        Computed once per ``ci`` (its replicates are seeded, so the same each
        time): the checks, the summary, the figures and the lab report share it.

        Args:
            ci: Mass of the amplitude intervals (90% by default).
        """
        memo = self.__dict__.setdefault("_ppc_memo", {})
        if ci not in memo:
            memo[ci] = self._ppc(ci)
        return memo[ci]

    def _ppc(self, ci: float) -> PosteriorPredictiveCheck:
        f = self.features
        curve, pred, p_amp = [], [], []
        reps = []
        rng = np.random.default_rng(self.seed)
        for i, c in enumerate(self.training_coefficients):
            rep = c + self.noise_sd(c, f.coeffs_se[i], [f.mu[i]],
                                     "unstable" if f.unstable[i] else "stable"
                                     ) * rng.standard_normal(c.shape)
            reps.append(rep)
            a, ap = self._amplitude_of(c), self._amplitude_of(rep)
            curve.append(interval(a, ci))
            pred.append(interval(ap, ci))
            p_amp.append(float(np.mean(ap[np.isfinite(ap)] <= f.amplitude[i])))
        reps = np.array(reps)                                   # (n_rec, n, 2, 2K+1)
        flat = reps.reshape(reps.shape[0], reps.shape[1], -1)
        obs = f.coeffs.reshape(f.n_recordings, -1)
        coeff_p = np.nanmean(flat <= obs[:, None], axis=1)
        coeff_z = (obs - np.nanmean(flat, axis=1)) / np.nanstd(flat, axis=1)
        return PosteriorPredictiveCheck(
            names=f.names, mu=f.mu, unstable=f.unstable, measured=f.amplitude,
            curve=tuple(curve), predictive=tuple(pred), amplitude_p=np.array(p_amp),
            coeff_p=coeff_p, coeff_z=coeff_z,
            measured_se=f.amplitude_sd / np.sqrt(np.maximum(f.n_segments, 1)))

    @cached_property
    def log_likelihood(self) -> np.ndarray:
        """``log p(y_i | y_{−i}, θ_s)`` per chain, draw and recording, ``(chains, draws, n_rec)``.

        The pointwise log-likelihood of PSIS-LOO for this non-factorised model
        (:func:`~bayeshopf.model.collapsed.pointwise_log_likelihood`): given θ
        the map is refitted exactly without recording i.
        """
        shape = next(iter(self.run.chains.values())).shape[:2]
        ll = np.asarray(self._log_likelihood_dispatched)
        return ll.reshape(shape + (self.features.n_recordings,))

    @cached_property
    def _log_likelihood_dispatched(self):
        """:attr:`log_likelihood`'s draws as JAX's asynchronous dispatch returns them."""
        theta = {k: v.reshape((-1,) + v.shape[2:]) for k, v in self.run.chains.items()
                 if k in self.map_point.params}
        return log_likelihood_program(self.spec, theta, self.features)

    def dispatch(self) -> None:
        """Start the computation :meth:`to_inference_data` waits longest for, and return.

        JAX runs a compiled program on its own threads and returns at once
        (asynchronous dispatch): the pointwise log-likelihood of every draw
        then runs beside what Python does next, the figures in the CLI, and
        :attr:`log_likelihood` collects it.
        """
        if "log_likelihood" not in self.__dict__:
            self._log_likelihood_dispatched  # noqa: B018 (dispatches)

    def to_inference_data(self):
        """The fit as ArviZ :class:`~arviz.InferenceData` (ArviZ 0.x).

        Its groups, coordinates and attributes:
        :func:`~bayeshopf.diagnostics.inference_data.to_inference_data`. The file
        :func:`~bayeshopf.fit_folder.save_hybrid` writes is this object (``posterior.nc``).
        """
        from bayeshopf.diagnostics import inference_data

        return inference_data.to_inference_data(self)

    def orbit_error(self) -> list[dict]:
        """Each recording's posterior-median orbit against its measured mean orbit.

        ``relative``: RMS distance over the orbit (frame units), relative to the
        measured orbit's RMS radius; ``spread``: the segments' RMS distance from
        their mean orbit, relative to the same radius; ``ok``: relative below
        :data:`~bayeshopf.diagnostics.fit_checks.ORBIT_ERROR_MAX` or below
        :data:`~bayeshopf.diagnostics.fit_checks.ORBIT_SPREAD_FACTOR` × spread;
        ``by_harmonic``: the part of ``relative`` in the centre and in each
        harmonic 1…K (:func:`~bayeshopf.diagnostics.fit_checks.orbit_error_parts`;
        their squares add up to ``relative``'s).
        """
        return orbit_errors(self, N_PHI)


def log_likelihood_program(spec: cm.CollapsedSpec, theta: dict, features: HarmonicFeatures):
    """``log p(y_i | y_{−i}, θ_s)`` of each draw and recording as a JAX array, dispatched.

    :func:`~bayeshopf.inference.collapsed.pointwise_log_likelihood_draws` on the
    model's arguments for ``spec`` and ``features``; not waited for.
    """
    return ci.pointwise_log_likelihood_draws(ci.model_arguments(spec, features), theta)
