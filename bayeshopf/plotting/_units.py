"""Unit scales of the figures: lengths in m, cm, mm, µm; angles in rad, mrad, deg.

Only the axes change: a channel in ``m`` drawn with ``length_unit="mm"`` has
every value multiplied by 1000 and the label ``[mm]``. Units outside these
two families (V, N, …) are left as they are.
"""

from __future__ import annotations

import math

#: Size of each length unit in metres.
LENGTHS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "µm": 1e-6, "um": 1e-6, "μm": 1e-6, "nm": 1e-9}
#: Size of each angle unit in radians.
ANGLES = {"rad": 1.0, "mrad": 1e-3, "deg": math.pi / 180, "°": math.pi / 180}


def convert(unit: str, length_unit: str | None = None, angle_unit: str | None = None
            ) -> tuple[float, str]:
    """``(factor, new unit)``: values in ``unit`` times ``factor`` are in the new unit.

    A length becomes ``length_unit``, an angle ``angle_unit``; anything else
    (or a target of ``None``) is kept with factor 1.

    Raises:
        ValueError: For a target that is not a known length or angle unit.
    """
    for target, table, kind in ((length_unit, LENGTHS, "length"), (angle_unit, ANGLES, "angle")):
        if target is not None and target not in table:
            raise ValueError(f"{kind}_unit must be one of {', '.join(table)}; got {target!r}")
    if length_unit is not None and unit in LENGTHS:
        return LENGTHS[unit] / LENGTHS[length_unit], length_unit
    if angle_unit is not None and unit in ANGLES:
        return ANGLES[unit] / ANGLES[angle_unit], angle_unit
    return 1.0, unit


def readable_length(unit: str, largest: float) -> str | None:
    """The length unit among m, mm, µm in which ``largest`` (in ``unit``) reads 1–1000.

    ``None`` when ``unit`` is not a length or ``largest`` is not a positive number.
    """
    if unit not in LENGTHS or not (largest > 0 and math.isfinite(largest)):
        return None
    metres = largest * LENGTHS[unit]
    for name in ("m", "mm", "µm"):
        if metres / LENGTHS[name] >= 1.0:
            return name
    return "µm"
