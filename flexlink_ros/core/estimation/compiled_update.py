"""
The streaming update of an ordinary sample in one compiled call (``Update`` of _radau_step.c).

:meth:`StreamingEstimator.update <.streaming.StreamingEstimator.update>` hands each sample to
:attr:`CompiledUpdate.sample` first. For a sample the gate passes as a plain step it does, in
C, what the Python path does: the gate's checks, the crank filter, the clipping and flags,
the step row, the step, the record, the joint criteria, the deflection bound, the validity
indicator and the :class:`~.sample.Sample` (the same doubles). Anything else returns None with
nothing changed, and the Python path (the reference) takes the sample.

The two paths share the estimator's state: the model state z, the last crank state and the
crank filter's state are the estimator's own arrays, which the C object reads and writes in
place (and puts back when it falls back after changing them). Only the gate's reference, the
last accepted sample, moves to C while the path is armed: :meth:`fall_back` hands it back to
the :class:`~.gate.InputGate` before the Python path runs, and the estimator arms the path
again (:meth:`arm`) after the Python path accepted a sample with nothing pending (no skipped
outlier, no deferred warm start).
"""

import dataclasses
import math

from . import native
from .gate import ANGLE_ALLOWANCE_RAD
from .sample import (CLIPPED_ACCEL, CLIPPED_SPEED, ERROR_INDICATOR_FLOOR_M, LARGE_STEP, Sample,
                     SPEED_FROM_ANGLE)
from .step import MAX_SUBSTEP_NS, REACTION_FLOOR_FRACTION, STAGE1

# Why the last sample went to the Python path (Update.fallback; FALLBACK_* of _radau_step.c).
FALLBACK_REASONS = ('none', 'not armed', 'input', 'gate', 'filter', 'step', 'bound')


def compiled_update(estimator, stepper, gate, record, base_flags):
    """
    Return the compiled update of an estimator, or a :class:`PythonUpdate` where it cannot serve.

    It needs the compiled step and filter, and the validity indicator compiled or absent (its
    Python form differs in the last bits); a model with the dynamic second-order pass steps
    on the Python path (its own compiled step).

    Parameters
    ----------
    estimator : StreamingEstimator
        Its model, parameters, crank filter and validity indicator.
    stepper, gate, record, base_flags
        Its step, input gate, record array and the flags of every sample.

    """
    rate_filter, nonlinearity = estimator.rate_filter, estimator.nonlinearity
    if not (native.impl is not None and stepper.compiled and hasattr(rate_filter, 'state')
            and (nonlinearity.compiled or not nonlinearity.available)
            and estimator.model.dynamic_second_order is None):     # its pass: Python path
        return PythonUpdate()
    limits = {'speed_max': float(estimator.model.speed_max),
              'accel_limit': estimator.accel_limit, 'large_step_s': estimator.large_step_s,
              'near_zero_fraction': estimator.near_zero_fraction,
              'deflection_bound_m': estimator.deflection_bound_m, 'base_flags': base_flags}
    return CompiledUpdate(stepper, rate_filter, gate, nonlinearity, record, limits)


def use_python_path(estimator):
    """Send every sample of a StreamingEstimator to the Python path (comparisons, benchmarks)."""
    estimator.use_python_path()


def compiled_samples(estimator):
    """Count the samples of a StreamingEstimator that the compiled path estimated."""
    return estimator.compiled_samples


class PythonUpdate:
    """Stands in for :class:`CompiledUpdate` where it cannot serve: every sample goes to Python."""

    compiled = False
    taken = 0

    @staticmethod
    def sample(stamp_ns, crank_angle, crank_speed):
        """Return None: the Python path takes every sample."""
        return None

    def fall_back(self, gate):
        """Do nothing (the gate keeps its own reference)."""

    def arm(self, reference, stamp0_ns):
        """Do nothing."""

    def disarm(self):
        """Do nothing."""

    deflection_bound = property(lambda self: math.nan, lambda self, value: None,
                                doc='Not used.')


