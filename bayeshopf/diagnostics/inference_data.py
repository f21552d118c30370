"""A fit as ArviZ ``InferenceData``: draws, pointwise log-likelihood, replicated and observed."""

from __future__ import annotations

import numpy as np

from bayeshopf._version import __version__
from bayeshopf.diagnostics import arviz_io
from bayeshopf.features.harmonics import coefficient_names
from bayeshopf.model import collapsed as cm
from bayeshopf.model import discrepancy as dm
from bayeshopf.predictive import predictive_draws


def to_inference_data(post):
    """A fit as ArviZ :class:`~arviz.InferenceData` (ArviZ 0.x; see below).

    ``post``: a :class:`~bayeshopf.hybrid_posterior.HybridPosterior`. Groups,
    each with chains and draws as NUTS gave them:

    * ``posterior``: every site (``mu0``, ``a2``, ``mu_fold``, ``sigma`` over
      ``frame_axis``, …), the map's coefficients ``beta`` over
      ``(basis, frame_axis)`` and, with the frequency model, ``gamma`` over
      ``frequency_basis``;
    * ``log_likelihood``: ``y``, each recording's ``log p(y_i | y_{−i}, θ)``
      over ``recording``
      (:attr:`~bayeshopf.hybrid_posterior.HybridPosterior.log_likelihood`;
      ``az.loo`` reads it);
    * ``posterior_predictive``: a replicated recording at each training
      recording's μ and branch, per draw: ``amplitude`` (peak-to-peak of z1),
      ``coeffs`` (its harmonic coefficients in the frame) and, with the
      frequency model, ``frequency`` (Hz)
      (:func:`~bayeshopf.predictive.predictive_draws`);
    * ``observed_data``: the measured ``amplitude``, ``coeffs`` and ``frequency``
      with the same coordinates;
    * ``constant_data``: ``mu``, ``unstable`` (1 for the unstable branch),
      ``coeffs_se``, ``amplitude_sd``, ``n_segments``, ``segment_rms``,
      ``frequency_se`` (Hz) of each recording and, where the recordings name a
      control channel, ``control`` (its fundamental ``u_a1``, ``u_b1`` on the
      features' time origin, over ``control_part``).

    Coordinates: ``recording`` (names), ``frame_axis`` (``w1``, ``w2``, with
    the planar ``channel`` each follows: z = centre + L w with L lower
    triangular), ``coefficient`` (``a0, a1…aK, b1…bK``, with its
    ``harmonic``), ``basis`` and ``frequency_basis``. The attributes hold the
    criticality, the seed, μ's name and unit, the channels' units and the
    package version. There is no ``sample_stats`` group: the sampler's
    per-draw statistics are not kept (the divergence count is in
    :attr:`~bayeshopf.hybrid_posterior.HybridPosterior.diagnostics`).

    bayeshopf needs Python 3.11 and ArviZ 0.x (``arviz<0.24``); ArviZ 1.x
    needs Python ≥ 3.12 and replaces ``InferenceData`` with xarray's
    ``DataTree``. The file :func:`~bayeshopf.fit_folder.save_hybrid` writes is
    this object (``posterior.nc``).
    """
    f, run = post.features, post.run
    chains = {k: np.asarray(v) for k, v in run.chains.items() if not k.startswith("marginal")}
    shape = next(iter(chains.values())).shape[:2]
    chains["beta"] = np.asarray(run.betas).reshape(shape + run.betas.shape[1:])
    if run.gammas is not None:
        chains["gamma"] = np.asarray(run.gammas).reshape(shape + run.gammas.shape[1:])
    pred = predictive_draws(post.spec, post.theta, run.betas, run.gammas, f, post.seed)
    pred = {k: v.reshape(shape + v.shape[1:]) for k, v in pred.items()}
    observed = {"amplitude": f.amplitude, "coeffs": f.coeffs}
    if post.has_frequency:
        observed["frequency"] = f.frequency_hz
    K = post.spec.n_harmonics
    rec, coef = ["recording"], ["recording", "frame_axis", "coefficient"]
    dims = {"sigma": ["frame_axis"], "beta": ["basis", "frame_axis"],
            "gamma": ["frequency_basis"], "y": rec, "amplitude": rec, "frequency": rec,
            "coeffs": coef, "coeffs_se": coef, "mu": rec, "unstable": rec,
            "amplitude_sd": rec, "n_segments": rec, "segment_rms": rec, "frequency_se": rec}
    coords = {"recording": list(f.names), "frame_axis": ["w1", "w2"],
              "coefficient": coefficient_names(K),
              "basis": basis_names(post.spec, run.betas.shape[1]),
              "frequency_basis": [f"g{j}" for j in range(
                  0 if run.gammas is None else run.gammas.shape[1])]}
    extra = {"channel": ("frame_axis", list(post.spec.frame.names)),
             "harmonic": ("coefficient", [0, *range(1, K + 1), *range(1, K + 1)])}
    constant = {"mu": f.mu, "unstable": f.unstable.astype(int), "coeffs_se": f.coeffs_se,
                "amplitude_sd": f.amplitude_sd, "n_segments": f.n_segments,
                "segment_rms": f.segment_rms, "frequency_se": f.omega_se / (2 * np.pi)}
    if f.control is not None:
        constant["control"] = np.asarray(f.control, float)
        dims["control"] = ["recording", "control_part"]
        coords["control_part"] = ["u_a1", "u_b1"]
    attrs = {"criticality": post.criticality, "seed": post.seed, "mu_label": post.mu_label,
             "mu_units": post.mu_units, "amplitude_units": post.amplitude_units,
             "planar_channels": list(post.spec.frame.names),
             "channel_units": list(post.spec.frame.units),
             "inference": run.method, "bayeshopf_version": __version__}
    return arviz_io.chains_to_inference_data(
        chains, log_likelihood={"y": post.log_likelihood}, posterior_predictive=pred,
        observed=observed, constant=constant, coords=coords, dims=dims,
        extra_coords=extra, attrs=attrs)


def basis_names(spec: cm.CollapsedSpec, n: int) -> list[str]:
    """The names of the ``n`` rows of ``β``, or ``psi0…`` where the count does not match.

    The map's basis functions (``"u1^2 m"``, ``"nn3"``, …), the control's, then
    the discrepancy's latents (``"discrepancy3_a1"``: recording 3's fundamental
    cosine).
    """
    names = cm.basis_names(spec)
    if spec.has_discrepancy and n > len(names):
        h = dm.harmonic_index(spec.n_harmonics)
        parts = ["a1" if j <= spec.n_harmonics else "b1"
                 for j in np.flatnonzero(dm.smooth_mask(h.size))]
        names = names + [f"discrepancy{i}_{p}" for i in range((n - len(names)) // len(parts))
                         for p in parts]
    return names if len(names) == n and len(set(names)) == n else [f"psi{j}" for j in range(n)]
