"""What the estimator returns per crank sample: a :class:`Sample` with :class:`SampleFlag` bits."""

import dataclasses
import enum
import math

import numpy as np

# Output magnitude floor of the error indicator [m] (1 um: below it relative errors mean little).
ERROR_INDICATOR_FLOOR_M = 1e-6


class SampleFlag(enum.IntFlag):
    """What happened at a sample."""

    NONE = 0
    RESET = 1            # state restarted (first sample, backward stamp, long gap)
    WARM_START = 2       # state set to the periodic steady state at the current speed
    LARGE_STEP = 4       # step longer than the large-step threshold
    CLIPPED_SPEED = 8    # |speed| beyond the model's range, clipped for the model
    CLIPPED_ACCEL = 16   # |acceleration| beyond the limit, clipped
    REPEATED = 32        # same stamp and angle again: previous estimate returned
    SPEED_FROM_ANGLE = 64  # no measured speed: differentiated from angles
    NO_CRITERIA = 128    # the model has no joint-reaction data: criteria are zero
    OUTLIER = 256        # an implausible input sample was skipped before this one
    OUT_OF_BOUND = 512   # deflection beyond the model's bound: not a number to publish; reset
    COLD_START = 1024    # warm start skipped (rate limit of warm starts): static start


# Plain-int copies of the flags for the per-sample path (IntFlag arithmetic is slow).
RESET, WARM_START, LARGE_STEP = int(SampleFlag.RESET), int(SampleFlag.WARM_START), \
    int(SampleFlag.LARGE_STEP)
CLIPPED_SPEED, CLIPPED_ACCEL = int(SampleFlag.CLIPPED_SPEED), int(SampleFlag.CLIPPED_ACCEL)
REPEATED, SPEED_FROM_ANGLE = int(SampleFlag.REPEATED), int(SampleFlag.SPEED_FROM_ANGLE)
NO_CRITERIA = int(SampleFlag.NO_CRITERIA)
OUTLIER, OUT_OF_BOUND = int(SampleFlag.OUTLIER), int(SampleFlag.OUT_OF_BOUND)
COLD_START = int(SampleFlag.COLD_START)


@dataclasses.dataclass(slots=True)
class Sample:
    """
    One estimate.

    Attributes
    ----------
    stamp_ns : int
        Input stamp [ns].
    crank_angle, crank_speed, crank_accel : float
        Wrapped angle [rad] in [0, 2 pi), speed [rad/s], acceleration [rad/s^2].
    lever_tip, coupler_mid : tuple of float
        Elastic deflection (dx, dy) of the lever's upper end and the coupler's mid-point in
        the ground frame [m] (with the second-order motion when the model's order is 2).
    reaction_n, gamma_dot, criterion : tuple of float
        Per joint (O2, A, B, O4): rigid-body reaction magnitude R [N], rate of its direction
        [rad/s], and the Earles-Wu criterion |gamma-dot / R| [rad/(s N)].
    near_zero : tuple of bool
        Per joint: R below the near-zero fraction of its cycle RMS at this speed.
    error_indicator : float
        Size of the residual-flexibility correction relative to the deflection (see
        core/reduction); large values mean the reduced basis misses part of the response.
    flags : int
        What happened: bits of :class:`SampleFlag` (``sample.flags & SampleFlag.RESET``).
    message : str
        Warning text, empty if none.
    modal : tuple of float
        Reduced coordinates q (for :meth:`StreamingEstimator.link_shapes`).
    nonlinearity : float
        Validity indicator of the linear estimate (:mod:`core.validity`: the detuning ratio,
        frequency shift of the elastic axial force over the distance to resonance); above
        :data:`core.validity.VALIDITY_THRESHOLD` the estimate cannot be trusted. NaN when the
        model cannot compute it.

    """

    stamp_ns: int
    crank_angle: float
    crank_speed: float
    crank_accel: float
    lever_tip: tuple
    coupler_mid: tuple
    reaction_n: tuple
    gamma_dot: tuple
    criterion: tuple
    near_zero: tuple
    error_indicator: float
    flags: int
    message: str
    modal: tuple
    nonlinearity: float = math.nan


def sample_from_record(stamp_ns, crank, deflection, correction, criteria, flags, message, modal,
                       nonlinearity=math.nan):
    """
    Return the estimate of a sample from its record's values and its criteria.

    Parameters
    ----------
    stamp_ns : int
        Input stamp [ns].
    crank : tuple of float
        (angle, speed, accel) of the crank filter.
    deflection, correction : list of float
        Deflections with the residual correction, and the correction alone (lever tip x, y,
        coupler mid-point x, y) [m].
    criteria : tuple
        (reactions, gamma-dots, criteria, near-zero flags) per joint.
    flags : int
        :class:`SampleFlag` bits.
    message : str
        Warning text, empty if none.
    modal : tuple of float
        Reduced coordinates q.
    nonlinearity : float
        Validity indicator (NaN if the model cannot compute it).

    """
    size = math.sqrt(sum([d * d for d in deflection]))
    return Sample(
        stamp_ns=int(stamp_ns), crank_angle=crank[0], crank_speed=crank[1], crank_accel=crank[2],
        lever_tip=(deflection[0], deflection[1]),
        coupler_mid=(deflection[2], deflection[3]),
        reaction_n=criteria[0], gamma_dot=criteria[1], criterion=criteria[2],
        near_zero=criteria[3],
        error_indicator=math.sqrt(sum([c * c for c in correction]))
        / max(size, ERROR_INDICATOR_FLOOR_M),
        flags=flags, message=message, modal=modal, nonlinearity=nonlinearity)


def error_indicator_rows(lever_tip, coupler_mid, correction):
    """
    Return the error indicator of many samples, as :func:`sample_from_record` (the same bits).

    Parameters
    ----------
    lever_tip, coupler_mid : ndarray, shape (m, 2)
        Deflections with the residual correction [m].
    correction : ndarray, shape (m, 4)
        The correction alone (lever tip x, y, coupler mid-point x, y) [m].

    """
    # Summed left to right, as the scalar path's sum(), so the two agree to the last bit.
    size = np.sqrt(((lever_tip[:, 0] * lever_tip[:, 0] + lever_tip[:, 1] * lever_tip[:, 1])
                    + coupler_mid[:, 0] * coupler_mid[:, 0])
                   + coupler_mid[:, 1] * coupler_mid[:, 1])
    squares = correction * correction
    return (np.sqrt(((squares[:, 0] + squares[:, 1]) + squares[:, 2]) + squares[:, 3])
            / np.maximum(size, ERROR_INDICATOR_FLOOR_M))


def nan_sample(stamp_ns, crank, flags, message, size):
    """
    Return a sample that is not a number to publish: NaN deflections, criteria and state.

    Parameters
    ----------
    stamp_ns : int
        Input stamp [ns].
    crank : tuple of float
        (angle, speed, accel) of the crank filter.
    flags : int
        :class:`SampleFlag` bits (OUT_OF_BOUND among them).
    message : str
        Why.
    size : int
        Reduced size r (NaN modal coordinates).

    """
    nan2, nan4 = (math.nan,) * 2, (math.nan,) * 4
    return Sample(
        stamp_ns=int(stamp_ns), crank_angle=crank[0], crank_speed=crank[1], crank_accel=crank[2],
        lever_tip=nan2, coupler_mid=nan2, reaction_n=nan4, gamma_dot=nan4,
        criterion=nan4, near_zero=(False,) * 4, error_indicator=math.nan,
        flags=flags, message=message, modal=(math.nan,) * size)
