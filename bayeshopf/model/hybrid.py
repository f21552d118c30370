"""The hybrid model: normal-form orbits mapped to the measured plane.

A recording at ``μ`` on branch ``s`` is predicted by the closed-form LCO of the
normal form, ``u(φ) = r(μ, s) [cos φ, sin φ]``, mapped by ``U12`` into the
common planar frame and put in polar form; its least-squares Fourier
coefficients ``Φ(R̂)`` are compared with the measured ``Φ(R)`` (eq. XiU). These
are pure functions of a :class:`HopfParams` pytree; the NumPyro model
(:mod:`bayeshopf.model.probabilistic`) and every prediction call them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from bayeshopf.features import fourier
from bayeshopf.features.frame import PlanarFrame
from bayeshopf.model import normal_form
from bayeshopf.model.coordinate_map import (
    U12,
    MLPParams,
    linear_map,
    lower_triangular,
    mlp_shapes,
)

Criticality = Literal["subcritical", "supercritical"]


@dataclass(frozen=True)
class ModelSpec:
    """Static structure of a hybrid model and the data-derived constants of its priors.

    Attributes:
        criticality: ``"subcritical"`` (a2 > 0 and a4 = −1: both branches, a
            fold) or ``"supercritical"`` (a2 = −1 and a4 = −κ ≤ 0: one stable
            branch).
        frame: The common planar frame of the features.
        n_h: Harmonics of R(θ).
        mu_centre: μ_c, the centre of the training μ (NN input scaling).
        mu_span: Δμ, the spread of the training μ; also the scale of the priors
            on the distances from the data to μ0 and to the fold.
        mu_min: Smallest training μ (every branch must exist there).
        mu_unstable_max: Largest training μ on the unstable branch, or ``None``.
        orbit_scale: Median a0 of the measured R(θ) (frame units), the scale of
            the orbits.
        nn_width: Neurons per hidden layer of the map's MLP.
        nn_depth: Hidden layers of the map's MLP.
        n_phi: Points per predicted orbit.
    """

    criticality: Criticality
    frame: PlanarFrame
    n_h: int
    mu_centre: float
    mu_span: float
    mu_min: float
    mu_unstable_max: float | None
    orbit_scale: float
    nn_width: int = 10
    nn_depth: int = 2
    n_phi: int = 64
    mu_label: str = "mu"
    mu_units: str = ""
    extra: dict = field(default_factory=dict, compare=False, hash=False)

    @property
    def nn_shapes(self) -> list[tuple[int, int]]:
        """Weight shapes of the map's MLP (3 inputs u1, u2, μ̃; 2 outputs)."""
        return mlp_shapes(3, self.nn_width, self.nn_depth, 2)

    def mu_tilde(self, mu):
        """``μ̃ = (μ − μ_c)/Δμ``."""
        return (mu - self.mu_centre) / self.mu_span

    def to_dict(self) -> dict:
        """JSON-serialisable form (saved beside a fit)."""
        d = {k: getattr(self, k) for k in self.__dataclass_fields__ if k not in ("frame", "extra")}
        d["frame"] = self.frame.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> ModelSpec:
        """Inverse of :meth:`to_dict`."""
        d = dict(d)
        d["frame"] = PlanarFrame.from_dict(d["frame"])
        return cls(**d)


class HopfParams(NamedTuple):
    """Parameters of the hybrid model (one posterior draw, or a batch of them).

    Attributes:
        mu0: Hopf point μ0.
        a2: Cubic coefficient; the fold is at ``μ0 − a2²/4``.
        T_L: Linear part of the map, shape ``(2, 3)``.
        T_L1: μ̃-slope of T_L's 2×2 block (lower-triangular), shape ``(2, 2)``.
        T_s: Shift of the map, shape ``(2,)``.
        nn: Weights of the map's MLP correction.
        nn_scale: Output scale of the MLP.
        a4: Quintic coefficient: ``−1`` in the subcritical gauge, ``−κ`` in the
            supercritical one (where ``a2 = −1``; :mod:`~bayeshopf.model.normal_form`).
        T_L2: μ̃²-coefficient of T_L's 2×2 block (lower-triangular), shape
            ``(2, 2)``, or ``None``.
    """

    mu0: jax.Array
    a2: jax.Array
    T_L: jax.Array
    T_L1: jax.Array
    T_s: jax.Array
    nn: MLPParams
    nn_scale: jax.Array
    a4: jax.Array | float = -1.0
    T_L2: jax.Array | None = None


#: Sites added to the model after fits had been saved without them; when absent,
#: :func:`params_from_sites` uses the model they extend (``T_L2 = None``: no μ̃²
#: term; ``a4 = −1``: the quintic gauge of the earlier supercritical model).
OPTIONAL_SITES = ("T_L2", "a4")


