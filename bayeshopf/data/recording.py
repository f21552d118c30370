"""Immutable LCO recordings and recording sets.

A :class:`Recording` is one measured limit-cycle oscillation held at a fixed
value of the bifurcation parameter μ: uniformly sampled times ``t`` (with gaps
where a reader left out samples that had no reading) and named channels with
units. A :class:`RecordingSet` groups recordings that share their
channels (each channel in one unit across the set) and names the planar pair
(z1, z2) of the paper's map U12.

A NaN sample means "no reading", as for the readers (:mod:`bayeshopf.data.io`):
a :class:`Recording` leaves out every sample at which ``t`` or a channel is NaN,
with its time stamp, and counts it in :attr:`Recording.dropped`. The harmonic
features are least-squares fits over the samples that remain
(:mod:`bayeshopf.features.harmonics`), so a gap needs no filling.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType
from typing import Literal

import numpy as np

from bayeshopf.data.convergence import Convergence
from bayeshopf.errors import DataError

Branch = Literal["stable", "unstable"]
BRANCHES: tuple[str, ...] = ("stable", "unstable")
#: A spacing of ``t`` above this many times the median is a gap (left-out samples).
GAP_FACTOR = 1.5


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class Recording:
    """One LCO recording at a fixed μ.

    Attributes:
        t: Sample times in seconds, shape ``(n_t,)``, uniform spacing except
            for gaps of whole sample intervals where samples were left out.
        channels: Channel name -> samples, each of shape ``(n_t,)`` (read-only).
        units: Channel name -> physical unit (``""`` when unknown).
        mu: Value of the bifurcation parameter μ (for the flutter rig, the
            airspeed in m/s).
        branch: ``"stable"`` or ``"unstable"``.
        name: Short name, normally the file name (reported in summaries).
        source: Where the recording came from (a path or a description).
        dropped: Samples left out because a sensor had no reading (a reader's
            :class:`~bayeshopf.data.rig.ChannelSpec`, an empty cell, or a NaN in
            ``t`` or a channel given here); they are not in ``t``.
        convergence: How the CBC controller's iteration ended on this recording
            (:mod:`bayeshopf.data.convergence`), or ``None`` when not recorded.
    """

    t: np.ndarray
    channels: Mapping[str, np.ndarray]
    units: Mapping[str, str]
    mu: float
    branch: Branch
    name: str
    source: str = ""
    dropped: int = 0
    convergence: Convergence | None = None

    def __post_init__(self) -> None:
        where = self.name or self.source or "recording"
        t = np.asarray(self.t, dtype=np.float64)
        if t.ndim != 1:
            raise DataError(f"{where}: t must be a 1-D array of >= 3 samples; got shape {t.shape}")
        chans = {}
        for k, v in self.channels.items():
            v = np.asarray(v, dtype=np.float64)
            if v.shape != t.shape:
                raise DataError(
                    f"{where}: channel '{k}' must have shape {t.shape} matching t; got {v.shape}"
                )
            chans[k] = v
        if not chans:
            raise DataError(f"{where}: expected at least one channel besides t; found none")
        gap = np.isnan(t)
        for v in chans.values():
            gap |= np.isnan(v)
        n_gap = int(gap.sum())
        if n_gap:
            keep = ~gap
            t = t[keep]
            chans = {k: v[keep] for k, v in chans.items()}
        t = _readonly(t)
        chans = {k: _readonly(v) for k, v in chans.items()}
        if t.size < 3:
            extra = f" with a reading ({n_gap} NaN left out)" if n_gap else ""
            raise DataError(f"{where}: t must be a 1-D array of >= 3 samples{extra}; got "
                            f"shape {t.shape}")
        if self.convergence is not None and not isinstance(self.convergence, Convergence):
            raise DataError(f"{where}: convergence must be a Convergence or None; found "
                            f"{type(self.convergence).__name__}")
        if self.branch not in BRANCHES:
            raise DataError(
                f"{where}: branch must be 'stable' or 'unstable'; found {self.branch!r}"
            )
        if not np.isfinite(float(self.mu)):
            raise DataError(f"{where}: mu must be a finite number; found {self.mu!r}")
        units = {k: str(self.units.get(k, "")) for k in chans}
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "channels", MappingProxyType(chans))
        object.__setattr__(self, "units", MappingProxyType(units))
        object.__setattr__(self, "mu", float(self.mu))
        if isinstance(self.dropped, bool) or not isinstance(self.dropped, int | np.integer) \
                or self.dropped < 0:
            raise DataError(f"{where}: dropped must be a non-negative integer; "
                            f"found {self.dropped!r}")
        object.__setattr__(self, "dropped", int(self.dropped) + n_gap)

    def __repr__(self) -> str:
        chans = ", ".join(f"{k} [{u}]" if u else k for k, u in self.units.items())
        gaps = f", {self.dropped} left out" if self.dropped else ""
        return (f"Recording({self.name!r}, {self.branch}, mu={self.mu:g}, {self.t.size} samples "
                f"over {self.duration:.4g} s{gaps}; {chans})")

    @cached_property
    def dt(self) -> float:
        """Sampling interval in seconds.

        The mean spacing of ``t``; for a record with gaps (some spacing above
        1.5 times the median) the median spacing.
        """
        mean = float((self.t[-1] - self.t[0]) / (self.t.size - 1))
        steps = np.diff(self.t)
        median = float(np.median(steps))
        return median if float(steps.max()) > GAP_FACTOR * median else mean

    @property
    def has_gaps(self) -> bool:
        """Whether ``t`` has gaps (some spacing above 1.5 times the median)."""
        steps = np.diff(self.t)
        return bool(float(steps.max()) > GAP_FACTOR * float(np.median(steps)))

    @property
    def duration(self) -> float:
        """Record length in seconds."""
        return float(self.t[-1] - self.t[0] + self.dt)

    def channel(self, name: str) -> np.ndarray:
        """Samples of one channel.

        Raises:
            DataError: If the channel does not exist.
        """
        if name not in self.channels:
            raise DataError(
                f"{self.name}: channel '{name}' expected; found {', '.join(self.channels)}"
            )
        return self.channels[name]

    def planar(self, pair: tuple[str, str]) -> np.ndarray:
        """The planar pair (z1, z2) as an array of shape ``(n_t, 2)``."""
        return np.stack([self.channel(pair[0]), self.channel(pair[1])], axis=1)

    def trace(self, pair: tuple[str, str], max_points: int | None = None) -> np.ndarray:
        """The planar pair for drawing, with a NaN row at every gap.

        Every k-th sample (at most ``max_points`` of them; all without it), and
        a row of NaN between two kept samples more than 1.5 kept intervals
        apart, so that a line drawn through the points breaks where samples
        were left out instead of cutting across the orbit. Take means with
        ``np.nanmean``.

        Returns:
            Shape ``(n_points, 2)``.
        """
        z = self.planar(pair)
        step = 1 if not max_points else max(1, -(-z.shape[0] // max(int(max_points), 1)))
        z, t = z[::step], self.t[::step]
        if not self.has_gaps:
            return z
        after = np.flatnonzero(np.diff(t) > GAP_FACTOR * step * self.dt) + 1
        return np.insert(z, after, np.nan, axis=0)


@dataclass(frozen=True)
class RecordingSet:
    """Recordings that share channels, with the planar pair (z1, z2) named.

    A channel's stated unit must be the same in every recording (an empty unit,
    not stated, goes with any); readers convert to one unit per channel
    (:func:`bayeshopf.data.units.harmonise`), and a set built from recordings
    in different units is refused.

    Attributes:
        recordings: The recordings, in a fixed order.
        planar: Names of the planar pair (z1, z2) used by the map U12. z1 is the
            channel whose peak-to-peak amplitude the bifurcation diagram shows.
        mu_label: Name of the bifurcation parameter for plots (e.g. "airspeed").
        mu_units: Unit of μ (e.g. "m/s").
        extra: Free-form provenance (rig name, simulator, seed).
        control: The channel holding the control-based continuation's control
            output (the actuator command), or ``None``. Its residual fundamental
            enters the model as a measured input (:mod:`bayeshopf.model.collapsed`,
            "Control").
    """

    recordings: tuple[Recording, ...]
    planar: tuple[str, str]
    mu_label: str = "mu"
    mu_units: str = ""
    extra: Mapping[str, str] = field(default_factory=dict)
    control: str | None = None

    def __post_init__(self) -> None:
        recs = tuple(self.recordings)
        if not recs:
            raise DataError("recording set: expected at least one recording; found none")
        pair = tuple(self.planar)
        if len(pair) != 2 or pair[0] == pair[1]:
            raise DataError(f"planar pair must be two distinct channel names; got {pair!r}")
        for r in recs:
            for c in pair:
                if c not in r.channels:
                    raise DataError(
                        f"{r.name}: planar channel '{c}' expected; "
                        f"found channels {', '.join(r.channels)}"
                    )
        if self.control is not None:
            if self.control in pair:
                raise DataError(f"control channel '{self.control}' expected apart from the "
                                f"planar pair; found it in {pair!r}")
            for r in recs:
                if self.control not in r.channels:
                    raise DataError(f"{r.name}: control channel '{self.control}' expected; "
                                    f"found channels {', '.join(r.channels)}")
        first: dict[str, tuple[str, str]] = {}
        for r in recs:
            for c, u in r.units.items():
                if not u:
                    continue
                if c not in first:
                    first[c] = (u, r.name)
                elif first[c][0] != u:
                    raise DataError(
                        f"{r.name}: channel '{c}' in '{first[c][0]}' expected (as in "
                        f"{first[c][1]}); found '{u}' (convert first: "
                        "bayeshopf.data.units.harmonise)"
                    )
        object.__setattr__(self, "recordings", recs)
        object.__setattr__(self, "planar", pair)
        object.__setattr__(self, "extra", MappingProxyType(dict(self.extra)))

    def __len__(self) -> int:
        return len(self.recordings)

    def __repr__(self) -> str:
        r0 = self.recordings[0]
        chans = ", ".join(f"{k} [{u}]" if u else k for k, u in r0.units.items())
        mus = self.mus
        units = f" {self.mu_units}" if self.mu_units else ""
        n_unstable = int(self.is_unstable.sum())
        control = f", control {self.control}" if self.control else ""
        return (f"RecordingSet({self.size_text}: {len(self) - n_unstable} stable, {n_unstable} "
                f"unstable; {self.mu_label} {mus.min():g} to {mus.max():g}{units}; planar "
                f"({self.planar[0]}, {self.planar[1]}){control}; channels {chans})")

    @property
    def size_text(self) -> str:
        """``"1 recording"`` or ``"N recordings"``."""
        return f"{len(self)} recording{'' if len(self) == 1 else 's'}"

    def __iter__(self) -> Iterator[Recording]:
        return iter(self.recordings)

    def __getitem__(self, i: int) -> Recording:
        return self.recordings[i]

    @property
    def mus(self) -> np.ndarray:
        """μ of every recording, shape ``(n_rec,)``."""
        return np.array([r.mu for r in self.recordings])

    @property
    def is_unstable(self) -> np.ndarray:
        """Boolean mask of the unstable-branch recordings."""
        return np.array([r.branch == "unstable" for r in self.recordings])

    @property
    def names(self) -> list[str]:
        """Names of the recordings."""
        return [r.name for r in self.recordings]

    @property
    def units(self) -> tuple[str, str]:
        """Units of the planar pair (z1, z2)."""
        r0 = self.recordings[0]
        return (r0.units[self.planar[0]], r0.units[self.planar[1]])

    def subset(self, indices: Sequence[int]) -> RecordingSet:
        """A new set with only the recordings at ``indices`` (order kept)."""
        return RecordingSet(
            tuple(self.recordings[i] for i in indices),
            self.planar,
            self.mu_label,
            self.mu_units,
            self.extra,
            self.control,
        )

    def without(self, index: int) -> RecordingSet:
        """A new set with recording ``index`` left out (for leave-one-out)."""
        return self.subset([i for i in range(len(self)) if i != index])
