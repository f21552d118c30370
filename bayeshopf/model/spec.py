"""The collapsed model's structure and the normal form's limit cycles under it.

:class:`CollapsedSpec` holds the model's static structure and data constants;
:func:`radius` is the normal form's LCO radius at μ for one draw of its
parameters, with the curved unfolding (:func:`unfolding`) where it has one.
The model itself is :mod:`bayeshopf.model.collapsed`.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from bayeshopf.features.frame import PlanarFrame
from bayeshopf.model import horizontal, normal_form

#: Monomials ``ũ1^i ũ2^j`` of the map, by degree ``i + j`` (0: T_s; 1: T_L's gains;
#: 2 and 3: the polynomial shape terms), each also multiplied by μ̃ and μ̃².
MONOMIALS = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2), (3, 0), (2, 1), (1, 2), (0, 3))
#: Powers of μ̃ that multiply each monomial (T_L's μ column, L_1, L_2, …).
MU_POWERS = (0, 1, 2)
#: Names of the control's columns: the real and imaginary parts of ``H``.
CONTROL_TERMS = ("control_re", "control_im")


@dataclass(frozen=True)
class CollapsedSpec:
    """Static structure and data constants of the collapsed model (immutable).

    Attributes:
        criticality: ``"subcritical"`` or ``"supercritical"``.
        frame: The common planar frame of the features.
        n_harmonics: K.
        mu_centre: μ_c (centre of the training μ).
        mu_span: Δμ (range of the training μ); also the prior scale of the gaps.
        mu_min: Smallest training μ.
        mu_unstable_max: Largest unstable training μ, or ``None``.
        orbit_scale: ρ, the median amplitude of the orbits' fundamentals (frame units).
        nn_hidden: Hidden weights ``W_1`` (3 × H) and biases ``b_1`` (H,) of the
            network (a fixed draw from their unit-normal prior).
        mu_label: Name of μ.
        mu_units: Unit of μ.
        unfolding: ``"linear"`` (the paper's ``μ − μ0``), ``"curved"``
            (:func:`unfolding`, one more parameter ``w`` with a unit-normal prior),
            ``"horizontal"`` (the diagram's curve with a Gaussian process in
            its curvature) or ``"window"`` (that curve with a window in its
            curvature at the fold; both :mod:`bayeshopf.model.horizontal`).
        omega_centre: ``ω̄``, the mean measured angular frequency (rad/s), or
            ``None`` for a model without the frequency.
        control_scale: Prior sd of the control's gain ``h`` (frame units per
            unit of the control channel), or ``None`` for a model without the
            control term (:mod:`bayeshopf.model.collapsed`, "Control").
        discrepancy_scale: ``q_{c,h}`` ``(2, 2K+1)`` of the model discrepancy
            (:mod:`bayeshopf.model.discrepancy`), or ``None`` for a model
            without it (then the relative model error is ``σ_rel y``, the
            model of fits saved before the discrepancy existed).
        discrepancy_floor: ``κ`` of :func:`~bayeshopf.model.discrepancy.scales`
            (0: purely relative to the model's orbit).
        nn_training: ``(μ, sign)`` of the training recordings when the network
            is its infinite-width Gaussian process
            (:mod:`bayeshopf.model.network_kernel`; ``nn_hidden`` is then empty),
            or ``None`` for the network with the fixed hidden layer ``nn_hidden``.
        nn_mu_scale: ``ν``, the scale of the infinite-width network's input
            weight on ``μ̃``, or ``None`` where it is sampled (the site
            ``nu_mu``, :data:`~bayeshopf.model.network_kernel.NU_PRIOR`).
    """

    criticality: str
    frame: PlanarFrame
    n_harmonics: int
    mu_centre: float
    mu_span: float
    mu_min: float
    mu_unstable_max: float | None
    orbit_scale: float
    nn_hidden: tuple
    mu_label: str = "mu"
    mu_units: str = ""
    unfolding: str = "curved"
    omega_centre: float | None = None
    control_scale: float | None = None
    discrepancy_scale: tuple | None = None
    discrepancy_floor: float = 0.0
    nn_training: tuple | None = None
    nn_mu_scale: float | None = 1.0

    @property
    def has_discrepancy(self) -> bool:
        """Whether the model includes the discrepancy Gaussian process."""
        return self.discrepancy_scale is not None

    @property
    def samples_nu_mu(self) -> bool:
        """Whether the infinite-width network's input scale on ``μ̃`` is a site (``nu_mu``)."""
        return self.nn_training is not None and self.nn_mu_scale is None

    def mu_tilde(self, mu):
        """``μ̃ = (μ − μ_c)/Δμ``."""
        return (mu - self.mu_centre) / self.mu_span

    @property
    def n_basis(self) -> int:
        """Number of columns J of ``Φ``: the map's basis functions, then the control's two."""
        return self.n_map + (0 if self.control_scale is None else len(CONTROL_TERMS))

    @property
    def n_map(self) -> int:
        """Number of the map's own basis functions (monomials and network)."""
        return len(MONOMIALS) * len(MU_POWERS) + self.n_network

    @property
    def n_network(self) -> int:
        """The network's columns: ``H`` hidden units, or ``n_train (2K+1)`` latents at H = ∞."""
        if self.nn_training is None:
            return int(np.shape(self.nn_hidden[0])[1])
        return len(self.nn_training[0]) * (2 * self.n_harmonics + 1)

    def to_dict(self) -> dict:
        """JSON-serialisable form."""
        d = {k: getattr(self, k) for k in self.__dataclass_fields__
             if k not in ("frame", "nn_hidden")}
        d["frame"] = self.frame.to_dict()
        d["nn_hidden"] = [np.asarray(a).tolist() for a in self.nn_hidden]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> CollapsedSpec:
        """Inverse of :meth:`to_dict`."""
        d = dict(d)
        d["frame"] = PlanarFrame.from_dict(d["frame"])
        d["nn_hidden"] = tuple(np.asarray(a) for a in d["nn_hidden"])
        if d.get("discrepancy_scale") is not None:
            d["discrepancy_scale"] = tuple(tuple(float(v) for v in row)
                                           for row in d["discrepancy_scale"])
        if d.get("nn_training") is not None:
            d["nn_training"] = tuple(tuple(float(v) for v in row) for row in d["nn_training"])
        return cls(**d)


def hidden_layer(width: int, seed: int = 0) -> tuple:
    """A fixed draw ``(W_1, b_1) ~ N(0, 1)`` of the network's hidden layer (3 inputs)."""
    rng = np.random.default_rng(seed)
    return rng.standard_normal((3, width)), rng.standard_normal(width)

def reference_radius(spec: CollapsedSpec, a2):
    """``r_ref``: ``√a2`` (subcritical: the stable radius at μ0), ``√Δμ`` (supercritical)."""
    if spec.criticality == "subcritical":
        return jnp.sqrt(a2)
    return jnp.sqrt(spec.mu_span) * jnp.ones_like(a2)


def unfolding(mu, mu0, w, mu_fold):
    r"""The unfolding ``β(μ)`` that replaces ``μ − μ0`` in ``ṙ = β r + a2 r³ − r⁵``.

    .. math::  β(μ) = \frac{e^{b(μ-μ0)} - 1}{b},\qquad b = \frac{w}{μ0 - μ_{SN}},

    monotone for every ``w`` (its slope ``e^{b(μ−μ0)}`` is positive), with
    ``β(μ0) = 0`` and ``β'(μ0) = 1``, so μ0 stays the Hopf point; ``w = 0`` is the
    paper's ``μ − μ0``. ``w`` is the log of the ratio of the unfolding's slopes at
    μ0 and at the fold.
    """
    x = mu - mu0
    bx = w * x / (mu0 - mu_fold)
    safe = jnp.where(jnp.abs(bx) < 1e-8, 1.0, bx)
    return jnp.where(jnp.abs(bx) < 1e-8, x * (1 + 0.5 * bx), x * jnp.expm1(safe) / safe)


def radius(spec: CollapsedSpec, mu, sign, theta: dict):
    """Normal-form LCO radius at μ (``nan`` where the branch does not exist).

    With a horizontal unfolding (``theta`` holds ``h_coef``), the root of
    its curve (:func:`~bayeshopf.model.horizontal.position`), ``r = √(a2 x)``.
    """
    a2, a4 = theta.get("a2", -1.0), theta.get("a4", -1.0)
    if "h_coef" in theta:
        form = "window" if spec.unfolding == "window" else "process"
        x = horizontal.position(mu, sign, theta["mu0"], theta["mu_fold"], theta["h_coef"], form)
        return jnp.sqrt(a2 * x)
    if "w_unfold" in theta:
        beta = unfolding(mu, theta["mu0"], theta["w_unfold"], theta["mu_fold"])
        return normal_form.lco_radius(beta, 0.0, a2, sign, a4)
    return normal_form.lco_radius(mu, theta["mu0"], a2, sign, a4)
