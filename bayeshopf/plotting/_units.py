"""Unit scales of the figures: lengths in m, cm, mm, µm; angles in rad, mrad, deg.

Only the axes change: a channel in ``m`` drawn with ``length_unit="mm"`` has
every value multiplied by 1000 and the label ``[mm]``. Units outside these
two families (V, N, …) are left as they are. :func:`scale_diagram` and
:func:`scale_ppc` rescale the amplitudes of a diagram's and a check's records.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from bayeshopf.diagnostics.bifurcation import DiagramBands
from bayeshopf.diagnostics.ppc import PosteriorPredictiveCheck

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


def scale_diagram(diagram: DiagramBands, factor: float) -> DiagramBands:
    """The diagram with every amplitude multiplied by ``factor`` (a change of unit)."""
    def band(b):
        if b is None:
            return None
        return dataclasses.replace(
            b, quantiles=np.asarray(b.quantiles) * factor,
            predictive=np.asarray(b.predictive) * factor,
            to_hopf=None if b.to_hopf is None else np.asarray(b.to_hopf) * factor)

    fa = diagram.fold_amplitude
    return dataclasses.replace(
        diagram, stable=band(diagram.stable), unstable=band(diagram.unstable),
        fold_amplitude=None if fa is None else dataclasses.replace(
            fa, median=fa.median * factor, lo=fa.lo * factor, hi=fa.hi * factor))


def scale_ppc(ppc: PosteriorPredictiveCheck, factor: float) -> PosteriorPredictiveCheck:
    """The check with every amplitude multiplied by ``factor`` (a change of unit)."""
    def ivs(items):
        return tuple(dataclasses.replace(iv, median=iv.median * factor, lo=iv.lo * factor,
                                         hi=iv.hi * factor) for iv in items)

    return dataclasses.replace(
        ppc, measured=np.asarray(ppc.measured, float) * factor, curve=ivs(ppc.curve),
        predictive=ivs(ppc.predictive),
        measured_se=None if ppc.measured_se is None
        else np.asarray(ppc.measured_se, float) * factor)
