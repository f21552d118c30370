r"""The hybrid model with its linear part integrated out exactly (a neural-linear model).

**Normal form** (paper eq. NF-model-polar, :mod:`bayeshopf.model.normal_form`).
Recording ``i`` at ``μ_i`` on branch ``s_i`` is the circle of radius
``r_i = r(μ_i; μ0, a2, s_i)`` traversed at a constant phase speed, so over one
period ``u(φ) = r_i (cos φ, sin φ)`` with ``φ = ωt``.

**Map** (paper eq. g). In the frame ``w`` of the features
(:mod:`bayeshopf.features.harmonics`), with ``ũ = u / r_ref`` and
``μ̃ = (μ − μ_c)/Δμ``,

.. math::

    w(φ) = T_L\,[ũ_1, ũ_2, μ̃]^T + T_s + (μ̃ L_1 + μ̃^2 L_2)\,ũ + μ̃^2 t_2
           + \mathrm{NN}(ũ_1, ũ_2, μ̃),

    \mathrm{NN}(x) = W_2^T \tanh(W_1^T x + b_1) + \text{(degree-2 and -3 terms of ũ)},

Every coefficient of this map — ``T_L``, ``T_s``, ``L_1``, ``L_2``, ``t_2``, the
network's output layer ``W_2`` and the polynomial shape terms — enters ``w``
linearly. Collecting them in ``β_c`` (one column per channel ``c``), the
predicted harmonic coefficients of recording ``i`` are

.. math::  \hat y_{i,c} = Φ_i β_c,\qquad Φ_i = P\,Ψ(ũ(φ_n), μ̃_i),

with ``Ψ`` the basis functions at ``N`` uniform phases and ``P`` the discrete
Fourier projection onto ``[a_0, a_1..a_K, b_1..b_K]``.

**Priors.** ``β_{c,j} ~ N(0, v_j)`` with ``v_j`` set by the basis function's
group (module constants below): ``ρ`` (the orbit scale in the frame) times
``τ_μ^p`` for a term of power ``p`` in μ̃ and ``τ_s`` for the shape terms
(network and polynomial). ``τ_μ`` and ``τ_s`` are hyperparameters with
log-normal priors, integrated over with the rest: how much the map may change
with μ trades against μ0, and the posterior must carry that. The hidden layer
``(W_1, b_1)`` is a fixed draw from its unit-normal prior (random features), so
the network's prior is kept and its output layer integrated exactly; or
(``spec.nn_training`` set) the network is its limit of infinite width, a
Gaussian process with the network's kernel whose coefficients at the training
orbits are latent linear columns (:mod:`bayeshopf.model.network_kernel`), so no
draw of a hidden layer decides anything.

**Likelihood.** ``y_{i,c} ~ N(Φ_i β_c, diag(se_{i,c}^2 + σ_c^2 + σ_rel^2 y_{i,c}^2))``,
with ``se`` the measured standard errors, ``σ_c ~ HalfNormal(0.02 ρ)`` one
model-error scale per channel and ``σ_rel ~ HalfNormal(0.02)`` a model error in
proportion to each coefficient (no free per-harmonic scatter that could take up
the centre shift).

**Collapsing.** Given the few nonlinear parameters ``θ`` (the normal form's
gaps, ``τ_μ``, ``τ_s``, ``σ``), ``y_c`` is Gaussian with ``β_c`` integrated out,
``y_c | θ ~ N(0, Φ V Φᵀ + D)`` (:mod:`bayeshopf.model.marginal`, Woodbury form,
``V = diag(v)``, ``D = diag(se² + σ² + …)``), and ``β_c | y, θ`` is Gaussian.
The posterior of ``θ`` is sampled; ``β`` is drawn exactly given each draw of ``θ``.

**Frequency** (the phase equation ``θ̇ = Ω``, :mod:`bayeshopf.model.frequency`):
``ω_i = Ω(r_i, μ_i)``, a polynomial in ``r̃²`` and ``μ̃`` linear in its
coefficients ``γ``, integrated out by the same marginal.

**Control** (recordings held by control-based continuation, when the rig
records the controller's output; ``docs/model.md``). What CBC's search leaves
of the control's fundamental, ``U_i = u_{a,i} − i u_{b,i}`` on the features'
time origin, is measured; to first order it moves the second frame axis's
fundamental ``a_{2,1} − i b_{2,1}`` by ``H U_i``, ``H = h_r + i h_i``,

.. math::  Δa_{2,1} = h_r u_a + h_i u_b,\qquad Δb_{2,1} = h_r u_b − h_i u_a,

two more columns of ``Φ_i`` for ``w2`` (:func:`control_columns`; zero for
``w1``, whose crest is the time origin and whose size CBC's target sets),
integrated out with the map: ``h_r, h_i ~ N(0, (κ ρ / ū)^2)``, ``ū`` the RMS
of ``|U_i|`` and ``κ =`` :data:`CONTROL_SCALE`. Predictions at a new μ, the
diagram and its branches are the uncontrolled system's (``U = 0``).

**Model discrepancy** (:mod:`bayeshopf.model.discrepancy`). The recorded
coefficients are the model's plus a discrepancy ``Δ``, a Gaussian process over
the diagram on the orbit's fundamental (smooth, scale ``η``, length ``ℓ``) and
on every harmonic (independent, ``σ_rel``), both relative to the model's own
orbit size. Its smooth part is a few more linear columns of ``Φ`` (one latent
per recording and fundamental coefficient, :func:`linear_system`), integrated
out with the map; its independent part replaces ``σ_rel y`` in ``D``. ``η`` and
``ℓ`` are sampled with the normal form, so the Hopf and fold intervals widen
when the recordings disagree with the model, and predictions at a new μ take
the discrepancy's conditional there (``predictive.discrepancy_draws``). With
``spec.discrepancy_scale = None`` the model is the one without it (``D =
diag(se² + σ_c² + (σ_rel y)²)``).

**Extra model error away from the recordings** (predictions only): the rule of
the model without the discrepancy and a user's override,
:mod:`bayeshopf.model.extrapolation` (its constants re-exported here).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

from bayeshopf.features.harmonics import coefficient_names
from bayeshopf.model import discrepancy as dm
from bayeshopf.model import horizontal as hz
from bayeshopf.model import network_kernel as nk
from bayeshopf.model.extrapolation import (  # noqa: F401 (re-exported)
    EXTRAPOLATION_LENGTH,
    EXTRAPOLATION_SCALE,
    extrapolation_sd,
)
from bayeshopf.model.frequency import (  # noqa: F401 (re-exported)
    FREQUENCY_SCALE,
    FREQUENCY_TERMS,
    SIGMA_OMEGA_PRIOR,
    draw_frequency,
    frequency,
    frequency_basis,
    frequency_design,
    frequency_marginal,
    frequency_prior_sd,
    radius_tilde_squared,
)
from bayeshopf.model.marginal import (  # noqa: F401 (re-exported)
    _factored,
    _log_marginal_jvp,
    block_log_predictive,
    conditional_draw,
    log_marginal,
)
from bayeshopf.model.spec import (  # noqa: F401 (re-exported)
    CONTROL_TERMS,
    MONOMIALS,
    MU_POWERS,
    CollapsedSpec,
    hidden_layer,
    radius,
    reference_radius,
    unfolding,
)

#: Prior scale of the linear gains ``T_L[:, :2]`` relative to ρ (broad).
LINEAR_SCALE = 2.0
#: Prior scale of the shift ``T_s`` relative to ρ (the frame is centred on the data).
SHIFT_SCALE = 1.0
#: Log-normal prior of τ_μ (median, log-sd): a gain change of 10% per Δμ a priori.
TAU_MU_PRIOR = (0.1, 1.0)
#: Log-normal prior of τ_s (median, log-sd): shape terms of 10% of the orbit a priori.
TAU_SHAPE_PRIOR = (0.1, 1.0)
#: Half-normal scale of the model error σ_c relative to ρ.
SIGMA_PRIOR = 0.02
#: Half-normal scale of the relative model error σ_rel (a fraction of each coefficient).
SIGMA_REL_PRIOR = 0.02
#: Prior sd of the control's complex gain ``H`` in units of ``ρ / ū`` (module docstring).
CONTROL_SCALE = 1.0
#: Prior sd of the unfolding's curvature ``w`` (:func:`unfolding`; 0 is the paper's line).
UNFOLDING_PRIOR_SD = 1.0
#: Half-normal scale of the gaps to the fold and the Hopf point, in units of Δμ.
GAP_PRIOR = 1.0
#: Phases per orbit for the projection P (aliasing-free for K ≤ 8 with degree-3 terms).
N_PHI = 32


#: Prior scale, relative to ρ, of a monomial's coefficient by degree, before the
#: factors τ_μ^p (power p of μ̃) and τ_s (degree ≥ 2).
DEGREE_SCALE = {0: SHIFT_SCALE, 1: LINEAR_SCALE, 2: 1.0, 3: 1.0}

def basis_names(spec: CollapsedSpec) -> list[str]:
    """Readable names of the J basis functions (``"u1^2 m"``, ``"nn3"``, …)."""
    names = []
    for p in MU_POWERS:
        for i, j in MONOMIALS:
            term = " ".join(t for t in (f"u1^{i}" if i else "", f"u2^{j}" if j else "",
                                       f"m^{p}" if p else "") if t)
            names.append(term or "1")
    if spec.nn_training is None:
        names += [f"nn{h}" for h in range(spec.n_network)]
    else:
        names += [f"nn_{c}_rec{i}" for c in coefficient_names(spec.n_harmonics)
                  for i in range(len(spec.nn_training[0]))]
    return names + (list(CONTROL_TERMS) if spec.control_scale is not None else [])


def basis(u, mu_tilde, nn_hidden):
    """Basis functions ``Ψ(ũ, μ̃)``, shape ``(..., J)`` for ``ũ`` of shape ``(..., 2)``.

    The monomials ``ũ1^i ũ2^j μ̃^p`` (:data:`MONOMIALS` × :data:`MU_POWERS`), then
    the network's hidden features ``tanh(W_1ᵀ [ũ1, ũ2, μ̃] + b_1)``.
    """
    u1, u2 = u[..., 0], u[..., 1]
    m = jnp.broadcast_to(mu_tilde, u1.shape)
    mono = [u1**i * u2**j for i, j in MONOMIALS]
    cols = [c * m**p for p in MU_POWERS for c in mono]
    x = jnp.stack([u1, u2, m], axis=-1)
    W, b = nn_hidden
    h = jnp.tanh(x @ jnp.asarray(W) + jnp.asarray(b))
    return jnp.concatenate([jnp.stack(cols, axis=-1), h], axis=-1)


def prior_sd(spec: CollapsedSpec, tau_mu, tau_shape):
    """Prior standard deviations ``√v_j`` of the J coefficients (module docstring)."""
    rho = spec.orbit_scale
    sds = []
    for p in MU_POWERS:
        for i, j in MONOMIALS:
            deg = i + j
            s = rho * DEGREE_SCALE[deg] * tau_mu**p * (tau_shape if deg >= 2 else 1.0)
            sds.append(jnp.broadcast_to(s, jnp.shape(tau_mu)))
    H = spec.n_network          # hidden units, or the infinite-width network's latents
    unit = 1.0 if spec.nn_training is not None else 1.0 / np.sqrt(max(H, 1))
    nn = jnp.broadcast_to(rho * tau_shape * unit, jnp.shape(tau_mu) + (H,))
    parts = [jnp.stack(sds, axis=-1), nn]
    if spec.control_scale is not None:
        n = len(CONTROL_TERMS)
        parts.append(jnp.broadcast_to(spec.control_scale, jnp.shape(tau_mu) + (n,)))
    return jnp.concatenate(parts, axis=-1)


def projection(n_harmonics: int, n_phi: int = N_PHI) -> np.ndarray:
    """``P``: values at ``n_phi`` uniform phases → ``[a_0, a_1..a_K, b_1..b_K]``, (2K+1, N)."""
    phi = 2 * np.pi * np.arange(n_phi) / n_phi
    k = np.arange(1, n_harmonics + 1)[:, None]
    return np.concatenate([np.full((1, n_phi), 1.0 / n_phi), 2.0 / n_phi * np.cos(k * phi),
                           2.0 / n_phi * np.sin(k * phi)], axis=0)


def _monomial_harmonics(n_harmonics: int, n_phi: int) -> np.ndarray:
    """``P`` applied to each monomial ``cos^i φ sin^j φ`` on the unit circle, ``(2K+1, n_mono)``."""
    phi = 2 * np.pi * np.arange(n_phi) / n_phi
    mono = np.stack([np.cos(phi) ** i * np.sin(phi) ** j for i, j in MONOMIALS], axis=-1)
    return projection(n_harmonics, n_phi) @ mono


def control_columns(spec: CollapsedSpec, control):
    r"""The control's columns of ``Φ`` for ``w2``, ``(n, 2K+1, 2)`` (module docstring).

    Column ``h_r`` holds ``u_a`` at ``a_1`` and ``u_b`` at ``b_1``; column ``h_i``
    holds ``u_b`` at ``a_1`` and ``−u_a`` at ``b_1``: ``Δ(a_1 − i b_1) = H U``.

    Args:
        spec: Model structure (its ``n_harmonics``).
        control: ``(n, 2)``: ``(u_a, u_b)`` of each recording.
    """
    u = jnp.asarray(control)
    K = spec.n_harmonics
    z = jnp.zeros(u.shape[:1] + (2 * K + 1,))
    h_r = z.at[:, 1].set(u[:, 0]).at[:, K + 1].set(u[:, 1])
    h_i = z.at[:, 1].set(u[:, 1]).at[:, K + 1].set(-u[:, 0])
    return jnp.stack([h_r, h_i], axis=-1)


def design(spec: CollapsedSpec, mu, sign, theta: dict, n_phi: int = N_PHI, control=None,
           training: bool = False):
    r"""``Φ_i = P Ψ_i`` for every recording, shape ``(n_rec, 2K+1, J)``.

    On the circle ``ũ = s_i (\cos φ, \sin φ)`` (``s_i = r_i / r_ref``) a
    monomial column is ``s_i^{i+j} μ̃_i^p \cos^i φ \sin^j φ``, so its projection
    is ``s_i^{i+j} μ̃_i^p`` times a constant (:func:`_monomial_harmonics`); only
    the network's columns are evaluated at the ``n_phi`` phases. Equal to
    ``P · basis(ũ(φ_n), μ̃_i)`` (``tests/test_collapsed.py``), with a quarter of
    the work. At infinite width (``spec.nn_training``) the network's columns are
    :func:`~bayeshopf.model.network_kernel.columns`: at the training
    recordings the factor of its prior covariance, elsewhere the conditional
    mean given the training ones (``training``: ``mu`` and ``sign`` are those
    recordings, whose columns are then the factor itself). With the control
    term (``spec.control_scale``) the last two columns are
    :func:`control_columns` of ``control`` ``(n_rec, 2)``, those of ``w2``
    (:func:`channel_designs` gives ``w1`` zeros there); ``None`` means no
    control (the uncontrolled system: a new μ, the diagram).
    """
    phi = 2 * np.pi * np.arange(n_phi) / n_phi
    s = radius(spec, mu, sign, theta) / reference_radius(spec, theta.get("a2", -1.0))
    m = spec.mu_tilde(mu)
    deg = np.array([i + j for i, j in MONOMIALS])
    s_pow = jnp.stack([jnp.ones_like(s), s, s * s, s * s * s], axis=-1)[:, deg]   # (n, n_mono)
    m_pow = jnp.stack([m**p for p in MU_POWERS], axis=-1)                         # (n, n_pow)
    scale = (m_pow[:, :, None] * s_pow[:, None, :]).reshape(s.shape[0], -1)      # (n, J_mono)
    C = np.tile(_monomial_harmonics(spec.n_harmonics, n_phi), (1, len(MU_POWERS)))
    if spec.nn_training is None:
        W, b = (np.asarray(a) for a in spec.nn_hidden)
        pre = (s[:, None, None] * (np.cos(phi)[:, None] * W[0] + np.sin(phi)[:, None] * W[1])
               + m[:, None, None] * W[2] + b)                                      # (n, N, H)
        nn = jnp.einsum("kn,inh->ikh", projection(spec.n_harmonics, n_phi), jnp.tanh(pre))
    else:
        nn = nk.columns(spec, theta, mu, sign, n_phi, training=training)
    cols = [scale[:, None, :] * C, nn]
    if spec.control_scale is not None:
        cols.append(control_columns(spec, jnp.zeros((s.shape[0], 2)) if control is None
                                    else control))
    return jnp.concatenate(cols, axis=-1)


def pointwise_log_likelihood(spec: CollapsedSpec, theta: dict, mu, sign, coeffs, coeffs_se,
                             omega=None, omega_se=None, control=None):
    """``log p(y_i | y_{−i}, θ)`` of each recording: both channels' coefficients and ω.

    The channels and the frequency are independent given θ, so each
    recording's term is the sum of their :func:`block_log_predictive`.

    Args:
        spec: Structure and data constants.
        theta: One draw of every sampled and deterministic site.
        mu: μ of each recording, ``(n_rec,)``.
        sign: Branch sign of each recording.
        coeffs: Measured coefficients, ``(n_rec, 2, 2K+1)``.
        coeffs_se: Their standard errors.
        omega: Measured angular frequencies, or ``None``.
        omega_se: Their standard errors.
        control: The control's fundamental ``(n_rec, 2)``, or ``None``.

    Returns:
        Shape ``(n_rec,)``.
    """
    n = mu.shape[0]
    Phis, sd, ds = linear_system(spec, theta, mu, sign, coeffs, coeffs_se, control)
    total = sum(block_log_predictive(Phis[c], coeffs[:, c].reshape(-1), ds[c], sd, n)
                for c in range(2))
    if spec.omega_centre is not None and omega is not None:
        total = total + block_log_predictive(
            frequency_design(spec, mu, sign, theta), omega - spec.omega_centre,
            omega_se**2 + theta["sigma_omega"] ** 2, frequency_prior_sd(spec), n)
    return total


def normal_form_sites(spec: CollapsedSpec) -> dict:
    """The normal form's sites: gaps to the fold and the Hopf point (or κ), μ0, a2, a4.

    Subcritical: ``μ_SN = μ_min − g_fold``, ``μ0 = max(μ_SN, μ_u,max) + g_hopf``
    with ``g ~ HalfNormal(GAP_PRIOR · Δμ)``, so every recording lies on its branch; ``a2``
    follows from the fold, ``β(μ_SN) = −a2²/4``. Supercritical (gauge
    ``a2 = −1``, ``a4 = −κ``): ``μ0 = μ_min − g_hopf``, ``κ ~ HalfNormal(1/Δμ)``.
    """
    span = GAP_PRIOR * spec.mu_span
    if spec.criticality == "subcritical":
        g_fold = numpyro.sample("gap_fold", dist.HalfNormal(span))
        g_hopf = numpyro.sample("gap_hopf", dist.HalfNormal(span))
        mu_fold = numpyro.deterministic("mu_fold", spec.mu_min - g_fold)
        anchor = mu_fold if spec.mu_unstable_max is None else jnp.maximum(
            mu_fold, spec.mu_unstable_max)
        mu0 = numpyro.deterministic("mu0", anchor + g_hopf)
        theta = {"mu0": mu0, "mu_fold": mu_fold}
        if spec.unfolding == "horizontal":
            return {**theta, **hz.sites(mu0, mu_fold)}
        if spec.unfolding == "window":
            return {**theta, **hz.window_sites(mu0, mu_fold)}
        if spec.unfolding == "curved":
            w = numpyro.sample("w_unfold", dist.Normal(0.0, UNFOLDING_PRIOR_SD))
            theta["w_unfold"] = w
            beta_fold = -unfolding(mu_fold, mu0, w, mu_fold)
        else:
            beta_fold = mu0 - mu_fold
        theta["a2"] = numpyro.deterministic("a2", 2.0 * jnp.sqrt(beta_fold))
    else:
        g_hopf = numpyro.sample("gap_hopf", dist.HalfNormal(span))
        kappa = numpyro.sample("kappa", dist.HalfNormal(1.0 / spec.mu_span))
        theta = {"mu0": numpyro.deterministic("mu0", spec.mu_min - g_hopf), "a2": -1.0,
                 "a4": numpyro.deterministic("a4", -kappa)}
    return theta


def hyper_sites(spec: CollapsedSpec) -> dict:
    """``τ_μ``, ``τ_s``, the model error ``σ_c`` of each channel, the relative one ``σ_rel``.

    With the discrepancy also its scale ``η`` and length ``ℓ`` (``σ_rel`` its part
    independent between recordings); with ``spec.nn_mu_scale`` ``None``, ``ν``.
    """
    h = {"tau_mu": numpyro.sample(
            "tau_mu", dist.LogNormal(np.log(TAU_MU_PRIOR[0]), TAU_MU_PRIOR[1])),
         "tau_shape": numpyro.sample(
            "tau_shape", dist.LogNormal(np.log(TAU_SHAPE_PRIOR[0]), TAU_SHAPE_PRIOR[1])),
         "sigma": numpyro.sample(
            "sigma", dist.HalfNormal(SIGMA_PRIOR * spec.orbit_scale).expand([2]).to_event(1)),
         "sigma_rel": _relative_error(spec)}
    if spec.has_discrepancy:
        h["eta"] = numpyro.sample("eta", dist.HalfNormal(dm.ETA_PRIOR))
        h["ell"] = numpyro.sample("ell", dist.LogNormal(np.log(dm.LENGTH_PRIOR[0]),
                                                        dm.LENGTH_PRIOR[1]))
    if spec.samples_nu_mu:
        h["nu_mu"] = numpyro.sample("nu_mu", dist.LogNormal(np.log(nk.NU_PRIOR[0]),
                                                            nk.NU_PRIOR[1]))
    return h


def _relative_error(spec: CollapsedSpec):
    """``σ_rel ~ HalfNormal(SIGMA_REL_PRIOR)``; with the discrepancy as ``S|z|``, ``z ~ N(0, 1)``.

    The same prior (only ``σ_rel²`` enters the likelihood), but smooth through
    0, where its posterior reaches when ``η`` carries the misfit: in ``log σ_rel``
    (NumPyro's unconstrained space) a long tail that shrinks NUTS's steps.
    """
    if not spec.has_discrepancy:
        return numpyro.sample("sigma_rel", dist.HalfNormal(SIGMA_REL_PRIOR))
    z = numpyro.sample("sigma_rel_z", dist.Normal(0.0, 1.0))
    return numpyro.deterministic("sigma_rel", SIGMA_REL_PRIOR * jnp.abs(z))


def frequency_site(spec: CollapsedSpec):
    """``σ_ω ~ HalfNormal(SIGMA_OMEGA_PRIOR · ω̄)``, the frequency's model error (a site)."""
    return numpyro.sample("sigma_omega", dist.HalfNormal(SIGMA_OMEGA_PRIOR * spec.omega_centre))


def error_variance(coeffs, coeffs_se, sigma, sigma_rel):
    """``se² + σ_c² + (σ_rel y)²`` per coefficient, shape of ``coeffs`` ``(n_rec, 2, 2K+1)``.

    The measurement error, a model error per channel, and a model error in
    proportion to the coefficient (a misfit of the orbit's size grows with it).
    """
    return coeffs_se**2 + sigma[:, None] ** 2 + (sigma_rel * coeffs) ** 2


def discrepancy_geometry(spec: CollapsedSpec, theta: dict, mu, sign, mu_ref, sign_ref):
    """Scales ``g`` ``(n, 2, 2K+1)`` and coordinates ``x`` ``(n,)`` of the discrepancy at μ.

    ``mu_ref``, ``sign_ref``: the training recordings, whose radii normalise both
    (:mod:`bayeshopf.model.discrepancy`).
    """
    r_ref = reference_radius(spec, theta.get("a2", -1.0))
    s = radius(spec, mu, sign, theta) / r_ref
    same = mu is mu_ref and sign is sign_ref          # the training recordings themselves
    s_ref = s if same else radius(spec, mu_ref, sign_ref, theta) / r_ref
    return (dm.scales(jnp.asarray(spec.discrepancy_scale), s, s_ref, spec.discrepancy_floor),
            dm.coordinate(spec.mu_tilde(mu), s, s_ref))


def n_latent(spec: CollapsedSpec, n_rec: int) -> int:
    """Columns of the discrepancy's latent ``z`` for ``n_rec`` training recordings (0 without)."""
    if not spec.has_discrepancy:
        return 0
    return n_rec * int(dm.smooth_mask(2 * spec.n_harmonics + 1).sum())


def linear_system(spec: CollapsedSpec, theta: dict, mu, sign, coeffs, coeffs_se, control=None):
    """What is integrated out, per channel: ``(Φ_c, √v, d_c)`` of ``y_c ~ N(0, Φ_c V Φ_cᵀ + D_c)``.

    ``Φ_c``: the map's (and the control's) columns (:func:`channel_designs`) and,
    with the discrepancy, its latent columns
    (:func:`~bayeshopf.model.discrepancy.latent_columns`, prior sd 1), so that
    ``β`` of a draw holds ``[map, control, z]``; ``d_c``: the diagonal noise,
    ``se² + σ_c² + (σ_rel g)²`` (:func:`~bayeshopf.model.discrepancy.independent_variance`),
    or without the discrepancy ``se² + σ_c² + (σ_rel y)²`` (:func:`error_variance`).

    Returns:
        ``(Phis, sd, ds)``: two designs ``(n(2K+1), J')``, the prior sds ``(J',)``
        and two noise diagonals ``(n(2K+1),)``.
    """
    Phis = channel_designs(spec, mu, sign, theta, control)
    sd = prior_sd(spec, theta["tau_mu"], theta["tau_shape"])
    if not spec.has_discrepancy:
        var = error_variance(coeffs, coeffs_se, theta["sigma"], theta["sigma_rel"])
        return Phis, sd, [var[:, c].reshape(-1) for c in range(2)]
    g, x = discrepancy_geometry(spec, theta, mu, sign, mu, sign)
    Phis = [jnp.concatenate([Phis[c], dm.latent_columns(g[:, c], x, theta["eta"], theta["ell"])],
                            axis=1) for c in range(2)]
    sd = jnp.concatenate([sd, jnp.ones(n_latent(spec, mu.shape[0]))])
    ds = [dm.independent_variance(g[:, c], coeffs_se[:, c] ** 2 + theta["sigma"][c] ** 2,
                                  theta["sigma_rel"]).reshape(-1) for c in range(2)]
    return Phis, sd, ds


def channel_designs(spec: CollapsedSpec, mu, sign, theta: dict, control=None,
                    training: bool = True) -> list:
    """``Φ`` of each frame axis, flattened to ``(n_rec (2K+1), J)``.

    The same for both axes, except that with the control term ``w1``'s control
    columns are zero (the response is ``w2``'s; module docstring, "Control").
    ``training``: ``mu`` and ``sign`` are the recordings the model was built on
    (what the likelihood sees; see :func:`design`).
    """
    Phi = design(spec, mu, sign, theta, control=control, training=training)
    flat = Phi.reshape(-1, spec.n_basis)
    if spec.control_scale is None:
        return [flat, flat]
    return [Phi.at[..., spec.n_map:].set(0.0).reshape(-1, spec.n_basis), flat]


def coefficient_marginals(spec: CollapsedSpec, theta: dict, mu, sign, coeffs, coeffs_se,
                          control=None):
    """``log p(y_c | θ)`` of both channels, the map (and discrepancy) integrated out, ``(2,)``.

    ``theta`` holds the normal form's and the hyperparameters' values
    (:func:`normal_form_sites`, :func:`hyper_sites`).
    """
    Phis, sd, ds = linear_system(spec, theta, mu, sign, coeffs, coeffs_se, control)
    return jnp.stack([log_marginal(Phis[c], coeffs[:, c].reshape(-1), ds[c], sd)
                      for c in range(2)])


_JITS: dict[tuple, tuple] = {}


def spec_jit(spec: CollapsedSpec, fn):
    """``fn`` with ``spec`` bound, compiled once per spec.

    NumPyro runs the model eagerly to find its sites (``initialize_model``), and
    eagerly every operation of the marginal is compiled on its own, many small
    compilations with an empty compilation cache, against one compiled call
    this way.
    Inside NUTS's own jit the call is inlined.
    """
    key = (id(spec), fn.__name__)
    hit = _JITS.get(key)
    if hit is None or hit[0] is not spec:
        if len(_JITS) > 32:
            _JITS.clear()
        hit = _JITS[key] = (spec, jax.jit(lambda *a: fn(spec, *a)))
    return hit[1]


def clear_jits() -> None:
    """Forget the compiled marginals of every spec (``inference.cache.release_compiled``)."""
    _JITS.clear()


def collapsed_model(spec: CollapsedSpec, mu, sign, coeffs, coeffs_se, omega=None,
                    omega_se=None, control=None):
    """NumPyro model of the nonlinear parameters, the map integrated out.

    Args:
        spec: Structure and data constants.
        mu: μ of each recording, ``(n_rec,)``.
        sign: Branch sign (+1 stable, −1 unstable), ``(n_rec,)``.
        coeffs: Measured aligned coefficients, ``(n_rec, 2, 2K+1)``.
        coeffs_se: Their standard errors, same shape.
        omega: Measured angular frequencies (rad/s), ``(n_rec,)``; used when
            ``spec.omega_centre`` is set.
        omega_se: Their standard errors (0 for a one-segment record).
        control: The control's fundamental ``(n_rec, 2)`` (``spec.control_scale``
            set), or ``None``.
    """
    theta = {**normal_form_sites(spec), **hyper_sites(spec)}
    marginals = spec_jit(spec, coefficient_marginals)(theta, mu, sign, coeffs, coeffs_se,
                                                     control)
    for c in range(2):
        numpyro.factor(f"marginal_{c}", marginals[c])
    if spec.omega_centre is not None and omega is not None:
        sigma_omega = frequency_site(spec)
        numpyro.factor("marginal_omega", spec_jit(spec, frequency_marginal)(
            theta, sigma_omega, mu, sign, omega, omega_se))


def _map_conditional(spec: CollapsedSpec, theta: dict, mu, sign, coeffs, coeffs_se, eps,
                     control=None):
    """Draws (from standard-normal ``eps`` (2, J)) and means of ``β | y, θ``, each (J, 2).

    With the control term, ``w1``'s control rows are zero (no response there).
    """
    Phis, sd, ds = linear_system(spec, theta, mu, sign, coeffs, coeffs_se, control)
    pairs = [conditional_draw(Phis[c], coeffs[:, c].reshape(-1), ds[c], sd, eps[c])
             for c in range(2)]
    draw, mean = (jnp.stack([d for d, _ in pairs], axis=-1),
                  jnp.stack([m for _, m in pairs], axis=-1))
    if spec.control_scale is not None:
        ctl = slice(spec.n_map, spec.n_basis)
        draw, mean = draw.at[ctl, 0].set(0.0), mean.at[ctl, 0].set(0.0)
    return draw, mean


def draw_map(spec: CollapsedSpec, theta: dict, mu, sign, coeffs, coeffs_se, key, control=None):
    """One exact draw of the map's coefficients ``β`` (J, 2) given one draw ``θ``.

    With the control term, ``β``'s last two rows are the control's gain ``h`` (zero for ``w1``).
    """
    eps = jax.random.normal(key, (2, spec.n_basis + n_latent(spec, mu.shape[0])))
    return _map_conditional(spec, theta, mu, sign, coeffs, coeffs_se, eps, control)[0]


def map_mean(spec: CollapsedSpec, theta: dict, mu, sign, coeffs, coeffs_se, control=None):
    """``E[β | y, θ]`` (J, 2): the map's coefficients at their conditional mean."""
    eps = jnp.zeros((2, spec.n_basis + n_latent(spec, mu.shape[0])))
    return _map_conditional(spec, theta, mu, sign, coeffs, coeffs_se, eps, control)[1]


def orbit(spec: CollapsedSpec, theta: dict, beta, mu, sign, phi, control=None):
    """Predicted orbit ``w(φ)`` in the frame at one μ, shape ``phi.shape + (2,)``.

    At infinite width the network's part is its conditional mean's ``K``
    harmonics (:mod:`bayeshopf.model.network_kernel`).

    With the control term, ``control`` ``(u_a, u_b)`` adds the response
    ``h_r (u_a cos φ + u_b sin φ) + h_i (u_b cos φ − u_a sin φ)`` of each axis
    (``β``'s last two rows, zero for ``w1``); ``None`` is the uncontrolled orbit.
    """
    r = radius(spec, mu, sign, theta)
    scale = r / reference_radius(spec, theta.get("a2", -1.0))
    u = scale * jnp.stack([jnp.cos(phi), jnp.sin(phi)], axis=-1)
    n_mono = len(MONOMIALS) * len(MU_POWERS)
    if spec.nn_training is None:
        w = basis(u, spec.mu_tilde(mu), spec.nn_hidden) @ beta[: spec.n_map]
    else:       # the network's conditional mean at this orbit, as its Fourier series
        w = basis(u, spec.mu_tilde(mu), spec.nn_hidden) @ beta[:n_mono]
        cols = nk.columns(spec, theta, jnp.reshape(mu, (1,)), jnp.reshape(sign, (1,)),
                          N_PHI)[0]                                            # (M, n_nn)
        K = spec.n_harmonics
        k = jnp.arange(1, K + 1)
        four = jnp.concatenate([jnp.ones(phi.shape + (1,)), jnp.cos(phi[..., None] * k),
                                jnp.sin(phi[..., None] * k)], axis=-1)         # (..., M)
        w = w + four @ (cols @ beta[n_mono:spec.n_map])
    if spec.control_scale is None or control is None:
        return w
    ua, ub = control[0], control[1]
    c, s = jnp.cos(phi), jnp.sin(phi)
    cols = jnp.stack([ua * c + ub * s, ub * c - ua * s], axis=-1)
    return w + cols @ beta[spec.n_map:spec.n_basis]