class CompiledUpdate:
    """
    The compiled update of one estimator: its tables, its state arrays and its parameters.

    Parameters
    ----------
    stepper : CompiledStep
        The estimator's step (its tables, z and last crank state).
    rate_filter : CompiledCrankRateFilter
        The estimator's crank filter (its state array).
    gate : InputGate
        The estimator's gate (its thresholds).
    nonlinearity : NonlinearityIndicator
        The estimator's validity indicator (its compiled tables, or none).
    record : ndarray
        The estimator's record (RECORD_SIZE values, written in place).
    limits : dict
        speed_max, accel_limit, large_step_s, near_zero_fraction, deflection_bound_m and
        base_flags of the estimator.

    """

    compiled = True

    def __init__(self, stepper, rate_filter, gate, nonlinearity, record, limits):
        t = stepper.tables
        self._kernel = native.impl.Update(
            tables=(t.mass, t.damping, t.kf, t.out, t.joint, t.g0), second=t.second_packed,
            lift=stepper.lift_buffers,
            cells_per_radian=stepper.cells_per_radian, c1=STAGE1, z=stepper.z,
            prev=stepper.previous, filter=rate_filter.state, record=record,
            indicator=nonlinearity.kernel_tables, sample_type=Sample,
            sample_fields=tuple(field.name for field in dataclasses.fields(Sample)),
            speed_max=limits['speed_max'], accel_limit=limits['accel_limit'],
            large_step_s=limits['large_step_s'], reset_gap_s=gate.reset_gap_s,
            speed_bound=gate.speed_bound, jump_accel=gate.jump_accel,
            jump_allowance=gate.jump_allowance, angle_allowance=ANGLE_ALLOWANCE_RAD,
            near_zero_fraction=limits['near_zero_fraction'],
            floor_fraction=REACTION_FLOOR_FRACTION,
            deflection_bound=limits['deflection_bound_m'], error_floor=ERROR_INDICATOR_FLOOR_M,
            max_substep_ns=MAX_SUBSTEP_NS, base_flags=limits['base_flags'],
            flags=(LARGE_STEP, CLIPPED_SPEED, CLIPPED_ACCEL, SPEED_FROM_ANGLE))
        # The C method itself: the estimator calls it once per sample.
        self.sample = self._kernel.sample

    def fall_back(self, gate):
        """Before the Python path takes a sample: give the gate its reference back, disarm."""
        if self._kernel.armed:
            gate.last = self._kernel.reference()
            self._kernel.disarm()

    def arm(self, reference, stamp0_ns):
        """
        Let the compiled path take the next samples.

        Parameters
        ----------
        reference : tuple
            The gate's last accepted sample (stamp_ns, angle, speed or None).
        stamp0_ns : int
            The crank filter's time origin (the estimate's start) [ns].

        """
        try:
            self._kernel.arm(*reference, stamp0_ns)
        except OverflowError:   # stamps beyond int64: the Python path keeps them
            self._kernel.disarm()

    def disarm(self):
        """Leave every sample to the Python path until :meth:`arm`."""
        self._kernel.disarm()

    armed = property(lambda self: bool(self._kernel.armed),
                     doc='Whether the compiled path takes the next sample.')
    taken = property(lambda self: self._kernel.taken,
                     doc='Samples the compiled path estimated.')
    fills_slots = property(lambda self: self._kernel.fills_slots >= 0,
                           doc='Whether Samples are written into their slots (else Sample is '
                               'called).')
    fallback = property(lambda self: FALLBACK_REASONS[self._kernel.fallback],
                        doc="Why the last sample went to the Python path ('none' if not).")

    @property
    def deflection_bound(self):
        """Give the estimator's deflection bound [m] that the compiled path checks."""
        return self._kernel.deflection_bound

    @deflection_bound.setter
    def deflection_bound(self, value):
        self._kernel.deflection_bound = value
