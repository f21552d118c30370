"""The map U12 (eq. g) and the predicted Fourier features, against hand-written references."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from bayeshopf.features.frame import PlanarFrame
from bayeshopf.model import hybrid, normal_form
from bayeshopf.model.coordinate_map import U12, MLPParams, mlp_shapes

RNG = np.random.default_rng(7)


def _mlp(width: int = 4) -> MLPParams:
    shapes = mlp_shapes(3, width, 2, 2)
    return MLPParams(tuple(jnp.asarray(RNG.normal(size=s)) for s in shapes),
                     tuple(jnp.asarray(RNG.normal(size=s[1])) for s in shapes))


def test_u12_is_the_second_order_linear_map_plus_shift():
    """``T_L [u, μ̃] + (μ̃ L1 + μ̃² L2) u + T_s``, with the network switched off."""
    u = RNG.normal(size=(9, 2))
    T_L = np.array([[1.3, 0.0, 0.2], [-0.4, 0.8, -0.1]])
    L1, L2 = np.array([[0.1, 0.0], [0.3, -0.2]]), np.array([[-0.05, 0.0], [0.07, 0.02]])
    T_s = np.array([0.3, -0.6])
    for mt in (-1.3, 0.0, 0.7):
        expected = u @ (T_L[:, :2] + mt * L1 + mt**2 * L2).T + mt * T_L[:, 2] + T_s
        got = U12(jnp.asarray(u), mt, jnp.asarray(T_L), jnp.asarray(L1), jnp.asarray(T_s),
                  _mlp(), 0.0, jnp.asarray(L2))
        np.testing.assert_allclose(np.asarray(got), expected, rtol=1e-13, atol=1e-14)
        # no L2 is the first-order map
        first = U12(jnp.asarray(u), mt, jnp.asarray(T_L), jnp.asarray(L1), jnp.asarray(T_s),
                    _mlp(), 0.0)
        np.testing.assert_allclose(np.asarray(first), expected - mt**2 * u @ L2.T, atol=1e-13)


def _spec(criticality: str) -> hybrid.ModelSpec:
    frame = PlanarFrame(np.zeros(2), np.eye(2))
    return hybrid.ModelSpec(criticality=criticality, frame=frame, n_h=4, mu_centre=1.0,
                            mu_span=2.0, mu_min=0.0, mu_unstable_max=None, orbit_scale=1.0,
                            nn_width=4, nn_depth=2)


def _sites(spec, mu0, a2, gain, **extra) -> dict:
    sites = {"mu0": jnp.asarray(mu0), "a2": jnp.asarray(a2),
             "T_L_diag": jnp.array([gain, gain]), "T_L_21": jnp.asarray(0.0),
             "T_L_mu": jnp.zeros(2), "T_L1": jnp.zeros(3), "T_s": jnp.zeros(2),
             "nn_scale": jnp.asarray(0.0)}
    for i, (n_in, n_out) in enumerate(spec.nn_shapes):
        sites[f"nn_W{i}"], sites[f"nn_b{i}"] = jnp.ones((n_in, n_out)), jnp.ones(n_out)
    sites.update(extra)
    return sites


@pytest.mark.parametrize(("criticality", "mu0", "a2", "extra", "sign"), [
    ("subcritical", 2.0, 1.5, {}, normal_form.STABLE),
    ("subcritical", 2.0, 1.5, {}, normal_form.UNSTABLE),
    ("supercritical", -0.5, -1.0, {"a4": jnp.asarray(-0.3)}, normal_form.STABLE),
])
def test_circle_map_gives_the_closed_form_radius(criticality, mu0, a2, extra, sign):
    """With ``T_L = g I`` and nothing else, R(θ) is the constant ``g r(μ)``."""
    spec = _spec(criticality)
    gain, mu = 1.7, 1.6
    p = hybrid.params_from_sites(_sites(spec, mu0, a2, gain, **extra), spec)
    c = np.asarray(hybrid.predicted_coeffs(p, mu, sign, spec))
    r = float(normal_form.lco_radius(mu, mu0, a2, sign, extra.get("a4", -1.0)))
    assert c[0] == pytest.approx(gain * r, rel=1e-12)
    np.testing.assert_allclose(c[1:], 0.0, atol=1e-12)


def test_fits_saved_without_the_second_order_term_still_load():
    """Sites without ``T_L2`` give ``T_L2 = None``, the same orbit as ``T_L2 = 0``."""
    spec = _spec("subcritical")
    sites = _sites(spec, 2.0, 1.5, 1.2, T_L1=jnp.array([0.1, -0.2, 0.05]))
    old = hybrid.params_from_sites(sites, spec)
    new = hybrid.params_from_sites({**sites, "T_L2": jnp.zeros(3)}, spec)
    assert old.T_L2 is None
    np.testing.assert_allclose(np.asarray(hybrid.orbit_in_frame(old, 2.5, 1.0, spec)),
                               np.asarray(hybrid.orbit_in_frame(new, 2.5, 1.0, spec)), atol=0)
    moved = hybrid.params_from_sites({**sites, "T_L2": jnp.array([0.3, 0.0, 0.0])}, spec)
    assert not np.allclose(np.asarray(hybrid.orbit_in_frame(moved, 2.5, 1.0, spec)),
                           np.asarray(hybrid.orbit_in_frame(old, 2.5, 1.0, spec)))


def test_draws_saved_without_the_later_sites_give_the_model_they_extend():
    """Draws without ``T_L2`` (supercritical: ``a4``) predict as ``T_L2 = 0``, ``a4 = −1``.

    Fits saved before those sites existed must still predict (``bayeshopf predict``).
    """
    from bayeshopf.diagnostics.predictive import amplitude_draws

    for criticality, a2 in (("subcritical", 1.5), ("supercritical", -1.0)):
        spec = _spec(criticality)
        one = _sites(spec, 0.5, a2, 1.2, T_L1=jnp.array([0.1, -0.2, 0.05]))
        old = {k: jnp.stack([v, v]) for k, v in one.items()}  # two draws, no T_L2 / a4
        new = {**old, "T_L2": jnp.zeros((2, 3))}
        if criticality == "supercritical":
            new["a4"] = -jnp.ones(2)
        assert "T_L2" not in hybrid.param_site_names(spec, old)
        mu = np.array([1.0, 1.8])
        np.testing.assert_allclose(amplitude_draws(old, spec, mu, 1.0),
                                   amplitude_draws(new, spec, mu, 1.0), rtol=1e-12)
