"""The IMU swing estimate's low-pass, chosen from the flight's own vibration.

PX4 logs and streams its IMU as integrated samples (``sensor_combined``, HIGHRES_IMU: the
delta velocity over each 4–5 ms), so rotor vibration above their Nyquist rate folds down
instead of being filtered: 230 Hz read at 250 Hz lands at 20 Hz, inside the band PX4's own
30 Hz low-pass keeps. On PX4 SITL with swingrt's physics 65 % of the body-x specific force's
power sits at 10–30 Hz. The swing estimator's default low-pass (10 Hz,
``swing_core::sensors::swing``) was chosen where the estimate's noise above the payload's
motion is about 0.3° (the built-in simulator's IMU reads 0.25° by :func:`swing_noise`, which
is where the pendulum observer's measurement noise comes from), and it passes a 20 Hz alias
at a quarter of its amplitude: 1.6° on that SITL flight.

:func:`choose_cutoff` keeps the estimator's cutoff where the flight's vibration leaves at
most :data:`NOISE_BOUND_DEG` of angle noise through it, and otherwise lowers it to the
highest cutoff that does (not below :data:`MIN_CUTOFF_HZ`): on that flight 4.0 Hz, 0.30°.
The noise is the Welch spectrum of the body-horizontal specific force as the estimator is
fed it (block means at its rate), above :data:`MOTION_BAND_HZ` where no payload mode lies,
through the estimator's second-order Butterworth (bilinear, pre-warped:
|H|² = 1 / (1 + (tan(πf/f_s) / tan(πf_c/f_s))⁴)), over the pull scale k̂ (angle ≈ force / k̂),
the worse axis. A lower cutoff costs the swing's phase (the group delay at DC is
√2/(2πf_c): 56 ms at 4 Hz against 22 ms at 10); the identified model learns that lag with
the swing, and the flight estimates through the same filter.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import signal

#: The angle noise above the payload's motion the estimator's defaults were chosen at [deg].
NOISE_BOUND_DEG = 0.3
#: Above this the specific force carries vibration, noise and the attitude loop, not the
#: payload's swing [Hz]: the swing spectrum's band ends at 12 rad/s (1.9 Hz; a link of
#: 0.07 m), and a 0.3 m cable swings at 0.9 Hz.
MOTION_BAND_HZ = 3.0
#: The lowest cutoff chosen [Hz]: the top of the motion band, so the filter still passes
#: every swing mode with under 45° of phase.
MIN_CUTOFF_HZ = MOTION_BAND_HZ
#: Length of Welch's segments [s] (Hann, half overlap): a resolution of 0.39 Hz.
SEGMENT_S = 2.56


@dataclass(frozen=True)
class CutoffChoice:
    """What :func:`choose_cutoff` decided."""

    #: The cutoff to estimate with [Hz].
    cutoff: float
    #: The cutoff the estimator's settings had [Hz].
    given: float
    #: Angle noise above the motion band through the given cutoff [deg].
    noise_given_deg: float
    #: Angle noise above the motion band through the chosen cutoff [deg].
    noise_deg: float

    def as_dict(self) -> dict[str, float]:
        """Plain values, for a trace's ``meta`` and a model's diagnostics."""
        return asdict(self)


def _power(x: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """One-sided Welch power spectral density of ``x`` sampled at ``rate`` [Hz] (Hann
    segments of :data:`SEGMENT_S`, half overlap, each segment's mean removed): the
    frequencies [Hz] and the density [unit²/Hz]; empty when ``x`` is shorter than a
    segment."""
    seg = int(round(SEGMENT_S * rate))
    if seg < 8 or len(x) < seg:
        return np.zeros(0), np.zeros(0)
    freq, density = signal.welch(x, fs=rate, window="hann", nperseg=seg, detrend="constant")
    return freq, density


def _noise(freq: np.ndarray, density: np.ndarray, rate: float, cutoff: float) -> float:
    """RMS of the density's part above the motion band through the low-pass at ``cutoff``."""
    if len(freq) < 2:
        return 0.0
    band = freq >= MOTION_BAND_HZ
    if cutoff > 0.0 and cutoff < 0.5 * rate:
        ratio = np.tan(np.pi * freq[band] / rate) / math.tan(math.pi * cutoff / rate)
        gain = 1.0 / (1.0 + ratio**4)
    else:
        gain = np.ones(int(band.sum()))
    return math.sqrt(float(np.sum(density[band] * gain)) * float(freq[1] - freq[0]))


def _spectra(accel_xy: np.ndarray, rate: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Both axes' Welch densities, over the samples where both are finite."""
    x = np.asarray(accel_xy, float)
    x = x[np.isfinite(x).all(axis=1)]
    return [_power(x[:, i], rate) for i in range(2)]


def _worst(spectra, rate: float, scale: float, cutoff: float) -> float:
    """The worse axis's angle noise [rad] through the low-pass at ``cutoff``."""
    return max(_noise(f, p, rate, cutoff) for f, p in spectra) / scale


def swing_noise(accel_xy: np.ndarray, rate: float, scale: float, cutoff: float) -> float:
    """Angle noise [rad] the estimator passes at ``cutoff`` [Hz] of the body-horizontal
    specific force ``accel_xy`` (N×2 [m/s²], as fed at ``rate`` [Hz]) above the motion band,
    at the pull scale ``scale`` [m/s²]; the worse axis (module docs)."""
    return _worst(_spectra(accel_xy, rate), rate, scale, cutoff)


def choose_cutoff(accel_xy: np.ndarray, rate: float, scale: float, cutoff: float) -> CutoffChoice:
    """The estimator's cutoff [Hz] for a flight whose body-horizontal specific force, as the
    estimator is fed it, is ``accel_xy`` (N×2 at ``rate`` [Hz]): ``cutoff`` where the noise
    it passes is within :data:`NOISE_BOUND_DEG`, else the highest cutoff that keeps it
    there, found by bisection, or :data:`MIN_CUTOFF_HZ` (module docs). A cutoff of 0 (no
    low-pass) is lowered like any other; a flight shorter than a Welch segment keeps
    ``cutoff``."""
    spectra = _spectra(accel_xy, rate)
    bound = math.radians(NOISE_BOUND_DEG)

    def noise(fc: float) -> float:
        return _worst(spectra, rate, scale, fc)

    top = cutoff if 0.0 < cutoff < 0.5 * rate else 0.5 * rate
    given = noise(cutoff)
    if given <= bound or top <= MIN_CUTOFF_HZ:
        return CutoffChoice(cutoff, cutoff, math.degrees(given), math.degrees(given))
    lo, hi = MIN_CUTOFF_HZ, top
    if noise(lo) > bound:
        chosen = lo
    else:
        # noise(fc) grows with fc: the largest fc with noise(fc) <= bound, to 0.01 Hz
        # (rounded down, so the bound still holds).
        while hi - lo > 0.01:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if noise(mid) <= bound else (lo, mid)
        chosen = math.floor(lo * 100.0) / 100.0
    return CutoffChoice(chosen, cutoff, math.degrees(given), math.degrees(noise(chosen)))
