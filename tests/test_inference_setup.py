"""The sampler's setup: XLA's CPU flags, the stored compiled programs, the Laplace start of
NUTS's mass matrix and the imports done beside it."""

import json
import os
import subprocess
import sys
from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

from bayeshopf import _xla
from bayeshopf.errors import FitError
from bayeshopf.inference import cache
from bayeshopf.inference.collapsed import laplace_covariance


def test_xla_cpu_flags_are_added_once_and_a_users_choice_is_kept(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=true --xla_dump_to=/tmp/x")
    monkeypatch.setattr(_xla, "_jaxlib_version", lambda: (0, 10))
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
    monkeypatch.setattr(_xla, "_jaxlib_version", lambda: (0, 4))
    assert cache.configure_xla_cpu() == [cache.SINGLE_THREAD_EIGEN]
    assert "fusion_emitters" not in os.environ["XLA_FLAGS"]


def test_host_devices_are_asked_for_once_unless_the_user_chose(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "")
    monkeypatch.setattr(_xla, "_jaxlib_version", lambda: (0, 10))
    assert cache.configure_xla_cpu() == [cache.SINGLE_THREAD_EIGEN, cache.CLASSIC_FUSION]
    added = cache.configure_xla_cpu(host_devices=2)
    assert added[-1] == f"{cache.HOST_DEVICES}=2"
    cache.configure_xla_cpu(host_devices=2)
    assert os.environ["XLA_FLAGS"].split().count(f"{cache.HOST_DEVICES}=2") == 1
    monkeypatch.setenv("XLA_FLAGS", f"{cache.HOST_DEVICES}=8")
    cache.configure_xla_cpu(host_devices=2)                        # the user's, kept
    assert f"{cache.HOST_DEVICES}=8" in os.environ["XLA_FLAGS"].split()
    assert f"{cache.HOST_DEVICES}=2" not in os.environ["XLA_FLAGS"]


@pytest.mark.parametrize("cores, wanted", [(1, None), (2, 2), (8, 4)])
def test_the_cli_asks_for_a_device_per_core_up_to_the_chains(monkeypatch, tmp_path, cores,
                                                            wanted):
    from bayeshopf import _preload
    from bayeshopf.cli.main import main

    monkeypatch.setenv("XLA_FLAGS", "")
    monkeypatch.setattr(_preload, "available_cores", lambda: cores)
    # any command sets the flags first; this one then stops at its first check
    assert main(["predict", str(tmp_path), "--mu", "15", "--ci", "2"]) != 0
    found = [f for f in os.environ["XLA_FLAGS"].split() if f.startswith(cache.HOST_DEVICES)]
    assert found == ([] if wanted is None else [f"{cache.HOST_DEVICES}={wanted}"])


_BLAS_ORDER = """
import importlib.abc, os, sys
seen = []

class Watch(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "scipy.linalg" and not seen:   # SciPy's OpenBLAS loads with it
            seen.append(os.environ.get("OPENBLAS_NUM_THREADS"))
        return None

sys.meta_path.insert(0, Watch())
from bayeshopf.cli.main import main
main(["predict", sys.argv[1], "--mu", "15", "--ci", "2"])   # stops at its first check
print(seen)
"""


def test_the_cli_limits_blas_threads_before_scipy_loads_its_openblas(tmp_path):
    """SciPy's OpenBLAS reads OPENBLAS_NUM_THREADS once, when it loads; set after
    that, it has no effect, and on 2 cores the BLAS workers' busy-waiting made a
    warm rig fit's NUTS stage 18–21 s instead of 6–9 s with two devices."""
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    out = subprocess.run([sys.executable, "-c", _BLAS_ORDER, str(tmp_path)], env=env,
                         capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "['1']", out


_BLAS_LOADED = """
import json, os
# a test worker may be pinned to one core, and OpenBLAS starts no more threads than cores
os.sched_setaffinity(0, range(os.cpu_count()))
import numpy, scipy.linalg      # NumPy's and SciPy's OpenBLAS load here, before the call
from threadpoolctl import threadpool_info

def threads():
    return sorted(i["num_threads"] for i in threadpool_info() if i["internal_api"] == "openblas")

before = threads()
from bayeshopf.inference.cache import configure_xla_cpu
configure_xla_cpu()
print(json.dumps([before, threads()]))
"""


@pytest.mark.skipif((os.cpu_count() or 1) < 2 or not hasattr(os, "sched_setaffinity"),
                    reason="OpenBLAS runs one thread on one core; Linux's affinity is used")
@pytest.mark.parametrize("user", [None, "4"])
def test_blas_gets_one_thread_unless_the_user_chose(user):
    """Both OpenBLAS libraries, NumPy's and SciPy's, loaded before the call with
    several threads (OpenBLAS reads OMP_NUM_THREADS when it has no limit of its
    own, and caps it at the cores), get one, unless the user set OPENBLAS_NUM_THREADS."""
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    env["OMP_NUM_THREADS"] = "4"
    if user is not None:
        env["OPENBLAS_NUM_THREADS"] = user
    out = subprocess.run([sys.executable, "-c", _BLAS_LOADED], env=env, capture_output=True,
                         text=True, check=True).stdout.strip().splitlines()[-1]
    before, after = json.loads(out)
    assert len(before) == 2 and min(before) > 1, out
    assert after == ([1, 1] if user is None else before), out


def test_laplace_covariance_of_a_gaussian_potential_is_its_covariance():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((4, 4))
    cov = A @ A.T + 0.5 * np.eye(4)
    prec = np.linalg.inv(cov)
    mean = rng.standard_normal(4)

    def potential(x):                       # −log N(x | mean, cov) up to a constant
        d = x - mean
        return 0.5 * d @ jnp.asarray(prec) @ d

    got, ok = laplace_covariance(jax.jit(jax.value_and_grad(potential)), mean)
    assert bool(ok)
    np.testing.assert_allclose(got, cov, rtol=1e-9, atol=1e-12)
    # curved: the finite differences against JAX's own Hessian (the gradient is exact)
    def curved(x):
        return jnp.sum(jnp.exp(0.3 * x) - 0.3 * x) + 0.1 * (x[0] * x[1]) ** 2 + x[2] ** 4

    x = jnp.array([0.4, -1.2, 0.7])
    got, ok = laplace_covariance(jax.jit(jax.value_and_grad(curved)), x)
    assert bool(ok)
    np.testing.assert_allclose(got, np.linalg.inv(jax.hessian(curved)(x)), rtol=1e-7, atol=1e-6)
    # a saddle (indefinite Hessian): NUTS's own start, the identity
    saddle = jax.jit(jax.value_and_grad(lambda x: x[0] ** 2 - x[1] ** 2))
    got, ok = laplace_covariance(saddle, jnp.zeros(2))
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
    moved = replace(kw, mu=kw.mu + 0.1)
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
    monkeypatch.setattr(cache, "_COMPILED", {})
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
    assert call(2.0, x) == expected        # kept from the first call (stored on disk too)
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
    assert call(2.0, x) == first and made == [2.0]      # this process keeps what it loaded
    cache._COMPILED.clear()                             # as a new process would start
    assert call(2.0, x) == first and made == [2.0, 2.0]
    assert f.read_bytes() != b"not a serialized program"
    call, made = _stored_counting(monkeypatch, None)
    # without a cache on disk: traced once per key in a process, then kept until released
    assert call(2.0, x) == first and call(2.0, x) == first and made == [2.0]
    cache.release_compiled()
    assert call(2.0, x) == first and made == [2.0, 2.0]


def test_compile_ahead_runs_the_program_it_compiled_and_other_shapes_compile_their_own(
        monkeypatch, tmp_path):
    """A program compiled in the background (``compile_ahead``) is what
    ``compiled_function`` then runs, for arguments of the shapes it was compiled for;
    others go through ``jax.jit`` as before. Without the persistent cache it does nothing."""
    monkeypatch.setattr(cache, "_ENABLED", [str(tmp_path)])
    monkeypatch.setattr(cache, "_COMPILED", {})
    made = []

    def make():
        made.append(1)
        return lambda x: jnp.linalg.cholesky(jnp.eye(2) * x.sum())[0, 0] + jnp.sin(x).sum()

    spec = (jax.ShapeDtypeStruct((5,), jnp.float64),)
    assert cache.compile_ahead("ahead-probe", make, spec, key=("k",)) is not None
    assert made == [1]                 # traced and exported here, compiled in the background
    x = jnp.linspace(0.5, 1.5, 5)
    fn = cache.compiled_function("ahead-probe", make, (x,), key=("k",))
    assert isinstance(fn, cache._Ahead)
    assert float(fn(x)) == float(jax.jit(make())(x))
    assert float(fn(np.asarray(x))) == float(jax.jit(make())(x)) and fn.calls == [2, 0]
    y = jnp.arange(1.0, 4.0)             # another shape: another program, compiled as before
    other = cache.compiled_function("ahead-probe", make, (y,), key=("k",))
    assert not isinstance(other, cache._Ahead)
    assert float(other(y)) == pytest.approx(np.sqrt(6.0) + float(jnp.sin(y).sum()), rel=1e-14)
    assert fn.calls == [2, 0] and made == [1, 1, 1, 1]     # the checks' jits, then the export
    monkeypatch.setattr(cache, "_ENABLED", [])
    monkeypatch.setattr(cache, "_COMPILED", {})
    assert cache.compile_ahead("ahead-probe", make, spec, key=("k",)) is None
    assert cache._COMPILED == {}


def test_stored_shapes_are_computed_once_and_read_back(monkeypatch, tmp_path):
    monkeypatch.setattr(cache, "_ENABLED", [str(tmp_path)])
    computed = []
    f64, u32 = jnp.float64, jnp.uint32

    def compute():
        computed.append(1)
        return {"x": jax.ShapeDtypeStruct((9,), f64),
                "states": [jax.ShapeDtypeStruct((4, 9, 9), f64),
                           jax.ShapeDtypeStruct((4, 2), u32)],
                "theta": {"mu0": jax.ShapeDtypeStruct((2000,), f64),
                          "sigma": jax.ShapeDtypeStruct((2000, 2), f64)}}

    first = cache.stored_shapes("shapes-probe", ("k", 1), compute)
    again = cache.stored_shapes("shapes-probe", ("k", 1), compute)
    assert computed == [1] and again == first and again["states"][1].dtype == np.uint32
    assert cache.stored_shapes("shapes-probe", ("k", 2), compute) == first   # another key
    assert computed == [1, 1]
    for f in tmp_path.glob(f"{cache.STORED_PREFIX}shapes-probe-*.json"):
        f.write_text("{not json")
    assert cache.stored_shapes("shapes-probe", ("k", 1), compute) == first
    assert computed == [1, 1, 1]


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
    code = ("import sys, bayeshopf.posterior, bayeshopf.fit_folder, bayeshopf.cli.main; "
            "print(sorted(m for m in ('arviz', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"


def test_the_plotting_code_imports_without_jax():
    """The CLI's figure process imports only the plotting code; JAX's import (1.1 s)
    would slow the fit running beside it (``ensure_x64`` imports JAX when called).
    Nor does a band's half-width import SciPy's statistics (about 1 s in the figure
    process, for one quantile of the normal)."""
    code = ("import sys, bayeshopf.plotting; print('jax' in sys.modules)\n"
            "from bayeshopf.plotting._style import z_value\n"
            "z = [z_value(c) for c in (0.5, 0.9, 0.975)]; print('scipy.stats' in sys.modules)\n"
            "print(repr(z))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    jax_loaded, stats_loaded, values = out.stdout.strip().splitlines()
    assert (jax_loaded, stats_loaded) == ("False", "False")
    from scipy.stats import norm

    assert eval(values) == [norm.ppf(0.5 + c / 2) for c in (0.5, 0.9, 0.975)]  # noqa: S307


def _banana(monkeypatch):
    """A two-site posterior for NUTS's stages, in place of the collapsed model's functions.

    "mu0" ~ N(0, 1) and "a2" | "mu0" ~ N(mu0² / 2, 0.5²): curved, so that NUTS's trees
    and its adaptation have work to do, and cheap to compile.
    """
    from types import SimpleNamespace

    from bayeshopf.inference import programs

    unravel = ravel_pytree({"mu0": 0.0, "a2": 0.0})[1]

    def potential(x):
        p = unravel(x)
        return 0.5 * p["mu0"] ** 2 + 0.5 * ((p["a2"] - 0.5 * p["mu0"] ** 2) / 0.5) ** 2

    info = SimpleNamespace(postprocess_fn=lambda p: p)
    monkeypatch.setattr(programs, "model_functions", lambda kw: (info, unravel, potential))
    monkeypatch.setattr(programs, "model_key", lambda kw: ("banana",))
    monkeypatch.setattr(cache, "_COMPILED", {})
    start = SimpleNamespace(unconstrained={"mu0": 0.3, "a2": 0.1})
    return potential, unravel, start


def test_nuts_in_stages_is_numpyros_mcmc_and_is_extended_until_the_checks_pass(monkeypatch):
    """Chains advanced chunk by chunk are NumPyro's MCMC from the same start and keys;
    extended while R̂ or ESS fails, up to the cap, as one longer run."""
    from numpyro.infer import MCMC, NUTS

    from bayeshopf.inference import collapsed as ci
    from bayeshopf.inference import nuts

    potential, unravel, start = _banana(monkeypatch)
    settings = replace(ci.CollapsedSettings(), num_chains=2, num_warmup=150, num_samples=100,
                       extend_samples=50, max_samples=200)
    assert ci.nuts_chunk(settings) == 50          # the warm-up spans three calls
    key = jax.random.PRNGKey(3)
    # 2 × 100 draws cannot reach a bulk ESS of 400: extended by 50 until the cap of 200
    long, div_long, sampler = ci._nuts({}, start, settings, key, progress=False)
    assert sampler["draws_per_chain"] == 200 and long["mu0"].shape == (2, 200)
    assert sampler["mass_matrix_start"] == "laplace"
    # where every check passes, the first 100 draws are the answer: the first 100 of
    # the extended run, from the same program (only the run's length depends on them)
    monkeypatch.setattr(nuts, "ESS_MIN", 0)
    monkeypatch.setattr(nuts, "RHAT_MAX", np.inf)
    short, div, sampler = ci._nuts({}, start, settings, key, progress=False)
    assert sampler["draws_per_chain"] == 100
    np.testing.assert_array_equal(short["a2"], long["a2"][:, :100])

    x0 = ravel_pytree(start.unconstrained)[0]
    cov, _ = ci.laplace_covariance(jax.jit(jax.value_and_grad(potential)), x0)
    mcmc = MCMC(NUTS(potential_fn=potential, dense_mass=True, inverse_mass_matrix=cov),
                num_warmup=150, num_samples=100, num_chains=2, chain_method="sequential",
                progress_bar=False)
    mcmc.run(key, init_params=jnp.stack([x0, x0]), extra_fields=("diverging",))
    ref = jax.vmap(jax.vmap(unravel))(mcmc.get_samples(group_by_chain=True))
    # the same chains to rounding; a warm-up restarted at a call's boundary would give
    # another step size and mass matrix, and other draws from the first on
    for name in ("mu0", "a2"):
        np.testing.assert_allclose(short[name], ref[name], rtol=0, atol=1e-8)
    assert div == int(mcmc.get_extra_fields()["diverging"].sum())
    # a cap below the first draws is refused, in one line naming the settings
    with pytest.raises(FitError, match="num_samples=100, max_samples=50"):
        ci._nuts({}, start, replace(settings, max_samples=50), key, progress=False)


#: A process with ``{devices}`` CPU devices and the banana posterior (``_banana``) in place
#: of the model; four chains of 100 + 100 iterations from key 5.
_BANANA_PROCESS = """
import os, sys
os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count={devices}"
import numpy as np, pytest
from types import SimpleNamespace
from dataclasses import replace
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
sys.path.insert(0, sys.argv[1])
import test_inference_setup as t
from bayeshopf import _preload
from bayeshopf.inference import cache, collapsed as ci, devices, programs
mp = pytest.MonkeyPatch()
_, _, start = t._banana(mp)
settings = replace(ci.CollapsedSettings(), inference="nuts", num_chains=4, num_warmup=100,
                   num_samples=100,
                   extend_samples=100, max_samples=100)
key = jax.random.PRNGKey(5)
"""

_SPREAD = _BANANA_PROCESS.format(devices=3) + """
print(jax.local_device_count(), [ci.spread_devices(n) for n in (1, 2, 3, 4, 5, 6)])
spread, div, _ = ci._nuts({}, start, settings, key, progress=False)
mp.setattr(devices, "spread_devices", lambda n: 1)
one, div1, _ = ci._nuts({}, start, settings, key, progress=False)
print(max(float(np.abs(spread[k] - one[k]).max()) for k in one), div == div1,
      float(np.abs(spread["mu0"][0] - spread["mu0"][3]).max()))
"""


def test_chains_spread_over_devices_are_the_chains_of_one_device():
    """With several CPU devices NUTS splits its chains between them (two devices of
    two chains where there are three), and the draws are those of one device."""
    out = subprocess.run([sys.executable, "-c", _SPREAD, os.path.dirname(__file__)],
                         capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[0] == "3 [1, 2, 3, 2, 1, 3]"
    diff, same_divergences, between_chains = out[1].split()
    assert float(diff) == 0.0 and same_divergences == "True"
    assert float(between_chains) > 0.1       # chains of their own keys, not copies


_AHEAD = _BANANA_PROCESS.format(devices=2) + """
info, _, potential = programs.model_functions({})
info.param_info = SimpleNamespace(z={"mu0": jnp.asarray(0.0), "a2": jnp.asarray(0.0)})
mp.setattr(ci, "_map_draw", lambda kw: lambda a: (a[0]["mu0"] * 2.0, a[1].sum()))
mp.setattr(ci, "_pointwise", lambda kw: lambda t: t["a2"] - t["mu0"])
cache.enable_compilation_cache(sys.argv[2])
plain, _, _ = ci._nuts({}, start, settings, key, progress=False)
mp.setattr(cache, "_COMPILED", {})
mp.setattr(_preload, "available_cores", lambda: 2)
ci.compile_programs({}, settings)
ahead = {n: f for (n, _), f in cache._COMPILED.items()}
print(sorted(ahead), all(isinstance(f, cache._Ahead) for f in ahead.values()))
draws, _, _ = ci._nuts({}, start, settings, key, progress=False)
print(max(float(np.abs(draws[k] - plain[k]).max()) for k in plain),
      ahead["nuts-advance"].calls, ahead["value-and-grad"].calls[1],
      len(ahead["nuts-advance"].signature[1][0][2].device_set),
      all(f.future.exception() is None for f in ahead.values()))
"""


def test_programs_compiled_ahead_are_those_nuts_runs_and_give_its_draws(tmp_path):
    """``compile_programs`` traces the potential, NUTS's advance (its states split over
    two devices), the map draws and the log-likelihood before the MAP and compiles them
    in the background; NUTS then runs those programs, with the same draws as without."""
    out = subprocess.run([sys.executable, "-c", _AHEAD, os.path.dirname(__file__),
                          str(tmp_path)], capture_output=True, text=True, check=True
                         ).stdout.split("\n")
    assert out[0] == "['loglik', 'maps', 'nuts-advance', 'value-and-grad'] True"
    diff, *rest = out[1].split(" ", 1)
    assert float(diff) == 0.0
    # 2 chunks of 100 iterations, both from the program compiled ahead; the Laplace
    # covariance's gradients too; the advance compiled for states on two devices
    assert rest[0] == "[2, 0] 0 2 True"


_MAPPED = """
import os
os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=2"
import numpy as np, jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
from bayeshopf.inference import collapsed as ci
items = {"a": jnp.arange(6.0), "b": jnp.arange(12.0).reshape(6, 2)}
one = lambda it: (jnp.linalg.cholesky(jnp.eye(2) * (1 + it["a"]))[0, 0] + it["b"].sum(), it["a"])
two = ci.mapped_call("mapped-probe", one, items, key=("probe",))
print(jax.local_device_count(), len(two[0].sharding.device_set))
print(np.abs(np.asarray(two[0]) - np.sqrt(1 + np.arange(6.0))
             - np.arange(12.0).reshape(6, 2).sum(1)).max(), np.asarray(two[1]).tolist())
"""


def test_mapped_call_splits_the_items_over_devices_and_keeps_their_order():
    """``mapped_call`` (the map draws and the log-likelihood's draws): with two CPU
    devices each maps half of the items, and the results come back in order."""
    out = subprocess.run([sys.executable, "-c", _MAPPED], capture_output=True, text=True,
                         check=True).stdout.split("\n")
    assert out[0] == "2 2"
    err, order = out[1].split(" ", 1)
    assert float(err) < 1e-12 and order == "[0.0, 1.0, 2.0, 3.0, 4.0, 5.0]"


def test_the_imports_start_beside_the_first_nuts_chunk_not_beside_the_laplace_loop(
        monkeypatch):
    """ArviZ's and the figures' imports hold the interpreter between a Python loop's
    small compiled calls (the Laplace covariance: 1.3 s instead of 0.15 s on the rig),
    so ``_preload.start`` runs once NUTS's first chunk is dispatched, and once."""
    from bayeshopf import _preload
    from bayeshopf.inference import collapsed as ci
    from bayeshopf.inference import nuts, optimum

    _, _, start = _banana(monkeypatch)
    events = []
    laplace = ci.laplace_covariance
    monkeypatch.setattr(optimum, "laplace_covariance",
                        lambda *a: (events.append("laplace"), laplace(*a))[1])
    monkeypatch.setattr(_preload, "start", lambda: events.append("imports"))
    compiled_function = nuts.compiled_function

    def advancing(name, *a, **k):
        fn = compiled_function(name, *a, **k)
        if name != "nuts-advance":         # the gradient the Laplace covariance differences
            return fn
        return lambda *x: (events.append("chunk"), fn(*x))[1]

    monkeypatch.setattr(nuts, "compiled_function", advancing)
    settings = replace(ci.CollapsedSettings(), num_chains=2, num_warmup=50, num_samples=50,
                       extend_samples=50, max_samples=50)
    ci._nuts({}, start, settings, jax.random.PRNGKey(0), progress=False)
    assert events == ["laplace", "chunk", "imports", "chunk"]


def test_the_map_is_finished_by_a_root_find_where_lbfgs_stops_at_the_values_rounding():
    """The 3-DOF recordings are precise and the potential ill-conditioned: L-BFGS-B's line
    search stops with a gradient norm of 4e-4 (seed 0, 8 s records), and the root find on
    the gradient ends below the tolerance, at a minimum (a positive definite Hessian), not
    a saddle."""
    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference import collapsed as ci
    from bayeshopf.simulators.truth import flutter_experiment

    rs, _ = flutter_experiment(seed=0, fast=True)
    f = extract_harmonics(rs)
    kw = ci.model_arguments(ci.build_spec(f, "subcritical"), f)
    mp = ci.fit_map(kw)
    assert mp.polish_evaluations > 0
    assert mp.converged and mp.grad_norm < ci.MAP_GTOL
    x = ravel_pytree({k: jnp.asarray(v) for k, v in mp.unconstrained.items()})[0]
    value_and_grad = ci.potential_program(kw, x.shape[0])
    assert float(value_and_grad(x)[0]) == pytest.approx(-mp.log_joint, abs=1e-9)
    _, ok = ci.laplace_covariance(value_and_grad, x)
    assert ok



def test_svi_particles_one_after_another_give_the_vmapped_elbo():
    """The SVI's ELBO maps its particles (stop 45: vmapped, two batches of triangular solves
    at once hung XLA's CPU thread pool); the steps are those of NumPyro's vmapped particles."""
    import jax
    import numpy as np
    import numpyro
    import numpyro.distributions as dist
    import optax
    from numpyro.infer import SVI, Trace_ELBO
    from numpyro.infer.autoguide import AutoMultivariateNormal

    from bayeshopf.inference.collapsed import SVI_PARTICLES

    def model(y):
        m = numpyro.sample("m", dist.Normal(0.0, 10.0))
        s = numpyro.sample("s", dist.HalfNormal(2.0))
        numpyro.sample("y", dist.Normal(m, s), obs=y)

    y = np.random.default_rng(0).normal(1.5, 0.7, 40)
    runs = {}
    for vectorize in (True, False):
        svi = SVI(model, AutoMultivariateNormal(model), optax.adam(5e-3),
                  Trace_ELBO(num_particles=SVI_PARTICLES, vectorize_particles=vectorize))
        runs[vectorize] = svi.run(jax.random.PRNGKey(3), 200, y, progress_bar=False,
                                  stable_update=True)
    ref, got = runs[True], runs[False]
    np.testing.assert_allclose(np.asarray(got.losses), np.asarray(ref.losses), rtol=1e-9)
    assert float(ref.losses[-20:].mean()) < float(ref.losses[:20].mean()) - 1.0   # it learnt
    for k, v in ref.params.items():
        np.testing.assert_allclose(np.asarray(got.params[k]), np.asarray(v), rtol=1e-9,
                                   atol=1e-12)


def test_the_hidden_layer_seed_and_the_discrepancy_reach_the_spec():
    """``nn_seed`` draws another fixed hidden layer (N(0, 1) weights from NumPy's generator
    with that seed); ``discrepancy`` adds the coefficient scales and the floor, and a spec
    with them round-trips through its dict (a saved fit)."""
    from bayeshopf.data.synthetic import demo_system
    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference import collapsed as ci
    from bayeshopf.model import collapsed as cm

    rs, _ = demo_system(seed=11, fast=True)
    f = extract_harmonics(rs)
    base = ci.build_spec(f, "subcritical", nn_width=5)
    other = ci.build_spec(f, "subcritical", nn_width=5, nn_seed=3)
    want = np.random.default_rng(3)
    np.testing.assert_array_equal(other.nn_hidden[0], want.standard_normal((3, 5)))
    np.testing.assert_array_equal(other.nn_hidden[1], want.standard_normal(5))
    assert not np.allclose(base.nn_hidden[0], other.nn_hidden[0])
    assert base.discrepancy_scale is None and not base.has_discrepancy
    disc = ci.build_spec(f, "subcritical", discrepancy=True, discrepancy_floor=0.5)
    assert disc.has_discrepancy and disc.discrepancy_floor == 0.5
    assert np.shape(disc.discrepancy_scale) == (2, 2 * f.n_harmonics + 1)
    back = cm.CollapsedSpec.from_dict(json.loads(json.dumps(disc.to_dict())))
    assert back.discrepancy_scale == disc.discrepancy_scale
    assert back.discrepancy_floor == 0.5


_ORBIT_PROGRAM = """
import jax.numpy as jnp
from bayeshopf.cli.main import prepare_runtime
prepare_runtime()
from bayeshopf.discrepancy.orbits import _flow_jacobian
from bayeshopf.simulators import FLUTTER3DOF as system
n = system.n_states
text = _flow_jacobian(system.rhs).lower(jnp.ones((2, n)), jnp.ones(2), jnp.ones(2) * 16.0,
                                        system.param_tree()).as_text()
print(text.count("python_cpu_callback"))
"""


@pytest.mark.parametrize("user", [None, "raise"])
def test_the_clis_orbit_programs_hold_no_host_callback_unless_the_user_asks(user):
    """JAX's persistent cache stores no program with a host callback, and
    diffrax checks a solve's save times with one unless equinox is told to give
    NaN: the CLI tells it so (a user's EQX_ON_ERROR is kept), and the orbits'
    sampling and sensitivity program then compiles once per machine."""
    env = {k: v for k, v in os.environ.items() if k != "EQX_ON_ERROR"}
    if user is not None:
        env["EQX_ON_ERROR"] = user
    out = subprocess.run([sys.executable, "-c", _ORBIT_PROGRAM], env=env, capture_output=True,
                         text=True, check=True).stdout.strip().splitlines()[-1]
    assert (int(out) == 0) == (user is None), out
