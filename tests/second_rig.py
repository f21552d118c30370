"""Test fixtures of a second rig, generated in code (its real files are not available).

The rig is described in issue 20: ``.mat`` files named without a branch for the
CBC-held unstable orbits (``CBC_v22_4.mat``) and with ``stable`` for the others
(``CBC_stable_v21_5.mat``); a pitch encoder that reads exactly 6.28318 while it
has no reading, in runs (mostly 2–8 ms, some up to 80 ms, 3–22% of the samples)
that start whenever the pitch passes one angle, so the gaps sit at the same
phase of every cycle; valid pitch between about 0.27 and 0.45 rad; heave at an
offset of about 3.3 V; two files whose ``data`` holds 10,000 samples beside a
``time`` vector of 100,000; a ``manifest.csv`` giving branch and μ; a
``rig.toml``.

The orbits come from the planted Hopf system of :mod:`bayeshopf.data.synthetic`
(subcritical, Hopf point 23 m/s, fold 20.11 m/s). This module plants the
dropouts on its own, from the clean pitch; it shares no code with the reader
that detects them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.io

from bayeshopf.data import Recording, RecordingSet
from bayeshopf.data.synthetic import PlantedHopf

SENTINEL = 6.28318            # what the pitch encoder writes without a reading
DROPOUT_ANGLE = 0.36          # rad: a run starts whenever the pitch passes it
HEAVE_OFFSET_V = 3.3          # V
HEAVE_M_PER_V = 0.18
FS = 2000.0                   # Hz, the ordinary files
SHORT_FS, LONG_TIME_FS = 1000.0, 10000.0   # the two files with a long time vector
DURATION = 8.0                # s (10 s for the two short-data files)
MU0, A2 = 23.0, 3.4           # fold at 23 − 3.4²/4 = 20.11 m/s
# (file, μ, branch, share of long dropout runs, data at SHORT_FS beside a long time)
FILES: tuple[tuple[str, float, str, float, bool], ...] = (
    ("CBC_stable_v20_3.mat", 20.3, "stable", 0.00, False),
    ("CBC_stable_v21_5.mat", 21.5, "stable", 0.10, False),
    ("CBC_stable_v23_1.mat", 23.1, "stable", 0.30, True),
    ("CBC_stable_v24_5.mat", 24.5, "stable", 0.45, False),
    ("CBC_v20_6.mat", 20.6, "unstable", 0.05, False),
    ("CBC_v21_5.mat", 21.5, "unstable", 0.20, True),
    ("CBC_v22_4.mat", 22.4, "unstable", 0.40, False),
)

RIG_TOML = """\
# The second rig: pitch encoder writes 6.28318 when it has no reading.
name = "second rig"
data_variable = "data"        # 4 x N
time_variable = "time"
sample_rate = 2000.0
time_mismatch = "decimate"    # two files hold 10 time stamps per sample of data
mu_variable = "Wind_sped"
mu_label = "airspeed"
mu_units = "m/s"
planar = ["h", "alpha"]

[channels.h]
row = 0
unit = "m"
scale = 0.18                  # m/V; the heave sits at about 3.3 V

[channels.cbc_target]
row = 1
unit = "V"

[channels.actuator]
row = 2
unit = "V"

[channels.alpha]
row = 3
unit = "rad"
angle = true
sentinel = 6.28318
missing = ["nan"]
"""


@dataclass(frozen=True)
class SecondRig:
    """A generated second-rig folder and what was planted in it.

    Attributes:
        folder: The folder (``.mat`` files, ``manifest.csv``, ``rig.toml``).
        clean: The same recordings without dropouts, in manifest order, as
            the rig description reads them (heave in m with its offset).
        dropouts: File name -> mask of the planted sentinel samples.
        truth: The planted system.
    """

    folder: Path
    clean: RecordingSet
    dropouts: dict[str, np.ndarray]
    truth: PlantedHopf


def plant_dropouts(pitch: np.ndarray, fs: float, long_share: float,
                   rng: np.random.Generator) -> np.ndarray:
    """Mask of sentinel runs that start where the pitch passes :data:`DROPOUT_ANGLE`.

    A run starts at every crossing (either way) that is not inside a run
    already; it lasts 2–8 ms, or with probability ``long_share`` 8–80 ms.
    """
    above = pitch >= DROPOUT_ANGLE
    starts = np.flatnonzero(above[1:] != above[:-1]) + 1
    mask = np.zeros(pitch.size, dtype=bool)
    end = -1
    for s in starts:
        if s < end:
            continue
        ms = rng.uniform(8.0, 80.0) if rng.random() < long_share else rng.uniform(2.0, 8.0)
        end = min(pitch.size, s + max(1, int(round(ms * 1e-3 * fs))))
        mask[s:end] = True
    return mask


def build_second_rig(folder: Path, seed: int = 0) -> SecondRig:
    """Write the second rig's files into ``folder`` (created) and return what was planted."""
    folder.mkdir(parents=True, exist_ok=True)
    truth = PlantedHopf(mu0=MU0, a2=A2, omega=2 * np.pi * 4.0, T_s=np.array([0.0, 0.36]))
    rng = np.random.default_rng(seed)
    clean, dropouts, rows = [], {}, []
    for i, (name, mu, branch, long_share, long_time) in enumerate(FILES):
        fs = SHORT_FS if long_time else FS
        duration = 10.0 if long_time else DURATION
        rec = truth.simulate(
            [mu] if branch == "stable" else [], [mu] if branch == "unstable" else [],
            duration=duration, fs=fs, noise=0.01, seed=seed + i,
        )[0]
        h_m, alpha = rec.channel("h"), rec.channel("alpha")
        heave_v = HEAVE_OFFSET_V + h_m / HEAVE_M_PER_V
        n = h_m.size
        target = 0.05 * np.sin(2 * np.pi * 4.0 * rec.t)
        actuator = 0.01 * rng.standard_normal(n)
        mask = plant_dropouts(alpha, fs, long_share, rng)
        pitch = np.where(mask, SENTINEL, alpha)
        data = np.vstack([heave_v, target, actuator, pitch]).astype(np.float32)
        if long_time:
            time = np.arange(10 * n) / LONG_TIME_FS
        else:
            time = rec.t
        scipy.io.savemat(folder / name, {"data": data, "time": time[None, :],
                                         "Wind_sped": np.array([[mu + 0.04]])})
        # what a correct reader returns before leaving the dropouts out
        stored = data.astype(np.float64)
        clean.append(Recording(
            rec.t, {"h": HEAVE_M_PER_V * stored[0], "cbc_target": stored[1],
                    "actuator": stored[2],
                    "alpha": np.where(mask, alpha.astype(np.float32).astype(np.float64),
                                      stored[3])},
            {"h": "m", "cbc_target": "V", "actuator": "V", "alpha": "rad"},
            mu, branch, name=name))
        dropouts[name] = mask
        rows.append(f"{name},{mu},{branch}")
    (folder / "manifest.csv").write_text(
        "# mu_label: airspeed\n# mu_units: m/s\nfile,mu,branch\n" + "\n".join(rows) + "\n")
    (folder / "rig.toml").write_text(RIG_TOML)
    return SecondRig(folder, RecordingSet(tuple(clean), ("h", "alpha"), "airspeed", "m/s"),
                     dropouts, truth)
