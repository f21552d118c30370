"""The control term's summary: the orbits' response to a recording's control fundamental."""

from __future__ import annotations

import numpy as np

from bayeshopf.diagnostics.summaries import CI, interval
from bayeshopf.features.harmonics import HarmonicFeatures
from bayeshopf.model.collapsed import CollapsedSpec


def control_gain(spec: CollapsedSpec, betas, features: HarmonicFeatures,
                 ci: float = CI) -> dict | None:
    """The orbits' response to the control's fundamental, or ``None`` without the term.

    ``gain``: the median and ``ci`` interval of the real and imaginary parts
    of ``H``, the response of the second frame axis ``w2`` (frame units per
    unit of the control channel; :mod:`bayeshopf.model.collapsed`, "Control");
    ``prior_sd``: their prior sd; ``response``: per recording, the median of
    ``|H U_i|`` relative to the measured fundamental of ``w2``. Where ``U`` is
    nearly proportional to the orbit, as on the wind-tunnel rig, that part of
    the response is not told apart from the map's own linear gain, so
    ``response`` is an upper bound on what the control moves.

    Args:
        spec: Model structure.
        betas: Draws of the linear coefficients ``(n, J, 2)`` (the control's
            rows ``n_map:n_basis``).
        features: The training recordings' features (their control fundamentals).
        ci: Mass of the intervals.
    """
    if spec.control_scale is None:
        return None
    h = np.asarray(betas)[:, spec.n_map:spec.n_basis, 1]                 # (n, 2): w2's
    gain = {part: interval(h[:, j], ci).to_json() for j, part in enumerate(("re", "im"))}
    u = np.asarray(features.control)                                    # (n_rec, 2)
    resp = np.abs((h[:, :1] + 1j * h[:, 1:]) * (u[:, 0] - 1j * u[:, 1])[None])
    K = spec.n_harmonics
    c = features.coeffs[:, 1]
    rel = np.median(resp, axis=0) / np.hypot(c[:, 1], c[:, K + 1])
    return {"axis": "w2", "prior_sd": float(spec.control_scale), "gain": gain,
            "units": "frame units per unit of the control channel",
            "response": {name: float(rel[i]) for i, name in enumerate(features.names)}}
