"""
Streaming estimation of the linkage's elastic response, one crank sample at a time.

:class:`StreamingEstimator` gates each (stamp, crank angle[, crank speed]) sample
(:class:`~.gate.InputGate`), turns it into the crank's unwrapped angle, speed and acceleration
(:class:`~.crank_filter.CrankRateFilter`), advances the reduced model (core/reduction) by one
Radau IIA step (:mod:`.step`, compiled where built) and returns a :class:`~.sample.Sample`
with the deflections, the joint criteria, the validity indicator and flags (all of it in one
compiled call for an ordinary sample: :mod:`.compiled_update`). Implausible samples are
refused (:class:`OutlierSample`, the state untouched); an estimate beyond the model's
deflection bound, or a non-finite one, is flagged OUT_OF_BOUND (NaN deflections) and the
next sample restarts.
"""

import dataclasses
import logging
import math

import numpy as np

from . import tables
from .compiled_update import compiled_update, PythonUpdate
from .crank_filter import CompiledCrankRateFilter, CrankRateFilter, DEFAULT_FIT_TIME_CONSTANT_S
from .gate import DEFAULT_RESET_GAP_S, InputGate
from .native import compiled_step_available, RECORD_SIZE, ROW_SIZE
from .nonlinearity import NonlinearityIndicator
from .sample import (CLIPPED_ACCEL, CLIPPED_SPEED, LARGE_STEP, nan_sample, NO_CRITERIA,
                     OUT_OF_BOUND, REPEATED, sample_from_record, SPEED_FROM_ANGLE)
from .second_order_dynamic_step import step_for_model
from .step import MAX_SUBSTEP_NS
from .throttled_log import ThrottledWarning
from .warm_start import WarmStart
from ...errors import ConflictingSample, FlexlinkError, OutlierSample
from ...names import JOINT_NAMES, OUTPUT_NAMES

LOGGER = logging.getLogger(__name__)

# A step longer than this is flagged as large (accuracy degrades; still stable) [s].
DEFAULT_LARGE_STEP_S = 0.01
# Crank accelerations beyond this are clipped (speed steps give filter spikes) [rad/s^2].
DEFAULT_ACCEL_LIMIT = 5000.0
# A joint reaction below this fraction of its cycle RMS at the current speed is "near zero".
DEFAULT_NEAR_ZERO_FRACTION = 0.05
# Deflection bound: this factor times the resonant amplification 1 / (2 zeta) times the
# largest quasi-static deflection over the grid at constant speeds up to speed_max.
DEFLECTION_SAFETY_FACTOR = 2.0


