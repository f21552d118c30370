r"""Where the simulator and the recordings disagree: per recording, channel, harmonic, phase.

For recording :math:`r` and channel :math:`c`, the residual along the orbit is
the difference of the measured and simulated phase-fixed Fourier series
(:mod:`bayeshopf.discrepancy.features`), the sensor offsets removed,

.. math::  \Delta_c(\theta) = \Delta C_{c,0}
           + \sum_{k=1}^{K} 2\,\mathrm{Re}\big(\Delta C_{c,k}\,e^{2\pi i k\theta}\big),
           \qquad \theta \in [0, 1),

with :math:`\theta = 0` at the maximum of the first harmonic of the reference
channel. Reported: the amplitude error (simulated over measured half
peak-to-peak, minus 1), the frequency error, the phase of each channel's
fundamental relative to the reference channel's (measured, simulated, error:
a linear mode-shape mismatch shows here), the :math:`\chi^2` per harmonic
(which harmonics carry the mismatch), the arc of phase where
:math:`|\Delta_c|` exceeds half its maximum (around its maximum), the
displacement and velocity of the channel there relative to their amplitudes
("near α ≈ 0", "at large |α|", "at large |α̇|"), and whether the channel's
misfit is significant (:math:`\chi^2` of its features above the 99.9%
quantile for its number of features).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from bayeshopf.discrepancy.features import FeatureLayout

__all__ = ["N_THETA", "curve", "locate"]

N_THETA = 128


def curve(layout: FeatureLayout, y: np.ndarray, channel: str) -> np.ndarray:
    """The orbit of ``channel`` over one period from a feature vector, ``(N_THETA,)``."""
    th = np.arange(N_THETA) / N_THETA
    out = np.full(N_THETA, y[layout.labels.index(f"{channel}:mean")])
    for k in range(1, layout.K + 1):
        re = y[layout.labels.index(f"{channel}:Re{k}")]
        lab = f"{channel}:Im{k}"
        im = y[layout.labels.index(lab)] if lab in layout.labels else 0.0
        out += 2 * (re * np.cos(2 * np.pi * k * th) - im * np.sin(2 * np.pi * k * th))
    return out


def _arc(a: np.ndarray) -> tuple[float, float]:
    """Arc (in degrees of phase) around the maximum of ``a`` where ``a >= max/2``."""
    n = a.size
    i = int(np.argmax(a))
    lo = i
    while a[(lo - 1) % n] >= 0.5 * a[i] and (i - lo) < n - 1:
        lo -= 1
    hi = i
    while a[(hi + 1) % n] >= 0.5 * a[i] and (hi - lo) < n - 1:
        hi += 1
    return 360.0 * lo / n % 360.0, 360.0 * (hi + 1) / n % 360.0


def locate(layout: FeatureLayout, y_meas: np.ndarray, y_sim: np.ndarray, e: np.ndarray,
           offsets: dict[str, float], names, mu, branch, ok) -> list[dict]:
    """Mismatch per recording (module docstring).

    Args:
        layout: Feature layout.
        y_meas: Measured features ``(R, P)``.
        y_sim: Simulated features ``(R, P)`` (NaN rows where lost).
        e: Whitened residuals ``(R, P)`` (offsets profiled out).
        offsets: Fitted sensor offset per channel.
        names: Recording names.
        mu: μ per recording.
        branch: Branch per recording.
        ok: Whether the simulator has the orbit at each recording.

    Returns:
        One dict per recording: ``file``, ``mu``, ``branch``, the worst
        ``channel``, its ``amplitude_error``, the ``frequency_error``,
        ``phase_range`` (degrees), ``significant``, ``where`` (words) and
        ``channels`` (the same per channel, plus the χ² per harmonic).
    """
    out = []
    th = np.arange(N_THETA) / N_THETA
    for r in range(len(names)):
        rec = {"file": names[r], "mu": float(mu[r]), "branch": branch[r]}
        if not ok[r]:
            rec.update(channel=None, amplitude_error=None, frequency_error=None,
                       phase_range=None, significant=True, channels={},
                       where="the simulator has no LCO on this branch here")
            out.append(rec)
            continue
        ferr = float(y_sim[r, 0] / y_meas[r, 0] - 1.0)
        chans = {}
        for c in layout.channels:
            idx = [j for j, ch in enumerate(layout.channel) if ch == c]
            chi2 = float(np.sum(e[r, idx] ** 2))
            sig = bool(stats.chi2.sf(chi2, len(idx)) < 1e-3)
            zm = curve(layout, y_meas[r], c) - offsets.get(c, 0.0)
            zs = curve(layout, y_sim[r], c)
            d = zm - zs
            amp_m, amp_s = np.ptp(zm) / 2, np.ptp(zs) / 2
            arc = _arc(np.abs(d))
            i = int(np.argmax(np.abs(d)))
            v = np.gradient(np.concatenate([zs[-1:], zs, zs[:1]]), th[1] - th[0])[1:-1]
            qn = (zs[i] - zs.mean()) / (amp_s or 1.0)
            vn = v[i] / (np.max(np.abs(v)) or 1.0)
            words = []
            if abs(qn) < 0.35:
                words.append(f"near {c} ≈ {zs.mean():.3g}")
            elif abs(qn) > 0.7:
                words.append(f"at large |{c}|")
            if abs(vn) > 0.7:
                words.append(f"at large |{c}_dot|")
            elif abs(vn) < 0.35:
                words.append(f"near {c}_dot ≈ 0")
            harm = {}
            for k in range(0, layout.K + 1):
                jj = [j for j in idx if layout.harmonic[j] == k and layout.kind[j] != "f"]
                harm[str(k)] = float(np.sum(e[r, jj] ** 2))
            lab = f"{c}:Im1"
            if lab in layout.labels:  # phase of the fundamental relative to the reference
                jr, ji = layout.labels.index(f"{c}:Re1"), layout.labels.index(lab)
                pm = np.degrees(np.angle(y_meas[r, jr] + 1j * y_meas[r, ji]))
                ps = np.degrees(np.angle(y_sim[r, jr] + 1j * y_sim[r, ji]))
                phase = {"measured": float(pm), "simulated": float(ps),
                         "error": float((ps - pm + 180.0) % 360.0 - 180.0)}
            else:
                phase = None
            chans[c] = {"amplitude_error": float(amp_s / amp_m - 1.0), "chi2": chi2,
                        "phase_to_reference_deg": phase,
                        "n_features": len(idx), "significant": sig,
                        "phase_range": [arc[0], arc[1]], "where": ", ".join(words),
                        "rms_error": float(np.sqrt(np.mean(d**2)) / (np.std(zm) or 1.0)),
                        "chi2_by_harmonic": harm}
        worst = max(chans, key=lambda c: chans[c]["chi2"])
        w = chans[worst]
        rec.update(channel=worst, amplitude_error=w["amplitude_error"], frequency_error=ferr,
                   phase_range=w["phase_range"],
                   significant=bool(any(v["significant"] for v in chans.values())),
                   where=w["where"], channels=chans)
        out.append(rec)
    return out
