"""The one JSON schema of the command line's ``--json`` output.

``fit``, ``demo``, ``predict`` and ``next`` print with ``--json`` one JSON
object each. Every command prints one JSON object (never a bare list), whatever the number of
values asked for:

.. code-block:: text

    {
      "schema_version": 1,
      "command": "predict",              # fit | demo | predict | next
      "ci": 0.9,                         # mass of every interval in the object
      "units": {"mu": "m/s", "amplitude": "m", "frequency": "Hz"},
      ...                                # the command's own fields, below
    }

An interval is always ``{"median": m, "lo": a, "hi": b, "ci": 0.9}`` (the
posterior median and the equal-tailed ``ci`` interval), and ``null`` where
there is no value: where the branch exists in fewer than the share of
posterior draws asked for (``predict --min-p-exists``), or a candidate ``next``
skipped. Non-finite numbers are written ``null`` (strict JSON has no NaN).

``predict``: ``fit_dir``, ``branch``, ``predictive`` (bool), ``min_p_exists``,
and ``predictions``, one per ``--mu`` in the order given:
``{"mu", "p_exists", "exists", "amplitude": interval|null, "frequency": interval|null}``.

``next``: ``fit_dir``, ``target`` (fold | hopf | diagram), ``width_now``,
``min_p_exists``, ``min_amplitude``, ``resolution``, ``recommended`` (best
first) and ``candidates`` (grid order), each ``{"rank": int|null, "mu",
"branch", "p_exists", "amplitude": interval|null, "width_after", "gain",
"gain_mcse": float|null, "note": str|null, "ess", "skipped": str|null}``
(``gain_mcse``: the gain's Monte Carlo standard error; ``note``: "no gain",
"below the tunnel's resolution" or "merged into μ = …").

``fit`` and ``demo``: ``out``, ``criticality``, ``parameters``
(``{"mu0": interval, "a2": interval, "mu_fold": interval, ...}``; ``units.mu``
for ``mu0`` and ``mu_fold``), ``recordings``
(``{"file", "mu", "branch", "measured", "predicted": interval, "inside": bool}``),
``checks`` (``{"n_recordings", "amplitudes_inside", "coefficients_inside"}``),
``warnings`` (list of str); ``demo`` adds ``truth`` (``{name: value}``).

The version rises by one with any change that removes or renames a field;
fields may be added within a version.
"""

from __future__ import annotations

import json

from bayeshopf.fit_folder import json_ready

#: Version of the schema above.
SCHEMA_VERSION = 1


def interval_json(median: float, lo: float, hi: float, ci: float) -> dict:
    """An interval of the schema: ``{"median", "lo", "hi", "ci"}``."""
    return {"median": float(median), "lo": float(lo), "hi": float(hi), "ci": float(ci)}


def from_interval(iv) -> dict | None:
    """A :class:`~bayeshopf.diagnostics.summaries.Interval` (or ``None``) in the schema."""
    return None if iv is None else interval_json(iv.median, iv.lo, iv.hi, iv.mass)


def from_summary(entry: dict | None, ci: float) -> dict | None:
    """A ``summary.json`` entry ``{"median": m, "ci90": [lo, hi]}`` in the schema."""
    if entry is None:
        return None
    lo, hi = entry[f"ci{round(100 * ci)}"]
    return interval_json(entry["median"], lo, hi, ci)


def document(command: str, *, ci: float, units: dict, **fields) -> dict:
    """The object a command prints: version, command, ``ci``, ``units``, then ``fields``."""
    return {"schema_version": SCHEMA_VERSION, "command": command, "ci": float(ci),
            "units": dict(units), **fields}


def dumps(doc: dict) -> str:
    """``doc`` as strict JSON (NaN and infinities as ``null``)."""
    return json.dumps(json_ready(doc), indent=1, allow_nan=False)
