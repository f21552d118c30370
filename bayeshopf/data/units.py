"""Units of recorded channels: read with pint, one unit per channel across a set.

A CSV header cell ``h [mm]`` says that column ``h`` is in millimetres; a rig
description's channel ``unit`` (and its ``time_unit``) says the same for
``.mat`` files. The readers convert

* the time column to seconds (a ``t`` without a unit is taken as seconds), and
* every channel to one unit across the set: the unit the rig description
  declares for it, else the first stated unit among the recordings (in
  reading order). A channel without a unit in one file is taken to be in that
  unit already.

A value x in unit a becomes ``x · (a / b)`` in unit b, the factor (and, for
units with an offset such as °C, the offset) taken from pint's registry
(https://pint.readthedocs.io). A channel already in its target unit is left
untouched, bit for bit. An angle in ``deg`` and one in ``rad`` are both
dimensionless to pint, so they convert into each other (by π/180); a unit pint
does not know, or one of another dimension than the target (a length column
given in seconds), stops reading with one line naming the file, the column, the
unit expected and the unit found.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from functools import cache
from typing import TYPE_CHECKING

import numpy as np

from bayeshopf.data.recording import Recording
from bayeshopf.errors import DataError

if TYPE_CHECKING:
    import pint

__all__ = ["SECOND", "convert", "harmonise", "parse_unit", "registry", "time_in_seconds"]

#: The unit of every time column after reading.
SECOND = "s"


@cache
def registry() -> pint.UnitRegistry:
    """The default pint unit registry (imported and built once per process, when needed)."""
    import pint

    return pint.UnitRegistry()


def parse_unit(text: str, where: str, column: str) -> pint.Unit | None:
    """The pint unit of a unit text; ``None`` for an empty text (no unit stated).

    Raises:
        DataError: If pint does not know the unit.
    """
    text = text.strip()
    if not text:
        return None
    try:
        unit = registry().parse_units(text)
    except Exception as exc:  # noqa: BLE001 - pint raises several types for bad text
        raise DataError(
            f"{where}: column '{column}': a unit pint knows expected (e.g. m, mm, rad, deg, V, "
            f"s, ms); found {text!r} ({type(exc).__name__})"
        ) from None
    return unit


def _dims(unit: pint.Unit) -> str:
    dims = str(unit.dimensionality)
    return "dimensionless" if dims in ("", "dimensionless") else dims


def convert(values: np.ndarray, unit: str, target: str, where: str, column: str,
            why: str = "") -> np.ndarray:
    """``values`` in ``unit`` expressed in ``target``.

    An empty ``unit`` (none stated), or one equal to ``target``, returns
    ``values`` unchanged.

    Args:
        values: The samples.
        unit: Their unit as stated.
        target: The unit to convert to.
        where: The file (for messages).
        column: The column (for messages).
        why: Where the target unit comes from (for messages), e.g.
            ``"as in run01.csv"``.

    Raises:
        DataError: If a unit is unknown or the two units are of different
            dimensions.
    """
    src = parse_unit(unit, where, column)
    dst = parse_unit(target, where, column)
    if src is None or dst is None or unit.strip() == target.strip():
        return values
    import pint  # imported by registry() already

    try:
        q = registry().Quantity(np.asarray(values, dtype=np.float64), src)
        return np.asarray(q.to(dst).magnitude, dtype=np.float64)
    except pint.DimensionalityError:
        note = f" {why}" if why else ""
        raise DataError(
            f"{where}: column '{column}': a unit convertible to '{target.strip()}'{note} "
            f"expected ({_dims(dst)}); found '{unit.strip()}' ({_dims(src)})"
        ) from None


def time_in_seconds(t: np.ndarray, unit: str, where: str) -> np.ndarray:
    """Time stamps in ``unit`` (seconds when empty) converted to seconds.

    Raises:
        DataError: If ``unit`` is unknown or not a unit of time.
    """
    return convert(t, unit, SECOND, where, "t", "(time is read in seconds)")


def harmonise(recordings: Sequence[Recording],
              declared: Mapping[str, str] | None = None) -> tuple[Recording, ...]:
    """The recordings with every channel in one unit across the set.

    The target unit of a channel is ``declared[channel]`` when given and not
    empty (a rig description's unit), else the first stated unit among
    ``recordings``. Every stated unit is checked with pint, also when no
    conversion is needed. A channel whose unit was not stated gets the target
    unit (its values untouched).

    Raises:
        DataError: If a unit is unknown or cannot be converted to the target.
    """
    declared = dict(declared or {})
    target: dict[str, tuple[str, str]] = {}
    for r in recordings:
        for c, u in r.units.items():
            if c in target:
                continue
            if declared.get(c, "").strip():
                target[c] = (declared[c].strip(), "(the rig description's unit)")
            elif u.strip():
                target[c] = (u.strip(), f"(as in {r.name})")
    out = []
    for r in recordings:
        channels = dict(r.channels)
        units = dict(r.units)
        for c, x in r.channels.items():
            unit = r.units.get(c, "")
            parse_unit(unit, r.name, c)
            if c not in target:
                continue
            goal, why = target[c]
            channels[c] = convert(x, unit, goal, r.name, c, why)
            units[c] = goal
        same = all(channels[c] is r.channels[c] for c in channels) and units == dict(r.units)
        out.append(r if same else replace(r, channels=channels, units=units))
    return tuple(out)
