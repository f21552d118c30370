"""The sampler's setup: XLA's CPU flags, the stored compiled programs, the Laplace start of
NUTS's mass matrix and the imports done beside it."""

import os
import subprocess
import sys

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


def test_blas_gets_one_thread_unless_the_user_chose(monkeypatch):
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    cache.configure_xla_cpu()
    assert os.environ["OPENBLAS_NUM_THREADS"] == "1"
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "4")
    cache.configure_xla_cpu()
    assert os.environ["OPENBLAS_NUM_THREADS"] == "4"


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


def _stored_counting(monkeypatch, folder):
    """``compiled_call`` with the cache in ``folder``, and a counter of ``make`` calls."""
    monkeypatch.setattr(cache, "_ENABLED", [str(folder)] if folder else [])
    made = []

    def call(scale, x):
        def make():
            made.append(scale)
            return lambda x: jnp.sin(scale * x).sum() + jnp.linalg.cholesky(
                jnp.eye(2) * scale)[0, 0]
        return float(cache.compiled_call("probe", make, (x,), key=(scale, np.ones(2))))

    return call, made


def test_compiled_call_traces_once_per_key_and_gives_the_jit_result(monkeypatch, tmp_path):
    call, made = _stored_counting(monkeypatch, tmp_path)
    x = jnp.linspace(0.0, 1.0, 5)
    expected = float(jnp.sin(2.0 * x).sum() + jnp.sqrt(2.0))
    assert call(2.0, x) == expected
    assert call(2.0, x) == expected        # read back from the stored file
    assert made == [2.0]
    assert len(list(tmp_path.glob(f"{cache.STORED_PREFIX}probe-*.bin"))) == 1
    assert call(3.0, x) == float(jnp.sin(3.0 * x).sum() + jnp.sqrt(3.0))   # a new key
    assert made == [2.0, 3.0]
    # the stored program takes any argument of the same shape (NUTS: other chain keys)
    assert call(2.0, x + 1.0) == float(jnp.sin(2.0 * (x + 1.0)).sum() + jnp.sqrt(2.0))
    assert made == [2.0, 3.0]
    assert call(2.0, jnp.arange(4.0)) == float(jnp.sin(2.0 * jnp.arange(4.0)).sum()
                                               + jnp.sqrt(2.0))
    assert made == [2.0, 3.0, 2.0]         # a new shape is traced again


def test_compiled_call_replaces_a_damaged_file_and_runs_without_a_cache(monkeypatch, tmp_path):
    call, made = _stored_counting(monkeypatch, tmp_path)
    x = jnp.arange(3.0)
    first = call(2.0, x)
    (f,) = tmp_path.glob(f"{cache.STORED_PREFIX}probe-*.bin")
    f.write_bytes(b"not a serialized program")
    assert call(2.0, x) == first and made == [2.0, 2.0]
    assert f.read_bytes() != b"not a serialized program"
    call, made = _stored_counting(monkeypatch, None)
    assert call(2.0, x) == first and call(2.0, x) == first and made == [2.0, 2.0]


_TWO_PROCESSES = """
import sys
from bayeshopf._x64 import ensure_x64
ensure_x64()
import jax.numpy as jnp
from bayeshopf.inference import cache
cache.enable_compilation_cache(sys.argv[1])
made = []
def make():
    made.append(1)
    return lambda x: jnp.linalg.cholesky(jnp.eye(2) * x.sum())[0, 0] + jnp.linalg.eigh(
        jnp.diag(x[:2]))[0][0]
print(float(cache.compiled_call("probe2", make, (jnp.arange(1.0, 4.0),), key=0)), len(made))
"""


def test_a_program_stored_by_one_process_runs_in_the_next(tmp_path):
    """Loaded in a fresh process, LAPACK kernels included (Cholesky, eigh), without tracing."""
    run = [sys.executable, "-c", _TWO_PROCESSES, str(tmp_path)]
    first = subprocess.run(run, capture_output=True, text=True, check=True).stdout.split()
    second = subprocess.run(run, capture_output=True, text=True, check=True).stdout.split()
    assert first[1] == "1" and second[1] == "0"      # traced once, then loaded
    assert float(first[0]) == float(second[0]) == np.sqrt(6.0) + 1.0


def test_arviz_and_matplotlib_are_not_imported_with_the_inference_core():
    """They are imported beside NUTS (bayeshopf._preload), not before the fit starts."""
    code = ("import sys, bayeshopf.posterior, bayeshopf.report, bayeshopf.cli.main; "
            "print(sorted(m for m in ('arviz', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"
