"""
The linear model's validity over its speed range: where the nonlinear model is needed.

``model.nonlinear auto`` (the node) decides once, before any sample, by the linear model's
own validity indicator (:mod:`core.validity`) over every speed the model serves. The linear
estimator (:func:`.offline.estimate_offline`, the node's numbers) runs a crank ramped from
rest to the model's largest speed at constant acceleration; the indicator's largest value in
each speed band says whether the linear estimate is valid there.

The ramp is slow enough for the response to build up at each resonance: over
:data:`RAMP_SECONDS` the crank gains ``speed_max / RAMP_SECONDS`` per second, about one
resonance width (``zeta omega / k`` in crank speed, k the crank harmonic) per settling time
``1 / (zeta omega)`` of the paper's linkage. On the paper's linkage (default model, 0-620
rpm) it flagged the regions a stepped steady-state scan flags (100 speeds in 1 % steps: 8 s
against 0.5 s for the ramp), to within a band's width at their edges; the test checks the two
verdicts at speeds inside and outside the resonance band.
"""

import math

import numpy as np

from .offline import estimate_offline
from ..validity import is_valid, VALIDITY_THRESHOLD

RAMP_SECONDS = 20.0
RAMP_RATE_HZ = 1000.0
BAND_RPM = 10.0          # speed bands of the verdict [rpm]
RPM = 30.0 / math.pi     # rad/s -> rpm


def crank_ramp(speed_max, seconds=RAMP_SECONDS, rate_hz=RAMP_RATE_HZ):
    """Return (stamps [ns], wrapped angles [rad], speeds [rad/s]) of a ramp from rest."""
    count = int(round(seconds * rate_hz)) + 1
    time_s = np.arange(count) / rate_hz
    speeds = speed_max * time_s / seconds
    angles = np.mod(0.5 * speed_max * time_s ** 2 / seconds, 2.0 * math.pi)
    return np.round(time_s * 1e9).astype(np.int64), angles, speeds


def validity_over_speeds(model, seconds=RAMP_SECONDS, rate_hz=RAMP_RATE_HZ, band_rpm=BAND_RPM):
    """
    Return the linear model's validity indicator over its speed range (module notes).

    Parameters
    ----------
    model : ReducedModel
        The linear model (its ``speed_max`` is the range).
    seconds, rate_hz : float
        Length and sample rate of the ramp.
    band_rpm : float
        Width of the speed bands [rpm].

    Returns
    -------
    dict
        'bands_rpm' (list of (low, high)), 'indicator_max' per band (NaN where the model has
        no indicator), 'largest' (over the range), 'valid' (None: no indicator),
        'not_valid_rpm' (merged (low, high) ranges above the threshold), 'threshold'.

    """
    stamps, angles, speeds = crank_ramp(model.speed_max, seconds, rate_hz)
    estimate = estimate_offline(model, stamps, angles, speeds, warm_start=False)
    indicator = estimate['nonlinearity']
    rpm = speeds * RPM
    edges = np.arange(0.0, rpm[-1] + band_rpm, band_rpm)
    bands, largest = [], []
    for low, high in zip(edges[:-1], edges[1:]):
        values = indicator[(rpm >= low) & (rpm < high) & np.isfinite(indicator)]
        bands.append((float(low), float(min(high, rpm[-1]))))
        largest.append(float(values.max()) if values.size else math.nan)
    verdict = is_valid(indicator)
    return {'bands_rpm': bands, 'indicator_max': largest, 'largest': verdict['indicator_max'],
            'valid': verdict['valid'], 'threshold': VALIDITY_THRESHOLD,
            'not_valid_rpm': _merged([band for band, value in zip(bands, largest)
                                      if value > VALIDITY_THRESHOLD])}


def _merged(bands):
    """Merge adjacent (low, high) bands."""
    merged = []
    for low, high in bands:
        if merged and merged[-1][1] >= low:
            merged[-1] = (merged[-1][0], high)
        else:
            merged.append((low, high))
    return merged


def ranges_text(ranges):
    """Say merged rpm ranges in words: '230-250, 260-620 rpm'."""
    return ', '.join(f'{low:.0f}-{high:.0f}' for low, high in ranges) + ' rpm'


__all__ = ['crank_ramp', 'validity_over_speeds', 'ranges_text', 'RAMP_SECONDS']
