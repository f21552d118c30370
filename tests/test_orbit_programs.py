"""The orbits' programs stored across processes (bayeshopf.simulators.compiled)."""

import os
import subprocess
import sys

import numpy as np
import pytest

from bayeshopf.discrepancy.terms import library, library_system
from bayeshopf.simulators import FLUTTER3DOF
from bayeshopf.simulators import compiled as programs
from bayeshopf.simulators.flutter import flutter_rhs


def test_only_code_a_key_pins_down_has_a_key():
    assert programs.key_of(flutter_rhs) == ("bayeshopf.simulators.flutter:flutter_rhs",)
    assert programs.key_of(lambda x, mu, p: x) is None           # a user's closure
    assert programs.key_of(None) is None
    lib = library(FLUTTER3DOF, {"h": 0.01, "alpha": 0.05}, 2.5)
    key = programs.key_of(library_system(FLUTTER3DOF, lib).rhs)
    assert key is not None and key[0] == "library" and key[1] == programs.key_of(flutter_rhs)[0]
    # another library has another key; a system with a planted closure has none
    fewer = library(FLUTTER3DOF, {"h": 0.01, "alpha": 0.05}, 2.5, kinds=("cubic_damping",))
    assert programs.key_of(library_system(FLUTTER3DOF, fewer).rhs) != key
    planted = FLUTTER3DOF.with_extra_force(lambda x, mu, p: 0.0 * x[:2])
    assert programs.key_of(planted.rhs) is None
    plib = library(planted, {"h": 0.01, "alpha": 0.05}, 2.5)
    assert programs.key_of(library_system(planted, plib).rhs) is None


#: A subprocess's start: the CLI's runtime, and a list of the functions it traces.
_TRACING = """
import sys
import numpy as np
from jax import monitoring
from bayeshopf.cli.main import prepare_runtime
prepare_runtime()
traced = []
monitoring.register_event_duration_secs_listener(
    lambda event, duration, **kw: traced.append(kw.get("fun_name"))
    if event.endswith("jaxpr_trace_duration") else None)
"""

_PROGRAM = _TRACING + """
from bayeshopf.discrepancy import orbits
from bayeshopf.discrepancy.terms import library, library_system, library_params
from bayeshopf.simulators import FLUTTER3DOF, bifurcation_diagram
lib = library(FLUTTER3DOF, {"h": 0.01, "alpha": 0.05}, 2.5)
system = library_system(FLUTTER3DOF, lib)
b = bifurcation_diagram(FLUTTER3DOF).branch("stable")
i = [len(b.mu) // 3, len(b.mu) // 2, 2 * len(b.mu) // 3]
p = orbits._params({**system.params, **library_params(lib)})
name, fun = sys.argv[1:]               # the program and the function it traces
out = orbits._batched_call(system, name, (b.x0[i], b.period[i], b.mu[i]), p)
out = out if name == "shoot" else out[1]             # the flow: ∂x(t)/∂x0
print(repr(np.ravel(out)[:50].tolist()), traced.count(fun))
"""


def _run(cache_dir, eqx_on_error, *argv, source=_PROGRAM):
    """``source`` run in a fresh process with ``argv``: its printed values and trace count."""
    env = {k: v for k, v in os.environ.items() if k != "EQX_ON_ERROR"}
    env["BAYESHOPF_CACHE_DIR"] = str(cache_dir)
    if eqx_on_error is not None:
        env["EQX_ON_ERROR"] = eqx_on_error
    out = subprocess.run([sys.executable, "-c", source, *argv], env=env, capture_output=True,
                         text=True, check=True).stdout.strip().splitlines()[-1]
    values, count = out.rsplit(" ", 1)
    return np.array(eval(values)), int(count)   # noqa: S307 - our own list of floats


def test_the_library_systems_programs_are_traced_by_the_first_process_only(tmp_path):
    first, n_first = _run(tmp_path, None, "shoot", "shoot")   # the CLI's EQX_ON_ERROR (nan)
    second, n_second = _run(tmp_path, None, "shoot", "shoot")
    assert n_first >= 1 and n_second == 0
    np.testing.assert_array_equal(first, second)
    assert len(list(tmp_path.glob("bayeshopf-exported-orbits-shoot-*.bin"))) == 1


@pytest.mark.slow
def test_a_user_s_eqx_on_error_raise_stores_nothing_and_traces_every_time(tmp_path):
    """With a user's EQX_ON_ERROR=raise nothing is stored; the flow is traced every time.

    The setting puts a host callback in the flow's program (diffrax checks its
    save times), which cannot be stored: each process traces it again and gets
    the same result. Slow (two fresh processes); in the normal suite,
    ``test_inference_setup`` checks which programs hold that callback.
    """
    other = tmp_path / "raise"
    raised, n_raised = _run(other, "raise", "flow", "one")
    again, n_again = _run(other, "raise", "flow", "one")
    assert n_raised >= 1 and n_again >= 1
    assert not list(other.glob("bayeshopf-exported-orbits-flow-*.bin"))
    np.testing.assert_array_equal(raised, again)


_CONTINUATION = _TRACING + """
from bayeshopf.simulators import FLUTTER3DOF
from bayeshopf.simulators.arclength import continue_from_hopf
system = FLUTTER3DOF.with_params(k_h=1.02 * FLUTTER3DOF.params["k_h"])   # not a stored diagram
d = continue_from_hopf(system)
print(repr([float(d.folds[0].mu), float(d.branches[-1].orbits[-1, 7, 0])]),
      traced.count("shoot") + traced.count("states"))
"""


def test_a_continuations_programs_are_traced_by_the_first_process_only(tmp_path):
    first, n_first = _run(tmp_path, None, source=_CONTINUATION)
    second, n_second = _run(tmp_path, None, source=_CONTINUATION)
    assert n_first >= 2 and n_second == 0
    np.testing.assert_array_equal(first, second)
    assert list(tmp_path.glob("bayeshopf-exported-orbits-shot-*.bin"))
    assert list(tmp_path.glob("bayeshopf-exported-orbits-states-*.bin"))
