r"""Synthetic LCO recordings of a known Hopf system, for tests and demonstrations.

The planted system is the paper's normal form (eq. NF-model-polar) with a known
map to two physical channels. On the branch with sign ``s`` (+1 stable, −1
unstable) the limit cycle at ``μ`` is

.. math::

    r^2 = \tfrac12\left(a_2 + s\sqrt{a_2^2 + 4(\mu-\mu_0)}\right), \qquad
    \theta(t) = \omega(r)\,t + \theta_0, \qquad
    \omega(r) = \omega_0\,(1 + \kappa r^2),

    u = r\,[\cos\theta, \sin\theta]^T,

and it is observed in physical units (heave ``h`` in m, pitch ``alpha`` in rad,
like the wind-tunnel flutter rig) through

.. math::

    z = T_L\,\bigl(u + \varepsilon\,[u_1^2,\; u_1 u_2]^T\bigr)
        + T_{L,\mu}\,(\mu - \mu_{\mathrm{ref}}) + T_s + n(t),

with ``n`` white Gaussian measurement noise whose standard deviation, per
channel and recording, is ``noise`` times that channel's amplitude (half its
peak-to-peak) in the recording. ``ε`` is a small smooth distortion that the
linear part of the learnt map cannot represent. ``θ0`` is drawn for every
recording from ``seed``, so a set is reproducible.

:class:`PlantedHopf` holds the truth and generates recordings
(:meth:`PlantedHopf.simulate`); :func:`hopf_recordings` does both in one call
and :func:`demo_system` returns a flutter-rig-like set with its truth.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal, NoReturn

import numpy as np

from bayeshopf.data.recording import Recording, RecordingSet
from bayeshopf.errors import DataError

__all__ = [
    "DEMO_STABLE_MU",
    "DEMO_UNSTABLE_MU",
    "PlantedHopf",
    "demo_system",
    "hopf_recordings",
]

Criticality = Literal["subcritical", "supercritical"]

#: Planar channels of the synthetic recordings and their units.
CHANNELS: tuple[str, str] = ("h", "alpha")
UNITS: tuple[str, str] = ("m", "rad")
#: μ of the demonstration set (m/s): four stable and three unstable LCOs.
DEMO_STABLE_MU: tuple[float, ...] = (15.3, 16.7, 18.1, 19.5)
DEMO_UNSTABLE_MU: tuple[float, ...] = (15.6, 16.5, 17.4)
#: Default linear map (per unit of the normal-form radius): heave a few cm and
#: pitch about 0.1 rad peak-to-peak at the largest demo orbit, coupled.
DEFAULT_T_L: tuple[tuple[float, float], ...] = ((0.010, 0.003), (-0.010, 0.040))
#: Default drift of the orbit centre with μ, in (m, rad) per (m/s).
DEFAULT_T_L_MU: tuple[float, float] = (4e-4, 3e-3)
#: Default static offset (m, rad).
DEFAULT_T_S: tuple[float, float] = (0.002, 0.01)
#: Largest |ε| r accepted: keeps u ↦ u + ε[u1², u1 u2] invertible on every
#: simulated orbit (Jacobian determinant (1 + 2εu1)(1 + εu1) above 0.28).
MAX_DISTORTION = 0.3
#: Points per orbit for the planted amplitudes (peak-to-peak of z1).
_N_ORBIT = 4096


def _fail(msg: str) -> NoReturn:
    raise DataError(msg)


def _finite(name: str, value, shape: tuple[int, ...]) -> np.ndarray:
    """Read-only float64 copy of ``value`` with shape ``shape``, all finite."""
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{name} must be a real array of shape {shape}; got {value!r}") from exc
    if a.shape != shape:
        _fail(f"{name} must have shape {shape}; got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        _fail(f"{name} must be finite; got {a.tolist()}")
    a.setflags(write=False)
    return a


def _scalar(name: str, value, *, positive: bool = False, nonneg: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{name} must be a real number; got {value!r}") from exc
    if not np.isfinite(x):
        _fail(f"{name} must be finite; got {x}")
    if positive and x <= 0:
        _fail(f"{name} must be > 0; got {x}")
    if nonneg and x < 0:
        _fail(f"{name} must be >= 0; got {x}")
    return x



def _lco_radius(mu: np.ndarray, mu0: float, a2: float, stable: bool) -> np.ndarray:
    """``r = √((a2 ± √(a2² + 4(μ−μ0)))/2)``, ``nan`` where the branch does not exist.

    Written here, apart from the model (:mod:`bayeshopf.model.normal_form`), so
    that planted data are an independent reference; the roots are taken in the
    forms that stay accurate near the Hopf point (``−2Δ/(a2 + √D)`` for the
    unstable branch), and the fold counts as on both branches within rounding.
    """
    delta = mu - mu0
    disc = a2**2 + 4.0 * delta
    sq = np.sqrt(np.maximum(disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        if stable:
            r2 = (a2 + sq) / 2.0 if a2 > 0 else 2.0 * delta / (sq - a2)
        else:
            r2 = -2.0 * delta / (a2 + sq) if a2 > 0 else np.full_like(delta, -1.0)
    ok = (disc >= -64.0 * np.finfo(np.float64).eps * (a2**2 + 4.0 * abs(mu0))) & (r2 > 0.0)
    return np.where(ok, np.sqrt(np.where(ok, r2, 1.0)), np.nan)

@dataclass(frozen=True, eq=False)
class PlantedHopf:
    """A known Hopf system and its map to the physical channels (the planted truth).

    The normal form is ``ṙ = (μ − μ0) r + a2 r³ − r⁵``, ``θ̇ = ω0 (1 + κ r²)``,
    observed as ``z = T_L (u + ε [u1², u1 u2]) + T_L_mu (μ − μ_ref) + T_s`` with
    ``u = r [cos θ, sin θ]`` (module docstring).

    Attributes:
        mu0: Hopf point μ0 (m/s).
        a2: Cubic coefficient; ``> 0`` subcritical (both branches and a fold),
            ``< 0`` supercritical (one stable branch for μ > μ0).
        omega: Angular frequency ω0 at the Hopf point (rad/s).
        omega_r2: κ, relative change of the frequency per unit r²
            (``ω(r) = ω0 (1 + κ r²)``).
        T_L: Linear map from ``u`` to ``(h, alpha)``, shape ``(2, 2)``,
            nonsingular.
        T_L_mu: Drift of the orbit centre per unit of ``μ − μ_ref``, shape ``(2,)``.
        T_s: Static offset, shape ``(2,)``.
        mu_ref: Reference μ of the drift; ``None`` means μ0.
        nonlinear: ε of the quadratic distortion ``u + ε [u1², u1 u2]``.
    """

    mu0: float = 18.0
    a2: float = 3.4
    omega: float = 2.0 * np.pi * 2.5
    omega_r2: float = 0.02
    T_L: np.ndarray = field(default_factory=lambda: np.array(DEFAULT_T_L))
    T_L_mu: np.ndarray = field(default_factory=lambda: np.array(DEFAULT_T_L_MU))
    T_s: np.ndarray = field(default_factory=lambda: np.array(DEFAULT_T_S))
    mu_ref: float | None = None
    nonlinear: float = 0.05

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "mu0", _scalar("mu0", self.mu0))
        a2 = _scalar("a2", self.a2)
        if a2 == 0.0:
            _fail("a2 must be non-zero (> 0 subcritical, < 0 supercritical); got 0.0")
        set_(self, "a2", a2)
        set_(self, "omega", _scalar("omega", self.omega, positive=True))
        set_(self, "omega_r2", _scalar("omega_r2", self.omega_r2))
        set_(self, "nonlinear", _scalar("nonlinear", self.nonlinear))
        T_L = _finite("T_L", self.T_L, (2, 2))
        det = float(np.linalg.det(T_L))
        if abs(det) <= 1e-12 * float(np.sum(T_L**2)):
            _fail(f"T_L must be nonsingular; got {T_L.tolist()} with determinant {det:.3g}")
        set_(self, "T_L", T_L)
        set_(self, "T_L_mu", _finite("T_L_mu", self.T_L_mu, (2,)))
        set_(self, "T_s", _finite("T_s", self.T_s, (2,)))
        ref = self.mu0 if self.mu_ref is None else _scalar("mu_ref", self.mu_ref)
        set_(self, "mu_ref", ref)

    # -- the normal form ------------------------------------------------------------

    @property
    def criticality(self) -> Criticality:
        """``"subcritical"`` if ``a2 > 0``, else ``"supercritical"``."""
        return "subcritical" if self.a2 > 0 else "supercritical"

    @property
    def mu_fold(self) -> float | None:
        """Fold of cycles ``μ_SN = μ0 − a2²/4`` (subcritical), else ``None``."""
        if self.a2 <= 0:
            return None
        return float(self.mu0 - self.a2**2 / 4.0)

    def branch_range(self, branch: str) -> tuple[float, float]:
        """Interval ``(lo, hi)`` of μ where ``branch`` has an LCO (ends may be excluded).

        Subcritical: stable ``[μ_SN, ∞)``, unstable ``(μ_SN, μ0)``. Supercritical:
        stable ``(μ0, ∞)``; the unstable branch does not exist.

        Raises:
            DataError: For an unknown branch, or the unstable branch of a
                supercritical system.
        """
        if branch not in ("stable", "unstable"):
            _fail(f"branch must be 'stable' or 'unstable'; got {branch!r}")
        if self.a2 > 0:
            return (self.mu_fold, np.inf) if branch == "stable" else (self.mu_fold, self.mu0)
        if branch == "unstable":
            _fail(
                f"a supercritical system (a2 = {self.a2:g} < 0) has no unstable LCO branch; "
                "got a request for one"
            )
        return (self.mu0, np.inf)

    def radius(self, mu, branch: str = "stable") -> np.ndarray:
        """Normal-form LCO radius ``r = √((a2 ± √(a2² + 4(μ−μ0)))/2)``; nan where none.

        Args:
            mu: Bifurcation parameter, any shape.
            branch: ``"stable"`` (+) or ``"unstable"`` (−).
        """
        if branch not in ("stable", "unstable"):
            _fail(f"branch must be 'stable' or 'unstable'; got {branch!r}")
        return _lco_radius(np.asarray(mu, dtype=np.float64), self.mu0, self.a2,
                           branch == "stable")

    def angular_frequency(self, r) -> np.ndarray:
        """``ω(r) = ω0 (1 + κ r²)`` in rad/s."""
        return self.omega * (1.0 + self.omega_r2 * np.asarray(r, dtype=np.float64) ** 2)

    def frequency_hz(self, mu, branch: str = "stable") -> np.ndarray:
        """Oscillation frequency ``ω(r(μ))/2π`` of the LCO in Hz (nan where none)."""
        return self.angular_frequency(self.radius(mu, branch)) / (2.0 * np.pi)

    # -- the map --------------------------------------------------------------------

    def U12(self, u, mu) -> np.ndarray:
        """``z = T_L (u + ε [u1², u1 u2]) + T_L_mu (μ − μ_ref) + T_s``.

        Args:
            u: Normal-form points, shape ``(..., 2)``.
            mu: Bifurcation parameter (a scalar or broadcastable to ``u[..., 0]``).

        Returns:
            Physical points ``(h, alpha)``, shape ``(..., 2)``.
        """
        u = np.asarray(u, dtype=np.float64)
        q = np.stack([u[..., 0] ** 2, u[..., 0] * u[..., 1]], axis=-1)
        shift = np.asarray(mu, dtype=np.float64)[..., None] - self.mu_ref
        return (u + self.nonlinear * q) @ self.T_L.T + shift * self.T_L_mu + self.T_s

    def orbit(self, mu, branch: str = "stable", n_points: int = 512) -> np.ndarray:
        """Noise-free LCO at ``mu`` in physical units, ``θ`` uniform in ``[0, 2π)``.

        Returns:
            Points of shape ``(..., n_points, 2)`` for ``mu`` of shape ``(...)``;
            nan where the branch does not exist.
        """
        r = self.radius(mu, branch)
        theta = np.linspace(0.0, 2.0 * np.pi, n_points, endpoint=False)
        u = r[..., None, None] * np.stack([np.cos(theta), np.sin(theta)], axis=-1)
        return self.U12(u, np.asarray(mu, dtype=np.float64)[..., None])

    def amplitude(self, mu, branch: str = "stable") -> np.ndarray:
        """Planted peak-to-peak of z1 (heave, m) of the LCO at ``mu``; nan where none.

        This is the quantity :func:`bayeshopf.features.extract_harmonics` measures
        as ``HarmonicFeatures.amplitude``.
        """
        # z1 of :meth:`orbit` less its constant terms, which a peak-to-peak drops:
        # a (u1 + ε u1²) + b (u2 + ε u1 u2) = (a cos θ + b sin θ) r (1 + ε r cos θ),
        # with (a, b) the first row of T_L
        r = self.radius(mu, branch)[..., None]
        theta = np.linspace(0.0, 2.0 * np.pi, _N_ORBIT, endpoint=False)
        a, b = self.T_L[0]
        z1 = (a * np.cos(theta) + b * np.sin(theta)) * r * (1.0 + self.nonlinear * r
                                                             * np.cos(theta))
        return np.max(z1, axis=-1) - np.min(z1, axis=-1)

    def to_dict(self) -> dict:
        """JSON-serialisable form, with the derived ``criticality`` and ``mu_fold``."""
        return {
            "mu0": self.mu0,
            "a2": self.a2,
            "mu_fold": self.mu_fold,
            "criticality": self.criticality,
            "omega": self.omega,
            "omega_r2": self.omega_r2,
            "T_L": self.T_L.tolist(),
            "T_L_mu": self.T_L_mu.tolist(),
            "T_s": self.T_s.tolist(),
            "mu_ref": self.mu_ref,
            "nonlinear": self.nonlinear,
        }

    # -- recordings -----------------------------------------------------------------

    def _check_mus(self, mus, branch: str) -> np.ndarray:
        try:
            a = np.atleast_1d(np.array(mus, dtype=np.float64))
        except (TypeError, ValueError) as exc:
            raise DataError(f"{branch}_mu must be a sequence of numbers; got {mus!r}") from exc
        if a.ndim != 1:
            _fail(f"{branch}_mu must be a flat sequence of numbers; got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            _fail(f"{branch}_mu must be finite; got {a.tolist()}")
        if a.size == 0:
            return a
        lo, hi = self.branch_range(branch)
        if self.a2 > 0:
            where = (
                f"[mu_fold, inf) = [{lo:.4g}, inf)"
                if branch == "stable"
                else f"(mu_fold, mu0) = ({lo:.4g}, {hi:.4g})"
            )
        else:
            where = f"(mu0, inf) = ({lo:.4g}, inf)"
        closed_lo = branch == "stable" and self.a2 > 0
        bad = [float(m) for m in a if (m < lo if closed_lo else m <= lo) or m >= hi]
        if bad:
            _fail(
                f"{branch}_mu: every value must lie in {where}, where the {branch} LCO of "
                f"the {self.criticality} system (mu0 = {self.mu0:g}, a2 = {self.a2:g}) exists; "
                f"got {bad} (no {branch} LCO there)"
            )
        return a

    def simulate(
        self,
        stable_mu: Sequence[float] = DEMO_STABLE_MU,
        unstable_mu: Sequence[float] = (),
        *,
        duration: float = 8.0,
        fs: float = 200.0,
        noise: float = 0.02,
        seed: int = 0,
    ) -> RecordingSet:
        """Noisy recordings of the planted LCOs (stable ones first).

        Recording ``i`` samples ``t_k = k/fs``, ``k = 0..round(duration·fs)−1``,
        of ``z(t) = U12(r [cos θ(t), sin θ(t)], μ) + n(t)`` with
        ``θ(t) = ω(r) t + θ0``. ``θ0`` and the noise come from the ``i``-th child
        of ``numpy.random.SeedSequence(seed)``, so a recording does not change
        when others are added after it.

        Args:
            stable_mu: μ of the stable-branch recordings.
            unstable_mu: μ of the unstable-branch recordings (subcritical only).
            duration: Record length in s.
            fs: Sampling rate in Hz; above twice the highest oscillation frequency.
            noise: Noise standard deviation as a fraction of each channel's
                amplitude (half peak-to-peak) in that recording.
            seed: Seed of the phases and the noise.

        Returns:
            The recordings, channels ``h`` (m) and ``alpha`` (rad), planar pair
            ``(h, alpha)``, μ labelled ``airspeed`` in m/s.

        Raises:
            DataError: If a μ has no LCO on its branch, no μ is given, the
                distortion is too strong for an orbit, or the sampling cannot
                resolve the oscillation.
        """
        duration = _scalar("duration", duration, positive=True)
        fs = _scalar("fs", fs, positive=True)
        noise = _scalar("noise", noise, nonneg=True)
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            _fail(f"seed must be a non-negative integer; got {seed!r}")
        s_mu = self._check_mus(stable_mu, "stable")
        u_mu = self._check_mus(unstable_mu, "unstable")
        if s_mu.size + u_mu.size == 0:
            _fail("expected at least one μ in stable_mu or unstable_mu; got none")
        plan = [(float(m), "stable") for m in s_mu] + [(float(m), "unstable") for m in u_mu]
        radii = np.array([float(self.radius(m, b)) for m, b in plan])
        strength = abs(self.nonlinear) * radii
        if np.any(strength >= MAX_DISTORTION):
            i = int(np.argmax(strength))
            _fail(
                f"nonlinear: |ε|·r must be < {MAX_DISTORTION} so that u + ε[u1², u1 u2] "
                f"stays invertible on the orbit; got |ε|·r = {strength[i]:.3g} "
                f"at mu = {plan[i][0]:g} (ε = {self.nonlinear:g}, r = {radii[i]:.3g})"
            )
        f_max = float(np.max(self.angular_frequency(radii))) / (2.0 * np.pi)
        if fs <= 2.0 * f_max:
            _fail(
                f"fs must exceed twice the highest oscillation frequency "
                f"(2 × {f_max:.3g} Hz); got fs = {fs:g} Hz"
            )
        n_t = int(round(duration * fs))
        if n_t < 3:
            _fail(f"duration·fs must give at least 3 samples; got {n_t}")
        t = np.arange(n_t) / fs
        children = np.random.SeedSequence(int(seed)).spawn(len(plan))
        recordings = []
        seen: dict[str, int] = {}
        for (mu, branch), r, child in zip(plan, radii, children, strict=True):
            rng = np.random.default_rng(child)
            theta0 = rng.uniform(0.0, 2.0 * np.pi)
            theta = self.angular_frequency(r) * t + theta0
            u = r * np.stack([np.cos(theta), np.sin(theta)], axis=-1)
            z = self.U12(u, mu)
            clean = self.orbit(mu, branch, _N_ORBIT)
            half_ptp = 0.5 * (np.max(clean, axis=0) - np.min(clean, axis=0))
            z = z + rng.standard_normal(z.shape) * (noise * half_ptp)
            name = f"{branch}_mu{mu:.2f}"
            seen[name] = seen.get(name, 0) + 1
            if seen[name] > 1:
                name = f"{name}_{seen[name]}"
            recordings.append(
                Recording(
                    t=t,
                    channels={CHANNELS[0]: z[:, 0], CHANNELS[1]: z[:, 1]},
                    units=dict(zip(CHANNELS, UNITS, strict=True)),
                    mu=mu,
                    branch=branch,
                    name=name,
                    source=f"synthetic Hopf system (bayeshopf.data.synthetic, seed={seed})",
                )
            )
        return RecordingSet(
            tuple(recordings),
            CHANNELS,
            mu_label="airspeed",
            mu_units="m/s",
            extra={
                "synthetic": "hopf",
                "seed": str(seed),
                "noise": repr(noise),
                "mu0": repr(self.mu0),
                "a2": repr(self.a2),
            },
        )


def hopf_recordings(
    *,
    mu0: float = 18.0,
    a2: float | None = None,
    stable_mu: Sequence[float] | None = None,
    unstable_mu: Sequence[float] | None = None,
    criticality: Criticality = "subcritical",
    omega: float = 2.0 * np.pi * 2.5,
    omega_r2: float = 0.02,
    duration: float = 8.0,
    fs: float = 200.0,
    noise: float = 0.02,
    seed: int = 0,
    T_L=DEFAULT_T_L,
    T_L_mu=DEFAULT_T_L_MU,
    T_s=DEFAULT_T_S,
    mu_ref: float | None = None,
    nonlinear: float = 0.05,
) -> RecordingSet:
    """Recordings of a known Hopf system: ``PlantedHopf(...).simulate(...)``.

    The LCO radius is ``r² = (a2 ± √(a2² + 4(μ−μ0)))/2`` and the observation
    ``z = T_L (u + ε[u1², u1 u2]) + T_L_mu (μ − μ_ref) + T_s + noise`` (see
    :class:`PlantedHopf`). Build the :class:`PlantedHopf` yourself and call
    :meth:`PlantedHopf.simulate` when you also need the truth.

    Args:
        mu0: Hopf point μ0.
        a2: Cubic coefficient; default ``3.4`` subcritical, ``−3.4`` supercritical.
        stable_mu: μ of the stable recordings; default :data:`DEMO_STABLE_MU`
            (subcritical) or ``μ0 + (0.5, 1.5, 2.5, 3.5)`` (supercritical).
        unstable_mu: μ of the unstable recordings, each in ``(μ_fold, μ0)``;
            default :data:`DEMO_UNSTABLE_MU` (subcritical) or none.
        criticality: ``"subcritical"`` (needs ``a2 > 0``) or ``"supercritical"``
            (needs ``a2 < 0``, no unstable recordings).
        omega: ω0, angular frequency at the Hopf point (rad/s).
        omega_r2: κ in ``ω(r) = ω0 (1 + κ r²)``.
        duration: Record length in s.
        fs: Sampling rate in Hz.
        noise: Noise std as a fraction of each channel's amplitude.
        seed: Seed of the phases θ0 and the noise.
        T_L: 2×2 linear map to ``(h [m], alpha [rad])``.
        T_L_mu: Drift of the orbit centre per unit μ, shape ``(2,)``.
        T_s: Static offset, shape ``(2,)``.
        mu_ref: Reference μ of the drift (default μ0).
        nonlinear: ε of the quadratic distortion.

    Returns:
        The :class:`RecordingSet` (stable recordings first).

    Raises:
        DataError: If an argument is out of range (message says what was
            expected and what was received).
    """
    if criticality not in ("subcritical", "supercritical"):
        _fail(f"criticality must be 'subcritical' or 'supercritical'; got {criticality!r}")
    sub = criticality == "subcritical"
    if a2 is None:
        a2 = 3.4 if sub else -3.4
    a2 = _scalar("a2", a2)
    if sub and a2 <= 0:
        _fail(
            f"a subcritical system needs a2 > 0; got a2 = {a2:g} "
            "(pass criticality='supercritical' for a2 < 0)"
        )
    if not sub and a2 >= 0:
        _fail(
            f"a supercritical system needs a2 < 0; got a2 = {a2:g} "
            "(pass criticality='subcritical' for a2 > 0)"
        )
    if not sub and unstable_mu:
        _fail(f"a supercritical system has no unstable LCOs; got unstable_mu = {list(unstable_mu)}")
    system = PlantedHopf(
        mu0=mu0,
        a2=a2,
        omega=omega,
        omega_r2=omega_r2,
        T_L=T_L,
        T_L_mu=T_L_mu,
        T_s=T_s,
        mu_ref=mu_ref,
        nonlinear=nonlinear,
    )
    if stable_mu is None:
        stable_mu = DEMO_STABLE_MU if sub else tuple(system.mu0 + np.array([0.5, 1.5, 2.5, 3.5]))
    if unstable_mu is None:
        unstable_mu = DEMO_UNSTABLE_MU if sub else ()
    return system.simulate(stable_mu, unstable_mu, duration=duration, fs=fs, noise=noise, seed=seed)


def demo_system(seed: int = 0, fast: bool = False) -> tuple[RecordingSet, PlantedHopf]:
    """A flutter-rig-like subcritical set and its planted truth.

    ``μ0 = 18``, ``a2 = 3.4`` (fold ``μ_SN = 18 − 3.4²/4 = 15.11`` m/s), stable
    LCOs at :data:`DEMO_STABLE_MU`, unstable ones at :data:`DEMO_UNSTABLE_MU`,
    ω0 = 2π·2.5 rad/s, heave of a few cm, pitch about 0.1 rad, 2 % noise.

    Args:
        seed: Seed of the phases and the noise.
        fast: Shorter, coarser records (4 s at 100 Hz instead of 8 s at 200 Hz)
            for quick runs; the planted system is the same.

    Returns:
        ``(recordings, truth)``.
    """
    truth = PlantedHopf()
    duration, fs = (4.0, 100.0) if fast else (8.0, 200.0)
    rs = truth.simulate(
        DEMO_STABLE_MU, DEMO_UNSTABLE_MU, duration=duration, fs=fs, noise=0.02, seed=seed
    )
    return rs, truth