class StreamingEstimator:
    """
    Elastic deflections and joint criteria of the linkage, one crank sample at a time.

    Parameters
    ----------
    model : ReducedModel
        Precomputed reduced model (core/reduction).
    fit_time_constant_s : float
        Time constant of the crank-rate filter [s].
    warm_start : bool
        Start (and restart) from the periodic steady state at the current speed, so the
        output is right from the first revolution; otherwise from the static deflection.
    large_step_s : float
        Steps longer than this are flagged LARGE_STEP [s].
    reset_gap_s : float
        Gaps longer than this restart the estimate [s].
    accel_limit : float
        |crank acceleration| clip [rad/s^2].
    near_zero_fraction : float
        Reaction below this fraction of its cycle RMS flags the joint as near zero.
    compiled : bool
        Use the compiled step when it is built (see :func:`compiled_step_available`);
        False runs the numpy step (the same numbers to rounding).
    step_tables : object or None
        :func:`step_tables` of ``model``, to share between estimators of one model (they
        are read only); built here if None.
    warm_start_limiter : WarmStartLimiter or None
        Rate limit of the warm starts that shoot; a new one (wall clock) if None.

    Attributes
    ----------
    deflection_bound_m : float
        Largest |deflection component| published as a number [m]: DEFLECTION_SAFETY_FACTOR
        / (2 zeta) times the largest quasi-static deflection over the grid at constant
        speeds up to speed_max (:meth:`quasi_static_peak`); beyond it OUT_OF_BOUND.
    outliers, out_of_bound, warm_starts, cold_starts : int
        Samples refused as outliers, estimates out of bound (or non-finite), warm starts
        that shot, and warm starts the rate limit turned into cold starts.

    """

    def __init__(self, model, fit_time_constant_s=DEFAULT_FIT_TIME_CONSTANT_S,
                 warm_start=True, large_step_s=DEFAULT_LARGE_STEP_S,
                 reset_gap_s=DEFAULT_RESET_GAP_S, accel_limit=DEFAULT_ACCEL_LIMIT,
                 near_zero_fraction=DEFAULT_NEAR_ZERO_FRACTION, compiled=True,
                 step_tables=None, warm_start_limiter=None):
        for name, value in (('large_step_s', large_step_s), ('reset_gap_s', reset_gap_s),
                            ('accel_limit', accel_limit)):
            if not value > 0.0:
                raise ValueError(f'`{name}` must be positive, got {value!r}')
        if not 0.0 <= near_zero_fraction < 1.0:
            raise ValueError(f'`near_zero_fraction` must be in [0, 1), got {near_zero_fraction!r}')
        self.model = model
        self.warm_start = bool(warm_start)
        self.large_step_s = float(large_step_s)
        self.reset_gap_s = float(reset_gap_s)
        self.accel_limit = float(accel_limit)
        self.near_zero_fraction = float(near_zero_fraction)
        compiled = compiled and compiled_step_available()
        self.rate_filter = (CompiledCrankRateFilter if compiled else CrankRateFilter)(
            fit_time_constant_s)
        self._speed_max = float(model.speed_max)
        # Without reaction data (core/dynamics.py absent at precompute) report zeros, flagged.
        self._base_flags = 0 if np.any(model.force_moments) else NO_CRITERIA
        if len(JOINT_NAMES) != 4:
            raise ValueError('the criteria path is written for four joints')
        self._tables = tables.step_tables(model) if step_tables is None else step_tables
        if (self._tables.size, self._tables.mass.shape[0]) != (model.step_size, model.grid_size):
            raise ValueError('`step_tables` do not match the model (size and grid)')
        self._stepper = step_for_model(model, self._tables, compiled)   # dynamic: its own
        self._record = np.zeros(RECORD_SIZE)
        self._row = np.zeros(ROW_SIZE)  # the step row: h, sub-steps, crank state, advance
        self._no_states = np.empty(0)
        self._last = None
        self._stamp0_ns = None
        self._pending_warm_start = False
        self.samples = 0
        self.outliers = self.out_of_bound = 0
        self._gate = InputGate(self._speed_max, self.accel_limit, self.reset_gap_s)
        self._warm = WarmStart(warm_start_limiter)
        self._bound_warning = ThrottledWarning(LOGGER)
        self._bound_m = self._tables.deflection_bound(model, DEFLECTION_SAFETY_FACTOR)
        self.nonlinearity = NonlinearityIndicator(model)
        # The common path of update() in one compiled call where it can serve; else Python.
        self._compiled = compiled_update(self, self._stepper, self._gate, self._record,
                                         self._base_flags)

    def _set_bound(self, bound_m):
        self._bound_m = self._compiled.deflection_bound = bound_m

    deflection_bound_m = property(lambda self: self._bound_m, _set_bound,
                                  doc='The deflection bound [m] (see the class docstring).')
    compiled = property(lambda self: self._stepper.compiled,
                        doc='Whether this estimator steps with the compiled kernel.')
    warm_start_limiter = property(lambda self: self._warm.limiter,
                                  doc='Rate limit of the warm starts that shoot.')
    warm_starts = property(lambda self: self._warm.warm_starts, doc='Warm starts that shot.')
    cold_starts = property(lambda self: self._warm.cold_starts,
                           doc='Warm starts the rate limit turned into cold starts.')

    orbit = property(lambda self: self._warm.orbit,
                     lambda self, orbit: setattr(self._warm, 'orbit', orbit),
                     doc='The kept periodic orbit: (speed, start angle, q, v) of the last '
                         'shooting. Given to another estimator of the model, it restarts '
                         'there without shooting.')
    state = property(lambda self: self._stepper.state,
                     doc="(q, q') of the newest sample (a view; the reduced model's r).")
    last_record = property(lambda self: self._record,
                           doc='Record of the newest sample (RECORD_SIZE values; overwritten '
                               'by the next sample): deflections, the residual correction, '
                               'joint reactions, their rates and cycle RMS.')

    def reset(self):
        """Forget the state; the next sample starts afresh."""
        self._compiled.disarm()
        self._gate.reset()
        self._restart()

    def _restart(self):
        """Forget the filter and the model state (the gate keeps its reference)."""
        self.rate_filter.reset()
        self._last = None
        self._pending_warm_start = False

    def quasi_static_peak(self, speed_max=None):
        """
        Return the largest |deflection component| of the quasi-static response over the grid [m].

        At constant speeds up to ``speed_max`` [rad/s] (default: the model's range). See
        :func:`~.tables.quasi_static_peak`; the deflection bound is
        DEFLECTION_SAFETY_FACTOR / (2 zeta) times it over the whole range.
        """
        return self._tables.quasi_static_peak(self.model, speed_max)

    def periodic_state(self, angle, speed):
        """
        Return (q, v) of the periodic steady state at crank ``angle`` and constant ``speed``.

        Shooting over one revolution, or the kept orbit interpolated (see
        :meth:`~.warm_start.WarmStart.periodic_state`).
        """
        return self._warm.periodic_state(self.model, self.system_blocks, angle, speed)

    def system_blocks(self, theta, w, a):
        """
        Return M, C, K, f at crank angles ``theta`` (array), speed ``w``, acceleration ``a``.

        From the step tables (:func:`~.tables.system_blocks`), so the estimator needs nothing
        of the model's full table: see :meth:`release_model_table`.
        """
        return tables.system_blocks(self.model, self._tables, theta, w, a)

    def release_model_table(self):
        """
        Drop this estimator's reference to the model's full table (tens of MB).

        Streaming, warm starts and link shapes need only the step tables and the shape
        table; ``model.evaluate`` of the model this estimator then holds returns rows of zero
        width. For a process that only streams (the node), which must drop its own references
        to the model too (it gets the released model back).
        """
        empty = np.empty((self.model.grid_size,) + self.model.table.shape[1:2] + (0,))
        self.model = dataclasses.replace(self.model, table=empty)
        return self.model

    def use_python_path(self):
        """Send every later sample to the Python path (comparisons, benchmarks)."""
        self._compiled = PythonUpdate()

    @property
    def compiled_samples(self):
        """Count the samples the compiled path estimated."""
        return self._compiled.taken

    def _set_state(self, angle, speed, accel, warm):
        """Start from the periodic state at this speed (warm) or the static deflection."""
        q0, v0, flags = self._warm.initial_state(self.model, self.system_blocks,
                                                 (angle, speed, accel), warm)
        self._stepper.start(q0, v0, (angle, speed, accel), self._record)
        return flags

    def update(self, stamp_ns, crank_angle, crank_speed=None):
        """
        Add one crank sample and return the estimate at its stamp.

        Parameters
        ----------
        stamp_ns : int
            Sample time [ns].
        crank_angle : float
            Crank angle [rad], any range (wrapped here).
        crank_speed : float or None
            Measured crank speed [rad/s]; None (or NaN) to derive it from angles.

        Returns
        -------
        Sample
            Flagged OUT_OF_BOUND (deflections NaN, the state reset) when the estimate left
            :attr:`deflection_bound_m` or went non-finite.

        Raises
        ------
        OutlierSample, ConflictingSample
            Implausible, or the last stamp with another angle; nothing of the state changed.

        """
        sample = self._compiled.sample(stamp_ns, crank_angle, crank_speed)
        if sample is not None:      # an ordinary sample, estimated in one compiled call
            self._last = sample
            self.samples += 1
            return sample
        self._compiled.fall_back(self._gate)        # the Python path: the gate's own state
        angle_in = float(crank_angle)
        if not math.isfinite(angle_in):
            raise ValueError(f'`crank_angle` must be finite, got {crank_angle!r}')
        if crank_speed is not None:
            crank_speed = float(crank_speed)
            if math.isnan(crank_speed):
                crank_speed = None
        stamp_ns = int(stamp_ns)
        kind, flags, message = self._gate.decide(stamp_ns, angle_in, crank_speed)
        if kind in (InputGate.OUTLIER, InputGate.CONFLICTING):
            self.outliers += kind == InputGate.OUTLIER
            raise (OutlierSample if kind == InputGate.OUTLIER else ConflictingSample)(message)
        if kind == InputGate.REPEATED:
            return dataclasses.replace(self._last, flags=self._last.flags | REPEATED,
                                       message=message)
        if kind == InputGate.START:
            if message:
                LOGGER.warning('estimator reset: %s', message)
            self._restart()
            return self._start(stamp_ns, angle_in, crank_speed, flags, message)
        return self._advance_to(stamp_ns, angle_in, crank_speed, flags, message)

    def _start(self, stamp_ns, angle_in, crank_speed, flags, message):
        """Start afresh at a sample: the filter's first sample, a warm or static state."""
        self._stamp0_ns = int(stamp_ns)
        angle, speed, accel = self.rate_filter.update(0.0, angle_in, crank_speed)
        if crank_speed is None:
            flags |= SPEED_FROM_ANGLE
        model_speed = max(-self._speed_max, min(self._speed_max, speed))
        if model_speed != speed:
            flags |= CLIPPED_SPEED
        warm = self.warm_start and crank_speed is not None
        try:
            flags |= self._set_state(angle, model_speed, 0.0, warm)
        except (ValueError, FlexlinkError) as exc:    # singular K or a failed shooting
            return self._out_of_bound(stamp_ns, angle, speed, accel, flags, str(exc))
        self._pending_warm_start = self.warm_start and crank_speed is None
        return self._finish(stamp_ns, angle, speed, accel, flags, message)

    def _advance_to(self, stamp_ns, angle_in, crank_speed, flags, message):
        """Step the model from the last sample to this one (or take the deferred warm start)."""
        dt_ns = stamp_ns - self._last.stamp_ns
        dt = dt_ns * 1e-9
        angle, speed, accel = self.rate_filter.update((stamp_ns - self._stamp0_ns) * 1e-9,
                                                      angle_in, crank_speed)
        if crank_speed is None:
            flags |= SPEED_FROM_ANGLE
        if dt > self.large_step_s:
            flags |= LARGE_STEP
        if not (math.isfinite(angle) and math.isfinite(speed) and math.isfinite(accel)):
            return self._out_of_bound(stamp_ns, angle, speed, accel, flags,
                                      'non-finite crank filter state')
        model_speed, model_accel = speed, accel
        if abs(speed) > self._speed_max:
            model_speed = math.copysign(self._speed_max, speed)
            flags |= CLIPPED_SPEED
        if abs(accel) > self.accel_limit:
            model_accel = math.copysign(self.accel_limit, accel)
            flags |= CLIPPED_ACCEL
        try:
            if self._pending_warm_start and self.rate_filter.count >= 3:
                self._pending_warm_start = False
                flags |= self._set_state(angle, model_speed, model_accel, True)
            else:
                self._row[:] = (dt, -(-dt_ns // MAX_SUBSTEP_NS), angle, model_speed,
                                model_accel, self.rate_filter.advance)
                self.step_rows(self._row, self._no_states, self._record)
        except (ValueError, FlexlinkError) as exc:    # singular or non-finite step
            return self._out_of_bound(stamp_ns, angle, speed, accel, flags, str(exc))
        return self._finish(stamp_ns, angle, speed, accel, flags, message)

    def step_rows(self, rows, states, records):
        """
        Advance the model through sample rows (h, sub-steps, angle, speed, accel, advance).

        The compiled step in one call, or the numpy step row by row. The offline replay
        steps whole chunks of a recording this way, after :meth:`update` started them.

        Parameters
        ----------
        rows : ndarray
            ROW_SIZE values per row: step h [s], sub-steps (MAX_SUBSTEP_NS), the model's
            crank angle, speed and acceleration, and the angle advance.
        states : ndarray
            Empty, or rows x 2 r: z[:2 r] = (q, v) after each row.
        records : ndarray
            Rows x RECORD_SIZE, or one record (of the last row).

        """
        self._stepper.advance(rows, states, records)

    def _out_of_bound(self, stamp_ns, angle, speed, accel, flags, message):
        """Return a sample flagged OUT_OF_BOUND, not a number to publish; reset the state."""
        self.out_of_bound += 1
        self._bound_warning.warn('estimate out of bound, state reset: %s (%d so far)', message,
                                 self.out_of_bound)
        sample = nan_sample(stamp_ns, (angle, speed, accel),
                            flags | OUT_OF_BOUND | self._base_flags, message, self.model.size)
        self.samples += 1
        self.reset()
        return sample

    def _finish(self, stamp_ns, angle, speed, accel, flags, message):
        """Return the sample of the new state (OUT_OF_BOUND beyond the deflection bound)."""
        values = self._record.tolist()
        outputs = len(OUTPUT_NAMES)
        deflection = values[:outputs]
        correction = values[outputs:2 * outputs]
        criteria = self._stepper.criteria(self._record, self.near_zero_fraction)
        largest = max([abs(d) for d in deflection])
        if not largest <= self.deflection_bound_m:     # also NaN
            return self._out_of_bound(
                stamp_ns, angle, speed, accel, flags,
                f'deflection {largest:.6g} m beyond the bound {self.deflection_bound_m:.6g} m')
        state = self.state
        sample = sample_from_record(
            stamp_ns, (angle, speed, accel), deflection, correction, criteria,
            flags | self._base_flags, message, tuple(state[:self.model.size].tolist()),
            self.nonlinearity(angle, speed, min(max(accel, -self.accel_limit), self.accel_limit),
                              state))
        self._last = sample
        self.samples += 1
        if not self._pending_warm_start:    # the gate accepted it with nothing pending
            self._compiled.arm(self._gate.last, self._stamp0_ns)
        return sample

    def link_shapes(self, sample):
        """
        Return rigid positions and elastic deflections of points along each link at a sample.

        Parameters
        ----------
        sample : Sample
            An estimate of this estimator.

        Returns
        -------
        positions, deflections : ndarray, shape (3, points, 2)
            Ground frame [m]; at order 2 with the joints' second-order motion.

        """
        modal = np.array(sample.modal)
        positions, deflections = self.model.shapes(sample.crank_angle, modal)
        if self._tables.second is not None:
            cells, t = self.model.cell(sample.crank_angle)
            deflections = deflections + self._tables.second.link_motion(
                cells, t, modal[None], deflections.shape[1])[0]
        return positions, deflections
