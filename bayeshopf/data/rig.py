r"""Rig descriptions: how a rig's ``.mat`` files hold its channels.

A :class:`RigDescription` says, for one rig, where each channel is in a MATLAB
file (a row of the ``data`` matrix or a variable of its own), its name, unit,
scale and offset, which channels are angles, what a sensor writes when it has
no reading, the sample rate or time variable, and where μ is. It is a frozen
dataclass, built in Python or read from a small TOML (or JSON) file that sits
beside the data as ``rig.toml``::

    name = "second rig"
    time_variable = "time"          # or leave it out and give sample_rate
    sample_rate = 10000.0           # Hz
    time_mismatch = "decimate"      # 'time' holds k stamps per sample of 'data'
    mu_variable = "Wind_sped"
    mu_label = "airspeed"
    mu_units = "m/s"
    planar = ["h", "alpha"]

    [convergence]                   # optional: how the CBC controller's iteration ended
    success = "success"
    error = "error1"
    tolerance = "error_tol"

    [channels.h]
    row = 0                         # row of the 'data' matrix (0-based)
    unit = "m"
    scale = 0.18                    # value = scale * (raw - offset)
    offset = 3.3                    # optional, in raw units (V)

    [channels.alpha]
    row = 3
    unit = "rad"
    angle = true
    sentinel = 6.28318              # the encoder's "no reading"
    missing = ["nan", "wrap"]       # NaN and a jump of a full turn mean "no reading" too

A sample is left out of the recording (with its time stamp) when any channel
has no reading there: the raw value equals the channel's ``sentinel`` (within
``sentinel_tolerance``, relative), is NaN or infinite (``"nan"`` in
``missing``), or lies more than half a turn from the channel's median reading
(``"wrap"``, angle channels only; a turn is ``turn``, by default 2π, or 360 for
a unit of ``deg``). The harmonic features are a least-squares fit, so they need
no uniform sampling (:mod:`bayeshopf.features.harmonics`).

**Top-level keys** (all optional except ``channels``): ``name``,
``data_variable`` (``"data"``: the matrix whose rows are channels),
``data_rows`` (the number of rows that matrix must have), ``time_variable``
(``"time"``; ``""`` for none), ``time_unit`` (the unit of the time variable,
``"s"`` by default; ``"ms"`` etc. are converted to seconds with pint,
:mod:`bayeshopf.data.units`), ``sample_rate`` (Hz; used when a file has no time
variable, and by ``time_mismatch = "sample_rate"``), ``time_mismatch``
(``"refuse"``, ``"decimate"``: when the time vector holds k times as many
stamps as ``data`` has samples, every k-th stamp; ``"sample_rate"``: ignore the
time vector's length and space the samples at ``sample_rate`` from its first
stamp), ``mu_variable`` (a scalar variable holding μ), ``mu_pattern`` (a
regular expression searched in the file name when ``mu_variable`` is absent;
its groups joined by ``.`` give μ, so ``'v(\d+)_(\d+)'`` reads 15.6 from
``v15_6``), ``mu_label``, ``mu_units``, ``planar`` (the two channels of the
planar pair; by default the first two channels) and ``control`` (the channel
that holds the control-based continuation's control output, the actuator
command; its residual fundamental is a measured input of the model, see
:mod:`bayeshopf.model.collapsed`; leave it out when the rig records none) and
``convergence`` (a table naming the variables that say whether the CBC
controller converged: ``success``, ``error``, ``tolerance``, ``branches``; see
:mod:`bayeshopf.data.convergence`).

**Channel keys**: ``row``, ``variable`` (default the ``data_variable``; a
vector variable needs no ``row``), ``unit``, ``scale``, ``offset``, ``angle``,
``turn``, ``sentinel``, ``sentinel_tolerance`` and ``missing``. A channel's
``unit`` is its unit after scaling; it must be one pint knows, and recordings
read with the description are given in it (:mod:`bayeshopf.data.units`). A NaN
sample is always "no reading"; ``missing = ["nan"]`` adds infinite values.

The flutter rig of the paper's authors is the built-in description
:meth:`RigDescription.flutter_cbc` (``bayeshopf/data/flutter_cbc.toml``).
Every problem with a description raises
:class:`~bayeshopf.errors.DataError` with one line naming the file and key.
"""

