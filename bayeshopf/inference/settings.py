"""Settings of the collapsed model's inference, and the model's arguments from the features.

:class:`CollapsedSettings` holds every choice of a fit; :func:`build_spec` reads
the model's structure and data constants (:class:`~bayeshopf.model.collapsed.CollapsedSpec`)
off the features, and :func:`model_arguments` gives the keyword arguments of
:func:`~bayeshopf.model.collapsed.collapsed_model`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from bayeshopf.errors import FitError
from bayeshopf.features.harmonics import HarmonicFeatures
from bayeshopf.model import collapsed as cm
from bayeshopf.model import discrepancy as dm

#: ``κ`` of the discrepancy in μ (:mod:`bayeshopf.model.bifurcation_shift`), chosen
#: by the interval scores of μ0 and the fold on a development block of simulated
#: rigs and tested on a fresh one (``docs/model_discrepancy.md``).
MU_DISCREPANCY = 2.0
#: ``φ``, the floor on ``η`` in the discrepancy in μ's scale ``κ√(η² + φ²)G``
#: (η's prior scale), chosen and tested as :data:`MU_DISCREPANCY` was.
MU_DISCREPANCY_FLOOR = 0.05


def _positive_or_none(x) -> bool:
    """Whether ``x`` is ``None`` or a finite number > 0 (not a bool)."""
    return x is None or (not isinstance(x, bool) and isinstance(x, (int, float))
                         and math.isfinite(x) and x > 0)


@dataclass(frozen=True)
class CollapsedSettings:
    """Settings of :func:`~bayeshopf.posterior.fit_hybrid` (the defaults are the documented ones).

    Attributes:
        n_harmonics: Harmonics per channel of the features.
        segment_periods: Segment length in periods.
        nn_width: Hidden units of the map's network; ``None`` (the default):
            its limit of infinite width, a Gaussian process with the network's
            kernel (:mod:`bayeshopf.model.network_kernel`), which has no hidden
            layer to draw.
        nn_mu_scale: At infinite width, the scale ``ν`` of the network's input
            weight on μ̃ (how fast the map may bend in μ, and how fast a
            prediction's spread grows away from the recordings); ``None``:
            sampled (:data:`~bayeshopf.model.network_kernel.NU_PRIOR`).
        nn_seed: Seed of the network's fixed hidden layer (a draw from its
            prior, :func:`~bayeshopf.model.collapsed.hidden_layer`; refit with
            others to see what the draw decides); unused at infinite width.
        unfolding: ``"curved"`` (default), ``"linear"`` (the paper's ``μ − μ0``),
            ``"horizontal"`` (the curve in μ with a Gaussian process in its
            curvature) or ``"window"`` (that curve with a window of learned depth
            and width in its curvature at the fold; both
            :mod:`bayeshopf.model.horizontal`, subcritical only).
        inference: ``"importance"`` (the default: draws from the MAP's Laplace
            approximation weighted by the posterior, NUTS where their check
            fails; :mod:`bayeshopf.inference.importance`), ``"nuts"`` or ``"svi"``.
        num_chains: NUTS chains (and, times ``num_samples``, the draws that
            importance sampling returns).
        num_warmup: NUTS warm-up steps per chain.
        num_samples: NUTS draws per chain before the first convergence check.
        extend_samples: Draws per chain added while a checked site fails R̂ or
            ESS (:data:`~bayeshopf.inference.nuts.RHAT_MAX`,
            :data:`~bayeshopf.inference.nuts.ESS_MIN`).
        max_samples: Most draws per chain; the chains stop here whatever the
            diagnostics say, and the CLI warns about the sites that fail.
        dense_mass: Adapt a dense mass matrix (the gaps, ``w`` and ``τ_μ`` are
            correlated: against a diagonal one it takes smaller trees and gives
            more effective draws per draw).
        target_accept: NUTS's target acceptance probability during warm-up.
        max_tree_depth: NUTS's largest tree depth (``2**depth − 1`` leapfrog steps).
        svi_steps: SVI steps (``inference="svi"``).
        n_svi_draws: Draws of the SVI posterior.
        lbfgs_steps: Most L-BFGS steps of the MAP.
        frequency: Whether the model includes the frequency ``Ω(r, μ)``.
        extrapolation: Whether a new measurement's band includes the model error
            away from the recordings (:func:`~bayeshopf.model.collapsed.extrapolation_sd`;
            zero at the training recordings, so the fit and its checks do not change).
        extrapolation_scale: Half-normal scale ``S`` of an extra model error
            away from the recordings, ``s_e ~ HalfNormal(S)`` in log orbit size
            (a user's override; it changes the bands of new measurements only).
            ``None`` (the default): none with the discrepancy, whose own process
            widens those bands; without it
            :data:`~bayeshopf.model.collapsed.EXTRAPOLATION_SCALE` (0.1).
        control: Whether the model includes the response to the control's
            residual fundamental, where the recordings name a control channel
            (:mod:`bayeshopf.model.collapsed`, "Control").
        discrepancy: Whether the model includes the model discrepancy, a
            Gaussian process over the diagram on the orbits' fundamental whose
            scale and length are sampled with the normal form
            (:mod:`bayeshopf.model.discrepancy`; ``docs/model_discrepancy.md``).
            On by default; off, the model is exact up to a relative model error
            ``σ_rel y`` of each coefficient.
        discrepancy_floor: ``κ``, the floor of the discrepancy's scale near the
            Hopf point relative to its training mean
            (:func:`~bayeshopf.model.discrepancy.scales`; 0: purely relative).
        mu_discrepancy: With the discrepancy, ``κ`` of its twin in μ at the Hopf
            point and the fold (:mod:`bayeshopf.model.bifurcation_shift`): the
            fit's ``mu0`` and ``mu_fold`` intervals are the rig's, the normal
            form's points moved by an error in μ of ``κ √(η² + φ²) G`` times a unit
            process held at zero at the recordings; 0 reports the normal form's
            own points.
        mu_discrepancy_floor: ``φ``, the floor on ``η`` in that error's scale,
            ``κ √(η² + φ²) G``: a close fit to the recordings does not show that
            the model extrapolates well; 0 for none.
    """

    # features
    n_harmonics: int = 4
    segment_periods: float = 5.0
    # the map's network
    nn_width: int | None = None
    nn_mu_scale: float | None = 1.0
    nn_seed: int = 0
    # the normal form's unfolding
    unfolding: str = "curved"
    # inference, and NUTS
    inference: str = "importance"
    num_chains: int = 4
    num_warmup: int = 500
    num_samples: int = 500
    extend_samples: int = 250
    max_samples: int = 2000
    dense_mass: bool = True
    target_accept: float = 0.8
    max_tree_depth: int = 10
    # SVI and the MAP
    svi_steps: int = 3000
    n_svi_draws: int = 2000
    lbfgs_steps: int = 300
    # parts of the model
    frequency: bool = True
    extrapolation: bool = True
    control: bool = True
    extrapolation_scale: float | None = None
    # the model discrepancy
    discrepancy: bool = True
    discrepancy_floor: float = dm.FLOOR
    mu_discrepancy: float = MU_DISCREPANCY
    mu_discrepancy_floor: float = MU_DISCREPANCY_FLOOR

    def __post_init__(self):
        w = self.nn_width
        if w is not None and (isinstance(w, bool) or not isinstance(w, int) or w < 1):
            raise FitError("nn_width: a positive whole number of hidden units, or None for the "
                           f"network's limit of infinite width, expected; got {w!r}")
        v = self.nn_mu_scale
        if not _positive_or_none(v):
            raise FitError("nn_mu_scale: a positive number, or None to sample it, expected; "
                           f"got {v!r}")
        if v != 1.0 and w is not None:
            raise FitError("nn_mu_scale: the network's input scale on μ is set only at "
                           f"infinite width (nn_width=None); got nn_width={w!r}")
        for name, what in (("mu_discrepancy", "κ of the discrepancy in μ at the Hopf point "
                             "and the fold"),
                           ("mu_discrepancy_floor", "φ, the floor on η in the discrepancy in "
                            "μ's scale")):
            k = getattr(self, name)
            if isinstance(k, bool) or not isinstance(k, int | float) or not 0 <= k < math.inf:
                raise FitError(f"{name}: a finite number ≥ 0 expected ({what}; 0: none); "
                               f"got {k!r}")
        s = self.extrapolation_scale
        if not _positive_or_none(s):
            raise FitError("extrapolation_scale: a positive number or None expected (the "
                           "half-normal scale of an extra model error away from the "
                           "recordings, in log orbit size; None: none with the discrepancy, "
                           f"{cm.EXTRAPOLATION_SCALE} without it); got {s!r}")

    @classmethod
    def fast(cls) -> CollapsedSettings:
        """Shorter chains for smoke tests, never extended (R̂ and ESS usually fail then)."""
        return cls(num_chains=2, num_warmup=200, num_samples=200, max_samples=200,
                   svi_steps=1000, n_svi_draws=400)


def build_spec(features: HarmonicFeatures, criticality: str, *, nn_width: int | None = 16,
               unfolding: str = "curved", mu_label: str = "mu",
               mu_units: str = "", frequency: bool = True,
               control: bool = True, discrepancy: bool = False,
               discrepancy_floor: float = dm.FLOOR, nn_seed: int = 0,
               nn_mu_scale: float | None = 1.0) -> cm.CollapsedSpec:
    """Structure and data constants of the collapsed model.

    The control term is on when ``control`` is true and the features hold a
    control channel whose fundamental is not zero throughout; its prior sd is
    ``CONTROL_SCALE · ρ / ū`` (``ū`` the RMS of ``|U_i|``). With ``discrepancy``
    the model includes the discrepancy Gaussian process, its coefficient
    scales ``q`` read off the features (:mod:`bayeshopf.model.discrepancy`).
    ``nn_width=None`` gives the network at infinite width, over the features'
    recordings (:mod:`bayeshopf.model.network_kernel`), with the input scale
    ``nn_mu_scale`` on μ (``None``: sampled).

    Raises:
        FitError: For fewer than two distinct μ, an unknown criticality or
            unfolding, or unstable recordings under a supercritical model.
    """
    if criticality not in ("subcritical", "supercritical"):
        raise FitError(f"criticality must be 'subcritical' or 'supercritical'; got {criticality!r}")
    if unfolding not in ("curved", "linear", "horizontal", "window"):
        raise FitError("unfolding must be 'curved', 'linear', 'horizontal' or 'window'; got "
                       f"{unfolding!r}")
    mu = features.mu
    if np.unique(mu).size < 2:
        raise FitError(f"the fit needs recordings at two or more distinct values of μ; found "
                       f"{features.n_recordings} recording(s) at μ = {sorted(set(mu.tolist()))}")
    if criticality == "supercritical" and features.unstable.any():
        raise FitError("criticality 'supercritical' has no unstable LCO branch, but the data hold "
                       f"{int(features.unstable.sum())} unstable recording(s)")
    orbits = features.orbit()
    rms = np.sqrt(np.mean(np.sum((orbits - orbits.mean(axis=1, keepdims=True)) ** 2, -1), -1))
    unstable_mu = mu[features.unstable]
    scale = float(np.median(rms))
    control_scale = None
    if control and features.control is not None:
        u_rms = float(np.sqrt(np.mean(np.sum(np.asarray(features.control) ** 2, axis=-1))))
        if u_rms > 0:
            control_scale = cm.CONTROL_SCALE * scale / u_rms
    return cm.CollapsedSpec(
        criticality=criticality, frame=features.frame, n_harmonics=features.n_harmonics,
        mu_centre=float(0.5 * (mu.max() + mu.min())), mu_span=float(mu.max() - mu.min()),
        mu_min=float(mu.min()),
        mu_unstable_max=float(unstable_mu.max()) if unstable_mu.size else None,
        orbit_scale=scale, nn_hidden=cm.hidden_layer(nn_width or 0, nn_seed),
        mu_label=mu_label, mu_units=mu_units,
        unfolding=unfolding if criticality == "subcritical" else "linear",
        omega_centre=float(np.mean(features.omega)) if frequency else None,
        control_scale=control_scale,
        discrepancy_scale=(tuple(map(tuple, dm.coefficient_scale(features.coeffs).tolist()))
                           if discrepancy else None),
        discrepancy_floor=float(discrepancy_floor),
        nn_training=None if nn_width is not None else (
            tuple(float(m) for m in mu),
            tuple(-1.0 if u else 1.0 for u in features.unstable)),
        nn_mu_scale=None if nn_mu_scale is None else float(nn_mu_scale),
    )



@dataclass(frozen=True, eq=False)
class ModelInputs(Mapping):
    """What the collapsed model is given: its structure and the features' arrays (immutable).

    Also a read-only mapping of the keyword arguments of
    :func:`~bayeshopf.model.collapsed.collapsed_model` (``control`` only when the
    model has the control term), so ``collapsed_model(**inputs)`` runs it.

    Attributes:
        spec: The model's structure and data constants.
        mu: μ of each recording, ``(n_rec,)``.
        sign: ``+1`` stable, ``−1`` unstable, ``(n_rec,)``.
        coeffs: Aligned harmonic coefficients, ``(n_rec, 2, 2K+1)``.
        coeffs_se: Their standard errors.
        omega: Angular frequency of each recording (rad/s).
        omega_se: Its standard error.
        control: The control channel's fundamental, ``(n_rec, 2)``, or ``None``.
    """

    spec: cm.CollapsedSpec
    mu: jax.Array
    sign: jax.Array
    coeffs: jax.Array
    coeffs_se: jax.Array
    omega: jax.Array
    omega_se: jax.Array
    control: jax.Array | None = None

    def _names(self) -> tuple[str, ...]:
        names = ("spec", "mu", "sign", "coeffs", "coeffs_se", "omega", "omega_se")
        return names if self.control is None else (*names, "control")

    def __getitem__(self, name: str):
        if name not in self._names():
            raise KeyError(name)
        return getattr(self, name)

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __len__(self) -> int:
        return len(self._names())


def model_arguments(spec: cm.CollapsedSpec, features: HarmonicFeatures) -> ModelInputs:
    """The :class:`ModelInputs` of a model ``spec`` and its features.

    Raises:
        FitError: When the model has the control term and the features no control channel.
    """
    control = None
    if spec.control_scale is not None:
        if features.control is None:
            raise FitError("the model has the control term but the features hold no control "
                           "channel; extract them from recordings that name one")
        control = jnp.asarray(features.control)
    return ModelInputs(spec=spec, mu=jnp.asarray(features.mu),
                       sign=jnp.asarray(np.where(features.unstable, -1.0, 1.0)),
                       coeffs=jnp.asarray(features.coeffs),
                       coeffs_se=jnp.asarray(features.coeffs_se),
                       omega=jnp.asarray(features.omega), omega_se=jnp.asarray(features.omega_se),
                       control=control)
