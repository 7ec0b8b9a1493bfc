"""
The compiled per-sample step (_radau_step.c): the one place that loads it, and its layouts.

``impl`` is the extension module, or None in a source tree that was not built; then the numpy
twins run (:class:`~.crank_filter.CrankRateFilter`, :class:`~.step.NumpyStep`). They are not
a stub module with the extension's call signatures: they keep their state in objects (the
filter's fits, the step's alternating slots) and an estimator picks them with
``compiled=False`` even where the extension is built (the tests compare the two paths).

The layouts the C code shares with Python are defined here once: the crank filter's state
(``enum F_*`` in the C file; a test parses it), a sample's record and a step row.
"""

from ...names import JOINT_NAMES, OUTPUT_NAMES

try:
    from . import _radau_step as impl
except ImportError:     # not built: the numpy step serves
    impl = None

# The compiled filter's state (enum F_* of _radau_step.c): started, time, unwrapped angle,
# mode (0 none, 1 speed, 2 angle), speed, accel, advance, mean step, time constant, minimum
# samples, then the speed and the angle fit (s0..s4, t0..t2, count each).
FILTER_STARTED, FILTER_TIME, FILTER_ANGLE, FILTER_MODE = 0, 1, 2, 3
FILTER_SPEED, FILTER_ACCEL, FILTER_ADVANCE, FILTER_MEAN_DT = 4, 5, 6, 7
FILTER_TC, FILTER_MIN_SAMPLES, FILTER_SPEED_FIT = 8, 9, 10
FIT_SIZE = 9            # s0..s4, t0..t2, count
FILTER_ANGLE_FIT = FILTER_SPEED_FIT + FIT_SIZE
FILTER_STATE = FILTER_ANGLE_FIT + FIT_SIZE
FIT_COUNT = 8           # offset of a fit's sample count
MODE_SPEED = 1.0        # FILTER_MODE of a filter fed measured speeds

# A sample's record (the compiled step's output; its numpy twin is _StepTables.record):
# deflections with the residual correction and, for a model of order 2, the second-order
# motion (outputs), the correction alone (outputs), joint
# reactions (joints x 2), their time derivative (joints x 2) and squared cycle-RMS reactions
# (joints).
RECORD_SIZE = 2 * len(OUTPUT_NAMES) + 5 * len(JOINT_NAMES)
# A step row: step h [s], sub-steps, crank angle, speed, acceleration, angle advance.
ROW_SIZE = 6


def compiled_step_available():
    """Tell whether the compiled step (_radau_step.c) is built and estimators use it."""
    return impl is not None