from __future__ import annotations

import json
import math
import os
import re
import tomllib
from dataclasses import dataclass, field, fields
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from bayeshopf.data.convergence import ConvergenceSpec
from bayeshopf.errors import DataError

__all__ = ["RIG_FILE", "ChannelSpec", "RigDescription", "find_rig", "load_rig"]

#: File name of a rig description that sits beside the data.
RIG_FILE = "rig.toml"
#: What ``missing`` may list besides a ``sentinel`` value.
MISSING_KINDS = ("nan", "wrap")
#: Ways of reading a record whose time vector and data differ in length.
TIME_MISMATCH = ("refuse", "decimate", "sample_rate")
_BUILTIN = "flutter_cbc.toml"


def _fail(where: str, msg: str):
    raise DataError(f"{where}: {msg}")


def _number(where: str, key: str, value: Any, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        _fail(where, f"'{key}' must be a number; found {value!r}")
    x = float(value)
    if not math.isfinite(x):
        _fail(where, f"'{key}' must be a finite number; found {value!r}")
    if positive and x <= 0:
        _fail(where, f"'{key}' must be > 0; found {value!r}")
    return x


def _text(where: str, key: str, value: Any, *, allow_empty: bool = True) -> str:
    if not isinstance(value, str) or (not allow_empty and not value.strip()):
        what = "a non-empty string" if not allow_empty else "a string"
        _fail(where, f"'{key}' must be {what}; found {value!r}")
    return value


@dataclass(frozen=True)
class ChannelSpec:
    """Where one channel sits in a rig's files and how to read it.

    Attributes:
        name: Channel name (e.g. ``"h"``).
        row: Row of the matrix variable (0-based); ``None`` for a vector variable.
        variable: Variable holding the channel; ``None`` means the rig's
            ``data_variable``.
        unit: Physical unit after scaling.
        scale: Physical value per raw unit: ``value = scale * (raw - offset)``.
        offset: Raw reading at zero, in raw units (e.g. 3.3 V).
        angle: Whether the channel is an angle (needed for ``"wrap"``).
        turn: A full turn in raw units for ``"wrap"``; ``None`` means 2π, or
            360 when ``unit`` is ``"deg"``.
        sentinel: Raw value the sensor writes when it has no reading.
        sentinel_tolerance: Relative tolerance of the sentinel match
            (``|raw − sentinel| ≤ tol · max(1, |sentinel|)``; the default
            matches a value stored in single precision).
        missing: Other signs of no reading: ``"nan"`` (NaN or infinite) and
            ``"wrap"`` (a jump of a full turn: more than half a turn from the
            channel's median reading).
    """

    name: str
    row: int | None = None
    variable: str | None = None
    unit: str = ""
    scale: float = 1.0
    offset: float = 0.0
    angle: bool = False
    turn: float | None = None
    sentinel: float | None = None
    sentinel_tolerance: float = 1e-6
    missing: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        where = f"channel '{self.name}'"
        name = _text("rig description", "channel name", self.name, allow_empty=False)
        if name != name.strip() or "[" in name or "]" in name or "," in name:
            _fail(where, "a name without surrounding spaces, commas or brackets expected")
        if self.row is not None and (isinstance(self.row, bool) or not isinstance(self.row, int)
                                     or self.row < 0):
            _fail(where, f"'row' must be a non-negative integer (0 is the first row); "
                  f"found {self.row!r}")
        if self.variable is not None:
            _text(where, "variable", self.variable, allow_empty=False)
        _text(where, "unit", self.unit)
        scale = _number(where, "scale", self.scale)
        if scale == 0:
            _fail(where, "'scale' must be non-zero; found 0")
        object.__setattr__(self, "scale", scale)
        object.__setattr__(self, "offset", _number(where, "offset", self.offset))
        if not isinstance(self.angle, bool):
            _fail(where, f"'angle' must be true or false; found {self.angle!r}")
        if self.turn is not None:
            object.__setattr__(self, "turn", _number(where, "turn", self.turn, positive=True))
        if self.sentinel is not None:
            object.__setattr__(self, "sentinel", _number(where, "sentinel", self.sentinel))
        tol = _number(where, "sentinel_tolerance", self.sentinel_tolerance)
        if tol < 0:
            _fail(where, f"'sentinel_tolerance' must be >= 0; found {tol!r}")
        object.__setattr__(self, "sentinel_tolerance", tol)
        kinds = (self.missing,) if isinstance(self.missing, str) else self.missing
        if not isinstance(kinds, list | tuple):
            _fail(where, f"'missing' must be a list drawn from {', '.join(MISSING_KINDS)}; "
                  f"found {self.missing!r}")
        bad = [k for k in kinds if k not in MISSING_KINDS]
        if bad:
            hint = " (give the value as 'sentinel = ...')" if "sentinel" in bad else ""
            _fail(where, f"'missing' entries must be one of {', '.join(MISSING_KINDS)}; "
                  f"found {bad[0]!r}{hint}")
        if "wrap" in kinds and not self.angle:
            _fail(where, "'wrap' in 'missing' needs an angle channel (angle = true); "
                  "found angle = false")
        object.__setattr__(self, "missing", tuple(dict.fromkeys(kinds)))

    @property
    def full_turn(self) -> float:
        """A full turn in raw units (``turn``, or 2π, or 360 for ``deg``)."""
        if self.turn is not None:
            return self.turn
        return 360.0 if self.unit.strip().lower() in ("deg", "degree", "degrees", "°") \
            else 2.0 * math.pi

    def no_reading(self, raw: np.ndarray) -> np.ndarray:
        """Mask of the raw samples at which the sensor had no reading.

        Args:
            raw: Raw samples, shape ``(n,)``.

        Returns:
            Boolean mask, ``True`` where the sample is a sentinel, non-finite
            (with ``"nan"``) or a full turn away (with ``"wrap"``). Non-finite
            samples are never flagged without ``"nan"``: the reader reports them.
        """
        raw = np.asarray(raw, dtype=np.float64)
        finite = np.isfinite(raw)
        mask = np.zeros(raw.shape, dtype=bool)
        if self.sentinel is not None:
            tol = self.sentinel_tolerance * max(1.0, abs(self.sentinel))
            mask |= finite & (np.abs(raw - self.sentinel) <= tol)
        if "nan" in self.missing:
            mask |= ~finite
        if "wrap" in self.missing:
            ok = finite & ~mask
            if ok.any():
                ref = float(np.median(raw[ok]))
                with np.errstate(invalid="ignore"):
                    mask |= finite & (np.abs(raw - ref) > 0.5 * self.full_turn)
        return mask

    def to_physical(self, raw: np.ndarray) -> np.ndarray:
        """``scale * (raw − offset)``."""
        return self.scale * (np.asarray(raw, dtype=np.float64) - self.offset)

    def to_dict(self) -> dict[str, Any]:
        """The channel's keys as in a rig file (defaults left out, no ``name``)."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name != "name" and v != f.default:
                out[f.name] = list(v) if isinstance(v, tuple) else v
        return out


@dataclass(frozen=True)
class RigDescription:
    """How a rig's MATLAB files hold its recordings (module docstring).

    Attributes:
        channels: The channels, in order.
        name: Name of the rig (shown in messages).
        data_variable: Variable of the matrix whose rows are channels.
        data_rows: Number of rows that matrix must have (``None``: any number
            that holds every channel's row).
        time_variable: Variable of the time stamps (s); ``None`` for none.
        sample_rate: Samples per second, used without a time variable and by
            ``time_mismatch = "sample_rate"``.
        time_mismatch: ``"refuse"``, ``"decimate"`` or ``"sample_rate"``
            (module docstring).
        mu_variable: Scalar variable holding μ (overridden by a manifest's μ).
        mu_pattern: Regular expression for μ in the file name (its groups
            joined by ``.``), used when ``mu_variable`` is absent from a file.
        mu_label: Name of μ for plots (e.g. ``"airspeed"``).
        mu_units: Unit of μ.
        planar: The planar pair (z1, z2); ``None`` means the first two channels.
        control: The channel of the control output (actuator command), or ``None``.
        time_unit: Unit of the time variable (converted to seconds).
        convergence: Where the files record the CBC controller's convergence,
            or ``None``.
        source: Where the description was read from (for messages).
    """

    channels: tuple[ChannelSpec, ...]
    name: str = "rig"
    data_variable: str = "data"
    data_rows: int | None = None
    time_variable: str | None = "time"
    sample_rate: float | None = None
    time_mismatch: str = "refuse"
    mu_variable: str | None = None
    mu_pattern: str | None = None
    mu_label: str = "mu"
    mu_units: str = ""
    planar: tuple[str, str] | None = None
    control: str | None = None
    time_unit: str = "s"
    convergence: ConvergenceSpec | None = None
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        where = self.where
        chans = tuple(self.channels)
        if not chans:
            _fail(where, "at least one channel expected ([channels.NAME] tables); found none")
        for c in chans:
            if not isinstance(c, ChannelSpec):
                _fail(where, f"channels must be ChannelSpec objects; found {type(c).__name__}")
        names = [c.name for c in chans]
        dup = [n for n in names if names.count(n) > 1]
        if dup:
            _fail(where, f"each channel named once expected; found '{dup[0]}' twice")
        _text(where, "name", self.name, allow_empty=False)
        _text(where, "data_variable", self.data_variable, allow_empty=False)
        if self.data_rows is not None and (isinstance(self.data_rows, bool)
                                           or not isinstance(self.data_rows, int)
                                           or self.data_rows < 1):
            _fail(where, f"'data_rows' must be a positive integer; found {self.data_rows!r}")
        for c in chans:
            if c.variable is None and c.row is None:
                _fail(where, f"channel '{c.name}': 'row' (of '{self.data_variable}') or "
                      "'variable' expected; found neither")
            if (self.data_rows is not None and c.row is not None and c.variable is None
                    and c.row >= self.data_rows):
                _fail(where, f"channel '{c.name}': 'row' below data_rows = {self.data_rows} "
                      f"expected (rows count from 0); found row = {c.row}")
        tv = self.time_variable
        if tv is not None:
            tv = _text(where, "time_variable", tv).strip() or None
        object.__setattr__(self, "time_variable", tv)
        if self.sample_rate is not None:
            object.__setattr__(self, "sample_rate",
                               _number(where, "sample_rate", self.sample_rate, positive=True))
        if tv is None and self.sample_rate is None:
            _fail(where, "'time_variable' or 'sample_rate' expected (how the samples are "
                  "timed); found neither")
        if self.time_mismatch not in TIME_MISMATCH:
            _fail(where, f"'time_mismatch' must be one of {', '.join(TIME_MISMATCH)}; "
                  f"found {self.time_mismatch!r}")
        if self.time_mismatch == "sample_rate" and self.sample_rate is None:
            _fail(where, "time_mismatch = 'sample_rate' needs 'sample_rate'; found none")
        if self.mu_variable is not None:
            _text(where, "mu_variable", self.mu_variable, allow_empty=False)
        if self.mu_pattern is not None:
            _text(where, "mu_pattern", self.mu_pattern, allow_empty=False)
            try:
                re.compile(self.mu_pattern)
            except re.error as exc:
                _fail(where, f"'mu_pattern' must be a regular expression; {self.mu_pattern!r} "
                      f"is not ({exc})")
        _text(where, "time_unit", self.time_unit, allow_empty=False)
        if self.convergence is not None and not isinstance(self.convergence, ConvergenceSpec):
            _fail(where, f"'convergence' must be a ConvergenceSpec (a [convergence] table); "
                  f"found {self.convergence!r}")
        _text(where, "mu_label", self.mu_label)
        _text(where, "mu_units", self.mu_units)
        pair = self.planar if self.planar is not None else tuple(names[:2])
        if (not isinstance(pair, list | tuple) or len(pair) != 2 or pair[0] == pair[1]
                or not all(isinstance(p, str) for p in pair)):
            _fail(where, f"'planar' must name two distinct channels; found {self.planar!r}"
                  + (" (the description has one channel)" if len(names) < 2 else ""))
        for p in pair:
            if p not in names:
                _fail(where, f"planar channel '{p}' expected among the channels; found "
                      f"{', '.join(names)}")
        if self.control is not None:
            if not isinstance(self.control, str) or self.control not in names:
                _fail(where, f"'control' must name one of the channels ({', '.join(names)}); "
                      f"found {self.control!r}")
            if self.control in pair:
                _fail(where, f"'control' must name a channel outside the planar pair "
                      f"{list(pair)}; found {self.control!r}")
        object.__setattr__(self, "channels", chans)
        object.__setattr__(self, "planar", (pair[0], pair[1]))

    @property
    def where(self) -> str:
        """How messages name the description: its file, or ``rig description 'NAME'``."""
        return self.source or f"rig description '{self.name}'"

    @property
    def channel_names(self) -> tuple[str, ...]:
        """Names of the channels, in order."""
        return tuple(c.name for c in self.channels)

    @property
    def variables(self) -> tuple[str, ...]:
        """Every variable a file of this rig is read for."""
        names = [c.variable or self.data_variable for c in self.channels]
        names += [v for v in (self.time_variable, self.mu_variable) if v]
        names += list(self.convergence.variables) if self.convergence else []
        return tuple(dict.fromkeys(names))

    def mu_from_name(self, file_name: str) -> float | None:
        """μ parsed from a file name with ``mu_pattern``, or ``None``."""
        if self.mu_pattern is None:
            return None
        m = re.search(self.mu_pattern, file_name)
        if m is None:
            return None
        parts = [g for g in m.groups() if g is not None] or [m.group(0)]
        try:
            return float(".".join(parts))
        except ValueError:
            return None

    # ----------------------------------------------------------------------- files

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "") -> RigDescription:
        """Description from the parsed contents of a rig file.

        Args:
            d: Top-level keys and a ``channels`` table of channel tables.
            source: Where ``d`` came from (for messages).

        Raises:
            DataError: On an unknown key, a missing or mistyped value.
        """
        where = source or "rig description"
        if not isinstance(d, dict):
            _fail(where, f"a table of keys expected; found {type(d).__name__}")
        top = {f.name for f in fields(cls)} - {"source"}
        unknown = [k for k in d if k not in top]
        if unknown:
            _fail(where, f"unknown key '{unknown[0]}' (expected keys: {', '.join(sorted(top))})")
        if "channels" not in d:
            _fail(where, "a 'channels' table expected ([channels.NAME] with row, unit, "
                  "scale, ...); found none")
        table = d["channels"]
        if not isinstance(table, dict):
            _fail(where, f"'channels' must be a table of channel tables; found {table!r}")
        ckeys = {f.name for f in fields(ChannelSpec)} - {"name"}
        chans = []
        for name, spec in table.items():
            cwhere = f"{where}: channel '{name}'"
            if not isinstance(spec, dict):
                _fail(cwhere, f"a table of keys expected; found {spec!r}")
            bad = [k for k in spec if k not in ckeys]
            if bad:
                _fail(cwhere, f"unknown key '{bad[0]}' (expected keys: "
                      f"{', '.join(sorted(ckeys))})")
            spec = dict(spec)
            if "missing" in spec and isinstance(spec["missing"], list):
                spec["missing"] = tuple(spec["missing"])
            try:
                chans.append(ChannelSpec(name=name, **spec))
            except DataError as exc:
                raise DataError(f"{where}: {exc}") from None
        kw = {k: v for k, v in d.items() if k != "channels"}
        if "convergence" in kw:
            conv = kw["convergence"]
            keys = {f.name for f in fields(ConvergenceSpec)}
            if not isinstance(conv, dict) or any(k not in keys for k in conv):
                bad = [k for k in conv if k not in keys] if isinstance(conv, dict) else [conv]
                _fail(where, f"[convergence]: keys among {', '.join(sorted(keys))} expected; "
                      f"found {bad[0]!r}")
            conv = dict(conv)
            if isinstance(conv.get("branches"), list):
                conv["branches"] = tuple(conv["branches"])
            try:
                kw["convergence"] = ConvergenceSpec(**conv)
            except DataError as exc:
                raise DataError(f"{where}: {exc}") from None
        if isinstance(kw.get("planar"), list):
            kw["planar"] = tuple(kw["planar"])
        try:
            return cls(channels=tuple(chans), source=source, **kw)
        except DataError as exc:
            msg = str(exc)
            raise DataError(msg if msg.startswith(where) else f"{where}: {msg}") from None

    @classmethod
    def from_file(cls, path: str | os.PathLike[str]) -> RigDescription:
        """Read a rig description from a ``.toml`` or ``.json`` file.

        Raises:
            DataError: If the file is missing, cannot be parsed or describes
                no valid rig.
        """
        path = Path(path)
        name = path.name
        if not path.is_file():
            _fail(str(path), "rig description file (.toml or .json) expected; not found")
        try:
            text = path.read_text(encoding="utf-8-sig")
        except (OSError, UnicodeDecodeError) as exc:
            _fail(name, f"cannot be read ({type(exc).__name__}: {exc})")
        try:
            if path.suffix.lower() == ".json":
                d = json.loads(text)
            else:
                d = tomllib.loads(text)
        except (tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
            kind = "JSON" if path.suffix.lower() == ".json" else "TOML"
            _fail(name, f"cannot be parsed as {kind} ({' '.join(str(exc).split())})")
        return cls.from_dict(d, source=name)

    @classmethod
    def flutter_cbc(cls) -> RigDescription:
        """The built-in description of the paper's wind-tunnel flutter rig.

        ``data`` is 5 x N: heave [V] (row 0, 0.18 m/V), CBC target [V], actuator
        [V], pitch [rad] (row 3) and a running mean of heave [V]; ``time`` in s
        (5 kHz without it); μ is ``Wind_sped`` (m/s), or parsed from a file
        name like ``v15_6``. Read from ``bayeshopf/data/flutter_cbc.toml``.
        """
        return _builtin()

    def to_dict(self) -> dict[str, Any]:
        """Contents of a rig file for this description (defaults left out)."""
        out: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "time_variable" and v is None:
                v = ""                    # no time variable (the default is "time")
            if f.name in ("channels", "source") or v is None or v == f.default:
                continue
            if isinstance(v, ConvergenceSpec):
                v = v.to_dict()
            out[f.name] = list(v) if isinstance(v, tuple) else v
        out["channels"] = {c.name: c.to_dict() for c in self.channels}
        return out


@cache
def _builtin() -> RigDescription:
    text = resources.files("bayeshopf.data").joinpath(_BUILTIN).read_text(encoding="utf-8")
    return RigDescription.from_dict(tomllib.loads(text), source=_BUILTIN)


def load_rig(rig: RigDescription | str | os.PathLike[str]) -> RigDescription:
    """A :class:`RigDescription` as given, or read from a file path.

    Raises:
        DataError: If the file cannot be read as a rig description.
    """
    if isinstance(rig, RigDescription):
        return rig
    if isinstance(rig, str | os.PathLike):
        return RigDescription.from_file(rig)
    raise DataError(f"rig: a RigDescription or the path of a rig file expected; found "
                    f"{type(rig).__name__}")


def find_rig(folder: str | os.PathLike[str]) -> RigDescription | None:
    """The description in ``folder/rig.toml``, or ``None`` when there is none."""
    path = Path(folder) / RIG_FILE
    return RigDescription.from_file(path) if path.is_file() else None
