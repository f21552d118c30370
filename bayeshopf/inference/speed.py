r"""The third training stage: the oscillation speed Ω from the measured time series.

**Model** (NumPyro, one sample site per symbol):

* ``ω0 ~ Normal(ω̄, 0.1|ω̄|)`` with ``ω̄ = 2π f̄`` the mean measured (signed)
  frequency;
* ``NN_Ω`` weights and biases ``~ Normal(0, 1)`` (scaled by ``1/√fan_in``),
  output scale ``s_Ω ~ HalfNormal(s|ω̄|)`` with
  ``s = max(0.05, 2 (f_max − f_min)/f̄)`` from the measured frequencies: a
  priori the speed varies along and between orbits by a few per cent, or by
  as much as the recordings' frequencies do (17% across the Van der Pol
  plan);
* initial phases ``θ0_i ~ Normal(θ0_i*, 0.2)`` centred on the root of eq.
  (zp_ang) for the first measured point: one noisy sample fixes the phase only
  to about noise/radius, and a fixed wrong θ0 would be traded against a biased
  frequency over the window;
* the **mean frequency of every recording** over its whole record, ``f_i``
  (the slope of the unwrapped frame angle, with its standard error ``s_i``
  from the spread over 5 segments), is observed too:

  .. math::  f_i \sim \mathcal N\big(\hat f_i,\ \sqrt{s_i^2 + (\tau \hat f_i)^2}\big),
     \qquad \hat f_i = 1/\oint d\theta/\Omega(r_i, \theta, \mu_i),
     \qquad \tau \sim \mathrm{HalfNormal}(0.01).

  The time series alone pin the mean frequency weakly (the map's shape error
  dominates their residuals). With this observation the curve of the simulated
  3-DOF aerofoil is within 0.05% of the true frequency at all 15 training and
  held-out orbits; on the Van der Pol relaxation orbits, which the map does
  not follow, the time series still pull it 0.3–1.7% low
  (``benchmarks/speed_validation.md``). ``τ`` (site ``tau_f``) is the relative
  scatter of the recordings' frequencies about the curve: recordings at the
  same μ differ by more than a smooth Ω(r, θ, μ) allows (the control is not
  perfectly non-invasive, records drift, and at the fold the two branches meet
  with one r but were measured at different frequencies). Like the scatter σ
  of the map's features, it makes the *predictive* frequency band (where a new
  recording's frequency is expected: ``f (1 + τ ε)``); the *curve* band is
  Ω's. (Per-recording frequency offsets in the time-series likelihood instead
  let the offsets absorb the trend with μ and r on planted data: the curve
  came out 1–3% wrong and flat.)
* noise ``σ_ij ~ HalfNormal(0.2 ρ_i)`` per recording ``i`` and planar channel
  ``j`` (frame units, ``ρ_i`` the RMS radius of recording ``i`` about its own
  centre); it absorbs the measurement noise and the map's shape error, which
  scale with the orbit. One σ shared by all recordings let the largest orbits
  set it, and the smallest (the unstable orbit nearest the Hopf point, 4×
  smaller) then carried almost no weight: its frequency came out 1.2% off on
  the wind-tunnel rig;
* likelihood ``w_i(t_k) ~ Normal(ŵ_i(t_k), σ)`` with
  ``ŵ_i(t) = U12(r_i[cos θ_i(t), sin θ_i(t)], μ̃_i)``,
  ``θ̇_i = Ω(r_i, θ_i, μ_i)``, ``θ_i(0)`` from eq. (zp_ang), on a short window
  of each recording (the first ``n_periods`` periods, downsampled to about
  ``samples_per_period`` samples per period), in the planar frame. The log
  likelihood is multiplied by ``likelihood_weight`` (default
  ``1/samples_per_period``): the residuals are dominated by the map's shape
  error and the drift of real records, which repeat period after period, so
  the samples of one period count as about one independent observation. With
  weight 1 the bands of the frequency are a few times narrower than the bias
  that this model error causes (checked on planted data, where the truth fell
  outside them); the power likelihood is the usual remedy for a misspecified,
  autocorrelated error model.

**Keeping the map's posterior.** Ω is fitted *conditionally on the map's MAP
point* (μ0, a2, T_L, T_s, NN_U fixed at ``hopf_fit.map.params``), which is the
paper's staging (map first, then speed) with the uncertainty of the speed given
the map. For every prediction the ``i``-th speed draw is paired with the
``i``-th posterior draw of the map: the radius r(μ), the initial phase and the
mapped trajectory come from that map draw, so the frequency and time-series
bands carry both uncertainties. This is the cheap alternative to a joint
posterior (which would need the ODE inside the map's SVI); it neglects the
correlation between the map and speed posteriors, and it is conservative only
if the map's uncertainty is not already explained by the speed.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

from bayeshopf.data.recording import RecordingSet
from bayeshopf.diagnostics.bands import FrequencyBand, TimeSeriesBand
from bayeshopf.diagnostics.summaries import Interval, interval
from bayeshopf.errors import FitError
from bayeshopf.inference.map import fit_map
from bayeshopf.inference.results import MapResult, SviResult
from bayeshopf.inference.svi import fit_svi
from bayeshopf.model import hybrid, normal_form
from bayeshopf.model import speed as sp
from bayeshopf.model.hybrid import ModelSpec, branch_signs
from bayeshopf.model.probabilistic import typical_radius

#: Initial standard deviation of the speed SVI guide (unconstrained space).
SPEED_INIT_SCALE = 1e-2

#: Prior standard deviation (rad) of each initial phase about its root-find value.
THETA0_SD = 0.2


@dataclass(frozen=True)
class SpeedSettings:
    """Settings of :func:`fit_speed`.

    Attributes:
        n_h: Harmonics of Ω in θ.
        nn_width: Neurons per hidden layer of ``NN_Ω``.
        nn_depth: Hidden layers of ``NN_Ω``.
        n_periods: Periods of each recording used for training.
        samples_per_period: Target samples per period after downsampling.
        likelihood_weight: Power of the likelihood (``None``: ``1/samples_per_period``,
            one effective observation per period; module docstring).
        adam_steps: MAP Adam iterations.
        lbfgs_steps: MAP L-BFGS iterations.
        svi_steps: SVI iterations.
        num_particles: ELBO particles.
        n_draws: Posterior draws (at most the map's number of draws).
    """

    n_h: int = 3
    nn_width: int = 8
    nn_depth: int = 1
    n_periods: float = 10.0
    samples_per_period: int = 30
    likelihood_weight: float | None = None
    adam_steps: int = 250
    lbfgs_steps: int = 60
    svi_steps: int = 600
    num_particles: int = 1
    n_draws: int = 400


@dataclass(frozen=True)
class SpeedData:
    """Training windows of the speed stage (planar frame, time from each window's start).

    Attributes:
        t: Times, shape ``(n_rec, n_t)``.
        w: Measured planar points in the frame, shape ``(n_rec, n_t, 2)``.
        radius: RMS radius of each window about its own centre (frame units).
        mu: μ per recording.
        sign: Branch sign per recording.
        theta0: Initial normal-form phase per recording (map's MAP point).
        measured_hz: Mean measured frequency over the whole record, per recording.
        measured_se: Its standard error (spread of the frequency over segments).
        names: Recording names.
    """

    t: np.ndarray
    w: np.ndarray
    radius: np.ndarray
    mu: np.ndarray
    sign: np.ndarray
    theta0: np.ndarray
    measured_hz: np.ndarray
    measured_se: np.ndarray
    names: tuple[str, ...]


def measured_frequency(w: np.ndarray, t: np.ndarray) -> float:
    """Mean frequency (Hz, signed; > 0 counter-clockwise) from the unwrapped frame angle."""
    ang = np.unwrap(np.arctan2(w[:, 1], w[:, 0]))
    slope = np.polyfit(t - t[0], ang, 1)[0]
    return float(slope / (2.0 * np.pi))


def measured_frequency_se(w: np.ndarray, t: np.ndarray, n_segments: int = 5) -> float:
    """Standard error (Hz) of :func:`measured_frequency`: ``sd/√n`` over ``n_segments`` segments."""
    f = [measured_frequency(w[k], t[k]) for k in np.array_split(np.arange(len(t)), n_segments)]
    return float(np.std(f, ddof=1) / np.sqrt(n_segments))


#: Smallest prior scale of the speed MLP's output, relative to |ω̄| (module docstring).
MIN_SPREAD = 0.05

#: Prior scale of the relative frequency scatter τ between recordings.
TAU_PRIOR = 0.01


def _initial_phases(map_sites: dict, map_spec: ModelSpec, mu, sign, w1):
    params = hybrid.params_from_sites(map_sites, map_spec)
    f = jax.jit(jax.vmap(lambda m, s, w: sp.initial_phase(params, m, s, w, map_spec)))
    return np.asarray(f(jnp.asarray(mu), jnp.asarray(sign), jnp.asarray(w1)))


def prepare_speed_data(recordings: RecordingSet, map_spec: ModelSpec, map_sites: dict,
                       settings: SpeedSettings) -> SpeedData:
    """Cut, downsample and frame the training windows; initial phases from the map.

    Raises:
        FitError: If a recording is shorter than two periods.
    """
    ws, ts, freqs, ses = [], [], [], []
    for r in recordings:
        w = np.asarray(map_spec.frame.to_frame(r.planar(recordings.planar)))
        f = measured_frequency(w, r.t)
        freqs.append(f)
        ses.append(measured_frequency_se(w, r.t))
        stride = max(1, int(round(1.0 / (abs(f) * r.dt * settings.samples_per_period))))
        n_win = int(settings.n_periods / (abs(f) * r.dt))
        if n_win < 2.0 / (abs(f) * r.dt):
            raise FitError(f"{r.name}: need at least two periods for the speed stage")
        ws.append(w[:n_win:stride])
        ts.append(r.t[:n_win:stride] - r.t[0])
    n_t = min(len(t) for t in ts)
    t = np.stack([x[:n_t] for x in ts])
    w = np.stack([x[:n_t] for x in ws])
    mu = recordings.mus.astype(float)
    sign = branch_signs(recordings.is_unstable).astype(float)
    theta0 = _initial_phases(map_sites, map_spec, mu, sign, w[:, 0])
    if not np.all(np.isfinite(theta0)):
        bad = [n for n, x in zip(recordings.names, theta0, strict=True) if not np.isfinite(x)]
        raise FitError(f"no LCO of the map's MAP point at the recording(s) {bad}")
    radius = np.sqrt(np.mean(np.sum((w - w.mean(axis=1, keepdims=True)) ** 2, axis=-1), axis=-1))
    return SpeedData(t, w, radius, mu, sign, theta0, np.array(freqs), np.array(ses),
                     tuple(recordings.names))


def _batched_trajectories(spec: sp.SpeedSpec, map_spec: ModelSpec):
    """Jitted ``(speed sites, map sites, μ, sign, θ0, t) ↦ ŵ`` for all recordings."""

    def build():
        def f(om_sites, map_sites, mu, sign, theta0, t):
            p = sp.speed_params_from_sites(om_sites, spec)
            mp = hybrid.params_from_sites(map_sites, map_spec)

            def one(m, s, th, tt):
                return sp.trajectory_in_frame(p, mp, m, s, th, tt, spec, map_spec)

            return jax.vmap(one)(mu, sign, theta0, t)

        return f

    return hybrid.jit_for_spec(map_spec, f"speed-traj-{hash(spec)}", build)


def _batched_frequencies(spec: sp.SpeedSpec, map_spec: ModelSpec):
    """Jitted ``(speed sites, map sites, μ, sign) ↦ f̂`` (Hz) for all recordings."""

    def build():
        def f(om_sites, map_sites, mu, sign):
            p = sp.speed_params_from_sites(om_sites, spec)
            mp = hybrid.params_from_sites(map_sites, map_spec)
            return jax.vmap(lambda m, s: sp.frequency_hz(p, mp, m, s, spec, map_spec))(mu, sign)

        return f

    return hybrid.jit_for_spec(map_spec, f"speed-freq-obs-{hash(spec)}", build)


def speed_model(spec: sp.SpeedSpec, map_spec: ModelSpec, map_sites: dict, mu, sign, theta0, t,
                radius, f_se, y=None, f_obs=None, weight: float = 1.0):
    """NumPyro model of the measured time series and mean frequencies given the map.

    Module docstring: time-series likelihood (power ``weight``) and the
    observed mean frequency of every recording with the scatter ``τ``.

    Args:
        spec: Speed structure (``omega_ref`` is the prior centre of ω0).
        map_spec: The map's structure.
        map_sites: Fixed map site values (one draw, e.g. the MAP point).
        mu: μ per recording, ``(n_rec,)``.
        sign: Branch sign per recording.
        theta0: Prior centre of the initial phase per recording (eq. zp_ang).
        t: Times, ``(n_rec, n_t)``.
        radius: RMS radius of each recording in the frame, ``(n_rec,)`` (noise prior scale).
        f_se: Standard error of each recording's mean frequency (Hz), ``(n_rec,)``.
        y: Measured frame points ``(n_rec, n_t, 2)``, or ``None`` to draw them.
        f_obs: Measured mean frequency of each recording (Hz, > 0), or ``None`` to draw it.
        weight: Power of the time-series likelihood (its log density is multiplied by it).
    """
    om_ref = spec.omega_ref
    sites = {"omega0": numpyro.sample("omega0", dist.Normal(om_ref, 0.1 * abs(om_ref)))}
    sites["om_scale"] = numpyro.sample("om_scale",
                                       dist.HalfNormal(spec.omega_spread * abs(om_ref)))
    for i, (n_in, n_out) in enumerate(spec.nn_shapes):
        sites[f"om_W{i}"] = numpyro.sample(
            f"om_W{i}", dist.Normal(0.0, 1.0).expand([n_in, n_out]).to_event(2)
        )
        sites[f"om_b{i}"] = numpyro.sample(
            f"om_b{i}", dist.Normal(0.0, 1.0).expand([n_out]).to_event(1)
        )
    sigma = numpyro.sample(
        "sigma_t", dist.HalfNormal(0.2 * jnp.stack([radius, radius], -1)).to_event(2)
    )
    tau = numpyro.sample("tau_f", dist.HalfNormal(TAU_PRIOR))
    with numpyro.plate("recordings", mu.shape[0]):
        th0 = numpyro.sample("theta0", dist.Normal(theta0, THETA0_SD))
    pred = _batched_trajectories(spec, map_spec)(sites, map_sites, mu, sign, th0, t)
    with numpyro.plate("recordings", mu.shape[0]), numpyro.handlers.scale(scale=weight):
        numpyro.sample("y", dist.Normal(pred, sigma[:, None, :]).to_event(2), obs=y)
    f_hat = _batched_frequencies(spec, map_spec)(sites, map_sites, mu, sign)
    with numpyro.plate("recordings", mu.shape[0]):
        numpyro.sample("f", dist.Normal(f_hat, jnp.sqrt(f_se**2 + (tau * f_hat) ** 2)), obs=f_obs)


@dataclass(frozen=True)
class SpeedFit:
    """A fitted oscillation-speed model, paired with the map's posterior (immutable).

    Attributes:
        spec: Speed structure.
        map_spec: The map's structure.
        samples: Speed draws (``omega0``, ``om_scale``, ``om_W*``, ``om_b*``, ``sigma_t``).
        map_samples: The map's draws paired one-to-one with ``samples``.
        map_point: The map's MAP sites on which Ω was fitted.
        data: The training windows.
        map: MAP of the speed stage.
        svi: SVI of the speed stage.
        seed: Seed.
        timings: Seconds per stage.
    """

    spec: sp.SpeedSpec
    map_spec: ModelSpec
    samples: dict
    map_samples: dict
    map_point: dict
    data: SpeedData
    map: MapResult
    svi: SviResult
    seed: int
    timings: dict = field(default_factory=dict, compare=False)

    @property
    def n_draws(self) -> int:
        """Number of paired draws."""
        return int(np.asarray(self.samples["omega0"]).shape[0])

    def _speed_sites(self):
        return {k: jnp.asarray(v) for k, v in self.samples.items() if k.startswith(("om", "omega"))}

    def _map_sites(self):
        return {k: jnp.asarray(v) for k, v in self.map_samples.items()}

    def frequency(self, mu, branch: str = "stable", predictive: bool = False) -> np.ndarray:
        """Draws of the LCO frequency ``f = 1/∮dθ/Ω`` in Hz, shape ``(n_draws, n_mu)``.

        ``predictive=True`` draws a new recording's frequency ``f (1 + τ ε)`` (the
        band where a new measurement's frequency is expected; module docstring).
        ``nan`` where a draw has no LCO on ``branch`` at μ.
        """
        return frequency_draws(self.spec, self.map_spec, self.samples, self.map_samples, mu,
                               branch, predictive=predictive, seed=self.seed)

    def frequency_interval(self, mu: float, branch: str = "stable",
                           predictive: bool = False) -> Interval:
        """Median and 90% interval of the frequency (Hz) at one μ (curve or predictive)."""
        x = self.frequency(mu, branch, predictive)[:, 0]
        return interval(x[np.isfinite(x)])

    def time_series(self, mu: float, branch: str, t, *, theta0=None,
                    initial_point=None) -> np.ndarray:
        """Predicted planar time series in physical units, shape ``(n_draws, n_t, 2)``.

        Args:
            mu: Bifurcation parameter.
            branch: ``"stable"`` or ``"unstable"``.
            t: Increasing times ``(n_t,)`` (s); the phase is set at ``t[0]``.
            theta0: Normal-form phase at ``t[0]`` (the same for every draw).
            initial_point: Measured point ``(z1, z2)`` at ``t[0]`` in physical
                units; each map draw finds its own θ0 from it (eq. zp_ang).
                Exactly one of ``theta0`` and ``initial_point`` must be given.
        """
        if (theta0 is None) == (initial_point is None):
            raise ValueError("give exactly one of theta0 and initial_point")
        sign = _sign(branch)
        spec, mspec = self.spec, self.map_spec
        t = jnp.asarray(t, dtype=float)
        if t.ndim != 1 or t.shape[0] < 2:
            raise ValueError(f"t must be a 1-D array of >= 2 times; got shape {t.shape}")
        if initial_point is not None:
            w1 = np.asarray(mspec.frame.to_frame(np.asarray(initial_point, dtype=float)))
            w1 = jnp.asarray(w1).reshape(2)
        else:
            w1 = jnp.full((2,), jnp.nan)
        use_point = initial_point is not None
        th0 = jnp.asarray(0.0 if theta0 is None else float(theta0))

        def build():
            def f(om_sites, map_sites, mu, th0, w1, t):
                def one(o, m):
                    p = sp.speed_params_from_sites(o, spec)
                    mp = hybrid.params_from_sites(m, mspec)
                    th = sp.initial_phase(mp, mu, sign, w1, mspec) if use_point else th0
                    w = sp.trajectory_in_frame(p, mp, mu, sign, th, t, spec, mspec)
                    return mspec.frame.from_frame(w)

                return jax.vmap(one)(om_sites, map_sites)

            return f

        f = hybrid.jit_for_spec(mspec, f"speed-ts-{hash(spec)}-{sign}-{use_point}", build)
        return np.asarray(f(self._speed_sites(), self._map_sites(), jnp.asarray(float(mu)),
                            th0, w1, t))

    def phase_error(self, recordings: RecordingSet, n_periods: float = 10.0) -> np.ndarray:
        """RMS phase error (rad) over the ``n_periods``-th period of each recording.

        Each recording is predicted from its first measured point
        (:meth:`time_series` with ``initial_point``); the error is the wrapped
        difference between the measured and the predicted angle about the frame
        centre, ``wrap(ang(w(t)) − ang(ŵ(t)))``, its median over draws, and the
        RMS over the samples of the last period before ``n_periods`` periods.

        Returns:
            One error per recording, shape ``(n_rec,)``.
        """
        out = []
        frame = self.map_spec.frame
        for r in recordings:
            z = r.planar(recordings.planar)
            w = np.asarray(frame.to_frame(z))
            period_s = 1.0 / abs(measured_frequency(w, r.t))
            t = r.t - r.t[0]
            stride = max(1, int(round(period_s / (40 * r.dt))))
            sel = np.flatnonzero(t <= n_periods * period_s)[::stride]
            pred = self.time_series(r.mu, r.branch, t[sel], initial_point=z[0])
            wp = np.asarray(frame.to_frame(pred.reshape(-1, 2))).reshape(pred.shape)
            d = np.angle(np.exp(1j * (np.arctan2(w[sel, 1], w[sel, 0])[None]
                                      - np.arctan2(wp[..., 1], wp[..., 0]))))
            d = np.nanmedian(d, axis=0)
            last = t[sel] >= (n_periods - 1.0) * period_s
            out.append(float(np.sqrt(np.mean(d[last] ** 2))))
        return np.array(out)

    def time_series_bands(self, recordings: RecordingSet, n_periods: float = 4.0,
                          channel: int = 0) -> list[TimeSeriesBand]:
        """Median and 90% band of one channel over the first ``n_periods`` of each recording.

        Each prediction starts from the recording's first measured point.
        """
        out = []
        for r in recordings:
            z = r.planar(recordings.planar)
            f = abs(measured_frequency(np.asarray(self.map_spec.frame.to_frame(z)), r.t))
            t = r.t - r.t[0]
            stride = max(1, int(round(1.0 / (f * 60 * r.dt))))
            sel = np.flatnonzero(t <= n_periods / f)[::stride]
            pred = self.time_series(r.mu, r.branch, t[sel], initial_point=z[0])[..., channel]
            q = np.nanquantile(pred, [0.5, 0.05, 0.95], axis=0)
            name = recordings.planar[channel]
            out.append(TimeSeriesBand(r.name, r.mu, r.branch, name, r.units[name], t[sel],
                                      z[sel, channel], q[0], q[1], q[2]))
        return out

    def frequency_band(self, mu, branch: str = "stable",
                       predictive: bool = False) -> FrequencyBand:
        """Frequency median and 90% band on a μ grid (draws without an LCO are dropped)."""
        mu = np.atleast_1d(np.asarray(mu, dtype=float))
        return FrequencyBand.from_draws(branch, mu, self.frequency(mu, branch, predictive))

    def map_point_time_series(self, i: int, t=None) -> np.ndarray:
        """Trajectory of training recording ``i`` at the MAP of both stages, frame units."""
        t = self.data.t[i] if t is None else np.asarray(t, dtype=float)
        p = sp.speed_params_from_sites({k: jnp.asarray(v) for k, v in self.map.params.items()},
                                       self.spec)
        mp = hybrid.params_from_sites({k: jnp.asarray(v) for k, v in self.map_point.items()},
                                      self.map_spec)
        return np.asarray(sp.trajectory_in_frame(
            p, mp, self.data.mu[i], self.data.sign[i], self.map.params["theta0"][i],
            jnp.asarray(t),
            self.spec, self.map_spec))


def frequency_draws(spec: sp.SpeedSpec, map_spec: ModelSpec, samples: dict, map_samples: dict,
                    mu, branch: str = "stable", *, predictive: bool = False,
                    seed: int = 0) -> np.ndarray:
    """Frequency draws (Hz) ``(n_draws, n_mu)``: speed draw i with map draw i.

    ``f = 1/T``, ``T = ∫₀^{2π} dθ/Ω(r_i(μ), θ, μ)`` (:func:`bayeshopf.model.speed.period`);
    ``predictive=True`` draws a new recording's frequency, ``f (1 + τ ε)``,
    ``ε ~ Normal(0, 1)``, with the draw's scatter τ (site ``tau_f``).
    """
    sign = _sign(branch)

    def build():
        def f(om_sites, map_sites, mu):
            def one(o, m):
                p = sp.speed_params_from_sites(o, spec)
                mp = hybrid.params_from_sites(m, map_spec)
                return jax.vmap(lambda x: sp.frequency_hz(p, mp, x, sign, spec, map_spec))(mu)

            return jax.vmap(one)(om_sites, map_sites)

        return f

    f = hybrid.jit_for_spec(map_spec, f"speed-freq-{hash(spec)}-{sign}", build)
    mu = jnp.atleast_1d(jnp.asarray(mu, dtype=float))
    om = {k: jnp.asarray(v) for k, v in samples.items() if k.startswith(("om", "omega"))}
    ms = {k: jnp.asarray(v) for k, v in map_samples.items()}
    out = np.asarray(f(om, ms, mu))
    if predictive:
        tau = np.asarray(samples.get("tau_f", np.zeros(out.shape[0])), dtype=float)
        # one new recording per draw, the same along μ (smooth band edges)
        eps = np.random.default_rng(seed).standard_normal((out.shape[0], 1))
        out = out * (1.0 + tau[:, None] * eps)
    return out


SPEED_DRAWS = "speed.npz"
SPEED_SPEC = "speed.json"


def save_speed(speed_fit: SpeedFit, folder) -> list:
    """Write the speed draws and the paired map draws (``speed.npz``) and ``speed.json``.

    The folder is normally a fit folder written by :func:`bayeshopf.report.save_fit`;
    ``bayeshopf predict`` then reports the frequency as well.
    """
    folder = Path(folder)
    arrays = {f"speed/{k}": np.asarray(v) for k, v in speed_fit.samples.items()
              if k.startswith(("om", "omega", "tau"))}
    arrays.update({f"map/{k}": np.asarray(v) for k, v in speed_fit.map_samples.items()})
    tmp = folder / (SPEED_DRAWS + ".tmp.npz")
    np.savez(tmp, **arrays)
    tmp.replace(folder / SPEED_DRAWS)
    meta = {"spec": speed_fit.spec.to_dict(), "seed": speed_fit.seed,
            "pairing": "speed draw i with map posterior draw i; Ω fitted given the map's MAP"}
    (folder / SPEED_SPEC).write_text(json.dumps(meta, indent=2) + "\n")
    return [folder / SPEED_DRAWS, folder / SPEED_SPEC]


def load_speed_draws(folder) -> tuple[sp.SpeedSpec, dict, dict] | None:
    """``(spec, speed draws, map draws)`` from a fit folder; ``None`` without a speed model."""
    folder = Path(folder)
    if not (folder / SPEED_DRAWS).is_file() or not (folder / SPEED_SPEC).is_file():
        return None
    meta = json.loads((folder / SPEED_SPEC).read_text())
    with np.load(folder / SPEED_DRAWS) as z:
        speed = {k.split("/", 1)[1]: z[k] for k in z.files if k.startswith("speed/")}
        maps = {k.split("/", 1)[1]: z[k] for k in z.files if k.startswith("map/")}
    return sp.SpeedSpec(**meta["spec"]), speed, maps


def _sign(branch: str) -> float:
    if branch not in ("stable", "unstable"):
        raise ValueError(f"branch must be 'stable' or 'unstable'; got {branch!r}")
    return normal_form.STABLE if branch == "stable" else normal_form.UNSTABLE


def fit_speed(hopf_fit, recordings: RecordingSet, *, seed: int = 0,
              settings: SpeedSettings | None = None, progress: bool = True) -> SpeedFit:
    """Fit Ω (third training stage) to the time series, given a fitted map.

    MAP of the speed parameters (Adam then L-BFGS, :func:`fit_map`) with the map
    fixed at its MAP point, then SVI with a full-rank normal guide
    (:func:`fit_svi`); the speed draws are paired with the map's posterior
    draws (module docstring).

    Args:
        hopf_fit: A :class:`~bayeshopf.pipeline.HopfFit` (``spec``, ``map``, ``samples``).
        recordings: The recordings whose time series train Ω (normally the
            training recordings of ``hopf_fit``).
        seed: Seed.
        settings: :class:`SpeedSettings`.
        progress: Show progress bars.

    Returns:
        A :class:`SpeedFit`.
    """
    settings = settings or SpeedSettings()
    timings = {}
    t0 = time.perf_counter()
    mspec = hopf_fit.spec
    keys = hybrid.param_site_names(mspec, hopf_fit.map.params)
    map_point = {k: np.asarray(hopf_fit.map.params[k]) for k in keys}
    data = prepare_speed_data(recordings, mspec, {k: jnp.asarray(v) for k, v in map_point.items()},
                              settings)
    omega_ref = float(2.0 * np.pi * np.mean(data.measured_hz))
    f = np.abs(data.measured_hz)
    spec = sp.SpeedSpec(
        n_h=settings.n_h, nn_width=settings.nn_width, nn_depth=settings.nn_depth,
        omega_ref=omega_ref, omega_spread=max(MIN_SPREAD, 2.0 * float(np.ptp(f) / np.mean(f))),
        r_scale=typical_radius(mspec),
    )
    kwargs = dict(
        spec=spec, map_spec=mspec, map_sites={k: jnp.asarray(v) for k, v in map_point.items()},
        mu=jnp.asarray(data.mu), sign=jnp.asarray(data.sign), theta0=jnp.asarray(data.theta0),
        t=jnp.asarray(data.t), radius=jnp.asarray(data.radius), y=jnp.asarray(data.w),
        f_se=jnp.asarray(data.measured_se), f_obs=jnp.asarray(np.abs(data.measured_hz)),
        weight=(1.0 / settings.samples_per_period if settings.likelihood_weight is None
                else float(settings.likelihood_weight)),
    )
    timings["prepare"] = time.perf_counter() - t0
    k_map, k_svi = jax.random.split(jax.random.PRNGKey(seed))
    init = {"omega0": omega_ref, "om_scale": 1e-3 * abs(omega_ref), "tau_f": 0.5 * TAU_PRIOR,
            "sigma_t": 0.05 * np.stack([data.radius, data.radius], -1), "theta0": data.theta0}
    for i, (n_in, n_out) in enumerate(spec.nn_shapes):
        init[f"om_W{i}"] = 0.5 * np.asarray(
            jax.random.normal(jax.random.fold_in(k_map, i), (n_in, n_out)))
        init[f"om_b{i}"] = np.zeros(n_out)
    t0 = time.perf_counter()
    map_result = fit_map(speed_model, kwargs, init, key=k_map, adam_steps=settings.adam_steps,
                         lbfgs_steps=settings.lbfgs_steps, progress=progress)
    if not np.isfinite(map_result.losses[-1]):
        raise FitError("speed MAP did not converge: the loss is not finite")
    timings["map"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    n_map = int(np.asarray(hopf_fit.samples["mu0"]).shape[0])
    n_draws = min(settings.n_draws, n_map)
    # the speed guide starts at 1e-2: started at 1e-4 (the map's start), the
    # frequency bands of the planted set stayed too narrow (truth outside at 8 of 10 μ)
    svi_result = fit_svi(speed_model, kwargs, map_result, key=k_svi, steps=settings.svi_steps,
                         num_particles=settings.num_particles, n_draws=n_draws,
                         progress=progress, obs_name="y", init_scale=SPEED_INIT_SCALE,
                         guide="mvn")
    timings["svi"] = time.perf_counter() - t0
    samples = {k: v for k, v in svi_result.samples.items() if k not in ("y_rep", "f")}
    map_samples = {k: np.asarray(hopf_fit.samples[k])[:n_draws] for k in keys}
    return SpeedFit(spec=spec, map_spec=mspec, samples=samples, map_samples=map_samples,
                    map_point=map_point, data=data, map=map_result, svi=svi_result, seed=seed,
                    timings=timings)
