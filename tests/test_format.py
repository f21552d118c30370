"""The command line's numbers show every interval's width; ``bayeshopf --help`` stays light."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from bayeshopf._format import (
    NO_VALUE,
    format_interval,
    format_number,
    format_values,
    interval_text,
)


def _last_digit(s: str) -> float:
    """The value of one unit in the last printed digit of ``s`` (fixed or scientific)."""
    mantissa, _, exp = s.partition("e")
    decimals = len(mantissa.partition(".")[2])
    return 10.0 ** (-decimals + (int(exp) if exp else 0))


@pytest.mark.parametrize("iv, expected", [
    ((17.0034, 17.0024, 17.0041), ("17.0034", "17.0024", "17.0041")),   # not 17 [17, 17]
    ((3.6, 3.6, 3.601), ("3.6000", "3.6000", "3.6010")),               # not 3.6 [3.6, 3.601]
    ((16.02, 15.9, 16.1), ("16.02", "15.90", "16.10")),                 # 4 significant digits
    ((1.234, 0.3, 2.5), ("1.234", "0.300", "2.500")),
])
def test_the_issues_cases(iv, expected):
    assert format_interval(*iv) == expected
    assert interval_text(*iv) == f"{expected[0]} [{expected[1]}, {expected[2]}]"


def test_every_width_shows_and_every_value_is_within_half_a_printed_digit():
    """Random intervals over 16 decades of magnitude and 8 of relative width: the printed
    ends differ, the printed width is within 10% of the true one (two significant digits
    of it at least), and the largest value keeps four significant digits."""
    rng = np.random.default_rng(0)
    for _ in range(3000):
        centre = rng.choice([-1, 1]) * 10.0 ** rng.uniform(-8, 8)
        width = abs(centre) * 10.0 ** rng.uniform(-7, 1)
        lo = centre - width * rng.uniform(0, 1)
        hi, med = lo + width, lo + width * rng.uniform(0, 1)
        strs = format_interval(med, lo, hi)
        back = [float(s) for s in strs]
        for s, x in zip(strs, (med, lo, hi), strict=True):
            assert abs(float(s) - x) <= 0.5 * _last_digit(s) * (1 + 1e-9), (s, x)
        assert back[1] < back[2], (strs, lo, hi)
        assert abs((back[2] - back[1]) - width) <= 0.1 * width * (1 + 1e-9), (strs, lo, hi)
        big = max(abs(med), abs(lo), abs(hi))
        worst = max(0.5 * _last_digit(s) for s in strs)
        assert worst <= 5e-4 * big * (1 + 1e-9), (strs, big)


def test_no_value_and_lone_numbers():
    assert format_interval(math.nan, math.nan, math.nan) == (NO_VALUE,) * 3
    assert format_values([None, 1.5], 0.1) == [NO_VALUE, "1.500"]
    assert format_number(None) == NO_VALUE
    assert format_number(0.019761) == "0.01976"
    assert format_number(0.0) == "0"
    assert format_number(2.5e-5) == "2.500e-05"


def test_help_imports_neither_jax_nor_the_library():
    """``bayeshopf --help`` lists every command without importing a command's module."""
    code = ("import sys\nfrom bayeshopf.cli.main import main\ntry:\n    main(['--help'])\n"
            "except SystemExit:\n    pass\n"
            "print(sorted(m for m in sys.modules if m in ('jax', 'scipy', 'bayeshopf.fit_folder')"
            " or m.startswith(('bayeshopf.cli.fit', 'bayeshopf.cli.predict'))))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120, check=True)
    lines = r.stdout.strip().splitlines()
    assert lines[-1] == "[]", r.stdout
    assert all(c in r.stdout for c in ("demo", "fit", "predict", "next", "discrepancy"))


def test_one_module_per_command():
    """Every command is a module with its description, its options and its run."""
    import importlib

    from bayeshopf.cli.main import COMMANDS

    modules = {cmd.module for cmd in COMMANDS.values()}
    assert len(modules) == len(COMMANDS)
    for cmd in COMMANDS.values():
        m = importlib.import_module(cmd.module)
        assert m.DESCRIPTION and callable(m.add_arguments) and callable(m.run), cmd.module
