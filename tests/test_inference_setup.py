"""The sampler's setup: XLA's CPU flags and the Laplace start of NUTS's mass matrix."""

import os

import jax.numpy as jnp
import numpy as np

from bayeshopf.inference import cache
from bayeshopf.inference.collapsed import laplace_covariance


def test_xla_cpu_flags_are_added_once_and_a_users_choice_is_kept(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=true --xla_dump_to=/tmp/x")
    monkeypatch.setattr(cache, "_jaxlib_version", lambda: (0, 10))
    added = cache.configure_xla_cpu()
    flags = os.environ["XLA_FLAGS"].split()
    assert "--xla_cpu_multi_thread_eigen=true" in flags          # the user's, kept
    assert cache.SINGLE_THREAD_EIGEN not in flags
    assert flags.count(cache.CLASSIC_FUSION) == 1 and "--xla_dump_to=/tmp/x" in flags
    assert added == [cache.CLASSIC_FUSION]
    cache.configure_xla_cpu()                                     # idempotent
    assert os.environ["XLA_FLAGS"].split() == flags


def test_older_xla_gets_no_flag_it_does_not_know(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "")
    monkeypatch.setattr(cache, "_jaxlib_version", lambda: (0, 4))
    assert cache.configure_xla_cpu() == [cache.SINGLE_THREAD_EIGEN]
    assert "fusion_emitters" not in os.environ["XLA_FLAGS"]


def test_laplace_covariance_of_a_gaussian_potential_is_its_covariance():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((4, 4))
    cov = A @ A.T + 0.5 * np.eye(4)
    prec = np.linalg.inv(cov)
    mean = rng.standard_normal(4)

    def potential(x):                       # −log N(x | mean, cov) up to a constant
        d = x - mean
        return 0.5 * d @ jnp.asarray(prec) @ d

    got, ok = laplace_covariance(potential, jnp.asarray(mean))
    assert bool(ok)
    np.testing.assert_allclose(got, cov, rtol=1e-9, atol=1e-12)
    # a saddle (indefinite Hessian): NUTS's own start, the identity
    got, ok = laplace_covariance(lambda x: x[0] ** 2 - x[1] ** 2, jnp.zeros(2))
    assert not bool(ok)
    np.testing.assert_array_equal(got, np.eye(2))


def test_model_functions_are_reused_only_for_the_same_arguments():
    from bayeshopf.data.synthetic import demo_system
    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference import collapsed as ci

    rs, _ = demo_system(seed=11, fast=True)
    f = extract_harmonics(rs)
    spec = ci.build_spec(f, "subcritical")
    kw = ci.model_arguments(spec, f)
    info = ci.model_functions(kw)[0]
    assert ci.model_functions(kw)[0] is info
    # equal values in new arrays, or a changed μ: a new model run, not the cached one
    moved = {**kw, "mu": kw["mu"] + 0.1}
    info_moved = ci.model_functions(moved)[0]
    assert info_moved is not info
    x = info_moved.param_info.z
    assert float(info_moved.potential_fn(x)) != float(info.potential_fn(x))
    assert ci.model_functions(ci.model_arguments(spec, f))[0] is not info_moved
    ci.clear_model_functions()
    assert ci.model_functions(moved)[0] is not info_moved
