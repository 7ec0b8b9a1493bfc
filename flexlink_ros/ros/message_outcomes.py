"""
What becomes of each message flexlink_node receives, without rclpy.

The crank sample read from a JointState's CDR (or the refusal that says why not), whether an
estimate may be published, and the counts of every outcome the node keeps, in total and per
diagnostics period, with the log of samples estimated at a clipped speed.
"""

import dataclasses
import math
import time

from .messages import crank_from_joint_state
from ..core.estimation.sample import CLIPPED_SPEED, OUT_OF_BOUND, SampleFlag
from ..core.numerics import RPM
from ..errors import InputRejected, MalformedCdr
from ..io import cdr

MAX_REASON_CHARS = 200   # a refusal's reason as logged and in /diagnostics
# What happens to a received message (counted per kind, in total and per diagnostics period).
SKIP_KINDS = ('malformed', 'content', 'estimator', 'internal')   # counted as 'skipped'
# 'inactive': delivered after deactivate or cleanup (queued before it), not estimated.
OTHER_KINDS = ('outlier', 'conflicting', 'repeated', 'out_of_bound', 'inactive')
# Flags after which the estimate is not to be trusted blindly: the estimator status is WARN.
WARN_FLAGS = (SampleFlag.CLIPPED_SPEED | SampleFlag.CLIPPED_ACCEL | SampleFlag.OUTLIER
              | SampleFlag.COLD_START)


def one_line(text):
    """Return the first line of ``text``, cut to MAX_REASON_CHARS."""
    lines = str(text).strip().splitlines()
    line = lines[0] if lines else ''
    return line if len(line) <= MAX_REASON_CHARS else line[:MAX_REASON_CHARS - 3] + '...'


def crank_sample(data, joint_name, deserialize, read=None):
    """
    Read stamp, angle and speed of the crank from JointState CDR; InputRejected says why not.

    The fast parser (cdr.parse_joint_state, or a cdr.JointStateReader of the stream) checks
    the bytes against the input bounds; only a message without a usable sample is
    deserialised by rclpy, to name what is wrong, and an error there (rclpy raises RMWError
    on truncated CDR) is a refusal too.

    Parameters
    ----------
    data : bytes
        CDR of a ``sensor_msgs/JointState``.
    joint_name : str
        Name of the crank joint.
    deserialize : callable
        bytes -> sensor_msgs.msg.JointState (rclpy's deserialize_message).
    read : callable or None
        bytes -> (stamp_ns, angle, speed) of the joint, as cdr.parse_joint_state returns
        them (the node's cdr.JointStateReader); None: cdr.parse_joint_state.

    Returns
    -------
    stamp_ns : int
    angle : float
    speed : float or None

    Raises
    ------
    errors.InputRejected
        With ``kind`` 'malformed' or 'content' and a one-line reason.

    """
    try:
        stamp_ns, angle, speed = (read(data) if read is not None
                                  else cdr.parse_joint_state(data, joint_name.encode()))
    except MalformedCdr as exc:
        raise InputRejected(f'malformed JointState: {one_line(exc)}', 'malformed') from None
    if angle is None or not math.isfinite(angle) or (
            speed is not None and not math.isfinite(speed)):
        try:
            message = deserialize(data)
        except (RuntimeError, ValueError, TypeError, MemoryError) as exc:  # RMWError: Runtime
            raise InputRejected(f'malformed JointState ({type(exc).__name__}): '
                                f'{one_line(exc)}', 'malformed') from None
        stamp_ns, angle, speed = crank_from_joint_state(message, joint_name)
    if stamp_ns <= 0:
        raise InputRejected('zero stamp (the publisher does not stamp its messages)'
                            if stamp_ns == 0 else f'negative stamp {stamp_ns} ns')
    return stamp_ns, angle, speed


def publishable(sample):
    """
    Say why a Sample's numbers may not be published (None if they may).

    The estimator flags OUT_OF_BOUND every estimate beyond its deflection bound or not finite
    (a non-finite state makes the deflections non-finite), so the flag is the one test.

    Parameters
    ----------
    sample : core.estimation.sample.Sample
        One estimate.

    """
    if sample.flags & OUT_OF_BOUND:
        return sample.message or "deflection beyond the model's bound"
    return None


class ClippedSpeedLog:
    """
    Samples estimated at a speed clipped to the model's range: counted, said once a second.

    Throttled by its own clock, not by the logger's: a logger call costs tens of us, and
    clipping comes on every sample of a crank beyond the range.

    Parameters
    ----------
    warn : callable
        Called with the warning sentence.
    running : callable
        False once the node shuts down (then nothing is logged).
    speed_max : float
        The model's speed range [rad/s].
    throttle_s : float
        Least time between two warnings [s] (the node's other warnings: once a second).

    """

    def __init__(self, warn, running, speed_max, throttle_s=1.0):
        self.count = 0
        self._warn, self._running = warn, running
        self._speed_max, self._throttle_s = speed_max, throttle_s
        self._said = -math.inf

    def add(self, sample):
        """Count ``sample`` if its speed was clipped; warn at most once per throttle period."""
        if not sample.flags & CLIPPED_SPEED:
            return
        self.count += 1
        now = time.monotonic()
        if now - self._said < self._throttle_s or not self._running():
            return
        self._said = now
        self._warn(f'crank at {abs(sample.crank_speed) / RPM:.0f} rpm, beyond the speed range '
                   f'of the model of {self._speed_max / RPM:.0f} rpm: {self.count} samples so '
                   'far estimated at the clipped speed (too small); restart with '
                   "model.speed_max_rpm above the crank's speed")


@dataclasses.dataclass
class Totals:
    """What became of every received message since the node started."""

    received: int = 0
    rejected: int = 0       # skipped (SKIP_KINDS)
    published: int = 0
    counts: dict = dataclasses.field(
        default_factory=lambda: dict.fromkeys(SKIP_KINDS + OTHER_KINDS, 0))   # kind -> messages
    last_rejection: str = ''
    last_outlier: str = ''


@dataclasses.dataclass
class PeriodStats:
    """What happened since the last /diagnostics message."""

    valid: int = 0
    rejected: int = 0
    counts: dict = dataclasses.field(default_factory=dict)   # kind -> messages
    last_out_of_bound: str = ''
    update_ns: list = dataclasses.field(default_factory=list)
    max_error_indicator: float = 0.0
    max_nonlinearity: float = -math.inf     # validity indicator (NaN samples left out)
    max_criterion: list = dataclasses.field(default_factory=lambda: [0.0] * 4)
    near_zero: list = dataclasses.field(default_factory=lambda: [False] * 4)
    flags: int = 0

    def add_sample(self, sample, validity=None):
        """
        Count a published sample: its flags, error and validity indicators, joint criteria.

        Parameters
        ----------
        sample : core.estimation.sample.Sample
            The estimate published.
        validity : float or None
            The published validity indicator (the nonlinear model's where it made the
            deflections); None: the sample's.

        """
        self.valid += 1
        self.flags |= sample.flags
        self.max_error_indicator = max(self.max_error_indicator, sample.error_indicator)
        validity = sample.nonlinearity if validity is None else validity
        if validity > self.max_nonlinearity:
            self.max_nonlinearity = validity
        for j, value in enumerate(sample.criterion):
            if value > self.max_criterion[j]:
                self.max_criterion[j] = value
            self.near_zero[j] = self.near_zero[j] or sample.near_zero[j]
