"""``import bayeshopf`` leaves JAX's float64 switch alone; computing turns it on.

Each check runs in a fresh interpreter: the test session itself has float64 on
(tests/conftest.py), and JAX's configuration is process-wide.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

IMPORT_ALL = """
import importlib, pkgutil
import jax
import bayeshopf
for m in pkgutil.walk_packages(bayeshopf.__path__, "bayeshopf."):
    importlib.import_module(m.name)
assert jax.config.jax_enable_x64 is False, "an import switched float64 on"
"""


def _run(code: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false",
           "JAX_ENABLE_X64": "0", "BAYESHOPF_CACHE_DIR": "off"}
    return subprocess.run([sys.executable, "-c", textwrap.dedent(IMPORT_ALL + code)],
                          capture_output=True, text=True, timeout=240, env=env)


def test_import_leaves_float64_off() -> None:
    r = _run("import jax.numpy as jnp\nprint(jnp.asarray(1.0).dtype)")
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["float32"]


@pytest.mark.parametrize("call, expect", [
    # the simulators: the Jacobian at the Van der Pol oscillator's equilibrium; a vector field
    ("from bayeshopf.simulators import equilibria, registry\n"
     "out = equilibria.jacobian(registry.get_system('vanderpol'), [0.0, 0.0], 0.1)",
     "float64"),
    ("from bayeshopf.simulators import registry\n"
     "s = registry.get_system('flutter3dof')\n"
     "out = s.vector_field([0.01] * s.n_states, 15.0)",
     "float64"),
    # the command line, before it dispatches (the fit folder is missing: exit 2)
    ("from bayeshopf.cli.main import main\nimport jax.numpy as jnp\n"
     "assert main(['predict', '/nonexistent/fit', '--mu', '1']) == 2\n"
     "out = jnp.asarray(1.0)",
     "float64"),
])
def test_computing_switches_float64_on(call: str, expect: str) -> None:
    r = _run(call + "\nimport numpy as np\nprint(jax.config.jax_enable_x64, np.asarray(out).dtype)")
    assert r.returncode == 0, r.stderr
    assert r.stdout.split()[-2:] == ["True", expect]


def test_the_first_float64_switch_sets_the_cpu_flags_before_any_computation():
    """A user's script that computes with bayeshopf before any fit gets JAX's CPU flags."""
    import subprocess
    import sys

    code = ("import os; os.environ.pop('XLA_FLAGS', None); "
            "from bayeshopf.simulators.truth import flutter_experiment; "
            "flutter_experiment(seed=0, fast=True); "
            "from bayeshopf._xla import SINGLE_THREAD_EIGEN; "
            "print(SINGLE_THREAD_EIGEN in os.environ.get('XLA_FLAGS', ''))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip().splitlines()[-1]
    assert out == "True"