def param_site_names(spec: ModelSpec, present=None) -> list[str]:
    """Names of the sites :func:`params_from_sites` reads (``a4`` only when it is free).

    Args:
        spec: The model structure.
        present: Names available (e.g. a saved fit's draws), or ``None``. When
            given, the :data:`OPTIONAL_SITES` missing from it are left out.
    """
    names = ["mu0", "a2", "T_L_diag", "T_L_21", "T_L_mu", "T_L1", "T_L2", "T_s", "nn_scale"]
    if spec.criticality == "supercritical":
        names.append("a4")
    names += [f"nn_{w}{i}" for i in range(len(spec.nn_shapes)) for w in ("W", "b")]
    if present is None:
        return names
    return [k for k in names if k in present or k not in OPTIONAL_SITES]


def params_from_sites(sites: dict, spec: ModelSpec) -> HopfParams:
    """Build :class:`HopfParams` from the NumPyro site values of one draw."""
    n = len(spec.nn_shapes)
    nn = MLPParams(
        tuple(sites[f"nn_W{i}"] for i in range(n)), tuple(sites[f"nn_b{i}"] for i in range(n))
    )
    return HopfParams(
        mu0=sites["mu0"],
        a2=sites["a2"],
        T_L=linear_map(sites["T_L_diag"], sites["T_L_21"], sites["T_L_mu"]),
        T_L1=lower_triangular(sites["T_L1"][:2], sites["T_L1"][2]),
        T_s=sites["T_s"],
        nn=nn,
        nn_scale=sites["nn_scale"],
        a4=sites.get("a4", -1.0),
        T_L2=lower_triangular(sites["T_L2"][:2], sites["T_L2"][2]) if "T_L2" in sites else None,
    )


def orbit_at(params: HopfParams, mu, sign, phi, spec: ModelSpec):
    """Points of the predicted orbit at normal-form phases φ, shape ``phi.shape + (2,)``.

    ``w(φ) = U12(r(μ, sign) [cos φ, sin φ], μ̃)`` in the planar frame; ``nan``
    where the branch does not exist.
    """
    r = normal_form.lco_radius(mu, params.mu0, params.a2, sign, params.a4)
    u = r * jnp.stack([jnp.cos(phi), jnp.sin(phi)], axis=-1)
    return U12(
        u, spec.mu_tilde(mu), params.T_L, params.T_L1, params.T_s, params.nn, params.nn_scale,
        params.T_L2,
    )


def orbit_in_frame(params: HopfParams, mu, sign, spec: ModelSpec):
    """Predicted orbit in the planar frame, shape ``(n_phi, 2)``.

    ``u(φ) = r(μ, sign) [cos φ, sin φ]`` on a uniform φ grid, mapped by U12.
    Where the branch does not exist the points are ``nan``.
    """
    phi = jnp.linspace(0.0, 2.0 * jnp.pi, spec.n_phi, endpoint=False)
    return orbit_at(params, mu, sign, phi, spec)


def predicted_coeffs(params: HopfParams, mu, sign, spec: ModelSpec):
    """``Φ(R̂)``: Fourier coefficients of the predicted orbit's R(θ) (eq. XiU)."""
    R, theta = fourier.polar(orbit_in_frame(params, mu, sign, spec))
    return fourier.project(theta, R, spec.n_h)


def orbit_physical(params: HopfParams, mu, sign, spec: ModelSpec):
    """Predicted orbit in physical units ``z = c + L w``, shape ``(n_phi, 2)``."""
    return spec.frame.from_frame(orbit_in_frame(params, mu, sign, spec))


def amplitude(params: HopfParams, mu, sign, spec: ModelSpec):
    """Predicted amplitude: peak-to-peak of z1 over the mapped orbit (``nan`` if no LCO)."""
    z1 = orbit_physical(params, mu, sign, spec)[..., 0]
    return jnp.max(z1, axis=-1) - jnp.min(z1, axis=-1)


_SPEC_JITS: dict[tuple[int, str], tuple] = {}


def jit_for_spec(spec: ModelSpec, kind: str, build):
    """``jax.jit(build())``, compiled once per (spec, kind) and cached.

    A :class:`ModelSpec` holds arrays and is not hashable, so it cannot be a
    static argument; the cache is keyed on its identity and keeps it alive.
    """
    hit = _SPEC_JITS.get((id(spec), kind))
    if hit is None or hit[0] is not spec:
        if len(_SPEC_JITS) > 64:
            _SPEC_JITS.clear()
        hit = (spec, jax.jit(build()))
        _SPEC_JITS[(id(spec), kind)] = hit
    return hit[1]


def clear_spec_jits() -> None:
    """Forget every cached :func:`jit_for_spec` program."""
    _SPEC_JITS.clear()


def branch_signs(unstable) -> np.ndarray:
    """Closed-form branch signs (+1 stable, −1 unstable) from a boolean mask."""
    return np.where(np.asarray(unstable), normal_form.UNSTABLE, normal_form.STABLE)
