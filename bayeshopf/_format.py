"""Numbers as bayeshopf prints them: enough digits that an interval's width shows.

Every table (the command line's, the lab report's) writes a median with its
interval through :func:`format_interval` (or a value beside an interval
through :func:`format_values`). The number of decimals ``d`` is the larger of

* ``SIGNIFICANT − 1 − ⌊log10 max|x|⌋``: :data:`SIGNIFICANT` significant digits of
  the largest value printed together, and
* ``WIDTH_DIGITS − 1 − ⌊log10 (hi − lo)⌋``: :data:`WIDTH_DIGITS` significant digits
  of the interval's width,

so ``17.0034 [17.0024, 17.0041]`` is printed where four significant digits would
give ``17 [17, 17]``, and the printed ends differ wherever the interval has a
width. Values of magnitude below ``1e-3`` or from ``1e6`` on are written in
scientific notation with the same rule applied to the mantissa's digits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

#: Significant digits of the largest value printed together (at least).
SIGNIFICANT = 4
#: Significant digits of an interval's width (at least).
WIDTH_DIGITS = 2
#: What a table prints where there is no value (the branch does not exist there).
NO_VALUE = "—"
#: Most decimals printed (float64 holds about 16 significant digits).
_MAX_DECIMALS = 15


def _exponent(x: float) -> int:
    """``⌊log10 |x|⌋`` of ``x`` rounded to 12 significant digits (finite, non-zero).

    The rounding keeps float noise out: ``3.601 − 3.6`` is ``0.000999…89``, a width
    of ``1e-3``.
    """
    return int(f"{abs(x):.11e}".partition("e")[2])


def decimals(values: Sequence[float], width: float | None = None) -> int:
    """Decimals in fixed notation that show ``values`` and an interval's ``width``.

    Args:
        values: The finite values printed together (a median and its interval's ends).
        width: The interval's width ``hi − lo`` (``None`` or ``0``: no width to show).

    Returns:
        ``max(SIGNIFICANT − 1 − ⌊log10 max|x|⌋, WIDTH_DIGITS − 1 − ⌊log10 width⌋)``,
        clipped to ``[0, 15]``.
    """
    finite = [abs(v) for v in values if math.isfinite(v) and v != 0]
    d = SIGNIFICANT - 1 - _exponent(max(finite)) if finite else 0
    if width is not None and math.isfinite(width) and width > 0:
        d = max(d, WIDTH_DIGITS - 1 - _exponent(width))
    return min(max(d, 0), _MAX_DECIMALS)


def format_values(values: Sequence[float | None], width: float | None = None) -> list[str]:
    """``values`` written with one number of digits that shows ``width`` (see module doc).

    ``None`` and non-finite values are written :data:`NO_VALUE`.
    """
    finite = [float(v) for v in values if v is not None and math.isfinite(v)]
    if not finite:
        return [NO_VALUE] * len(values)
    big = max(abs(v) for v in finite)
    if big != 0 and not 1e-3 <= big < 1e6:              # scientific: digits of the mantissa
        e = _exponent(big)
        d = decimals([v / 10.0 ** e for v in finite],
                     None if width is None else width / 10.0 ** e)
        return [NO_VALUE if v is None or not math.isfinite(v) else f"{v:.{d}e}"
                for v in values]
    d = decimals(finite, width)
    return [NO_VALUE if v is None or not math.isfinite(v) else f"{v:.{d}f}" for v in values]


def format_interval(median: float, lo: float, hi: float) -> tuple[str, str, str]:
    """``(median, lo, hi)`` as strings with enough digits that ``hi − lo`` shows.

    Examples:
        >>> format_interval(17.0034, 17.0024, 17.0041)
        ('17.0034', '17.0024', '17.0041')
        >>> format_interval(3.6, 3.6, 3.601)
        ('3.6000', '3.6000', '3.6010')
    """
    m, a, b = format_values([median, lo, hi], hi - lo)
    return m, a, b


def format_number(x: float | None) -> str:
    """One value on its own: :data:`SIGNIFICANT` significant digits (``NO_VALUE`` if none)."""
    return format_values([x])[0]


def interval_text(median: float, lo: float, hi: float) -> str:
    """``"median [lo, hi]"`` through :func:`format_interval`."""
    m, a, b = format_interval(median, lo, hi)
    return f"{m} [{a}, {b}]"
