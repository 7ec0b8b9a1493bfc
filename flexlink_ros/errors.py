"""
Errors of flexlink_ros.

Every error the core raises on purpose is a :class:`FlexlinkError`. The node logs one and
keeps running; the CLI prints it on one line and exits with its ``exit_code`` (1; 2 for a bag
still being recorded). Bad arguments raise ``ValueError``
naming the argument.
"""

import math
import struct


class FlexlinkError(Exception):
    """Root of the errors raised by flexlink_ros."""

    exit_code = 1   # of the CLI when it stops on this error


class MechanismError(FlexlinkError):
    """Raised if a mechanism file or definition is invalid; names the offending field."""

    def __init__(self, field, reason):
        self.field = field
        self.reason = reason
        super().__init__(f'{field}: {reason}')


class LoopClosureError(FlexlinkError):
    """Raised if the linkage cannot assemble (or is singular) at a crank angle."""

    def __init__(self, crank_angle_rad, reason):
        self.crank_angle_rad = crank_angle_rad
        self.reason = reason
        super().__init__(
            f'linkage cannot assemble at crank angle {math.degrees(crank_angle_rad):.3f} deg: '
            f'{reason}')


class ConvergenceError(FlexlinkError):
    """Raised if an iterative solve does not reach its tolerance."""

    def __init__(self, what, iterations, residual):
        self.what = what
        self.iterations = iterations
        self.residual = residual
        super().__init__(f'{what} did not converge in {iterations} iterations '
                         f'(residual {residual:.3g})')


class CacheError(FlexlinkError):
    """Raised if a precomputed-model cache file is corrupt, stale or foreign."""


class RecorderError(FlexlinkError):
    """Raised if the MCAP recorder cannot write (unwritable path, full disk, closed file)."""


class BagInUse(RecorderError):
    """Raised if a bag directory is locked by the recorder that is still writing it."""

    exit_code = 2


class OutlierSample(FlexlinkError):
    """
    Raised for an input sample the crank cannot have produced (counted and skipped).

    A speed beyond the mechanism's plausible range, or a change of speed or angle the crank
    cannot make in the sample interval. ``reason`` is one line naming the test it failed.
    """

    def __init__(self, reason):
        self.reason = reason
        super().__init__(f'outlier: {reason}')


class ConflictingSample(FlexlinkError):
    """
    Raised for a sample with the stamp of the last accepted one but another angle (skipped).

    Two readings cannot both be the crank at one instant: the first stays, this one is
    counted and skipped (not taken as a restart, which would publish its angle).
    """

    def __init__(self, reason):
        self.reason = reason
        super().__init__(f'conflicting: {reason}')


class McapFileError(FlexlinkError):
    """Raised if a file is not an MCAP file at all (its reason names why)."""


class DamagedRecord(FlexlinkError):
    """Raised if a record cannot be used; the message is the one-line reason (always caught)."""


class MalformedCdr(FlexlinkError, struct.error, ValueError):
    """Raised if bytes are not a JointState within the input bounds; the message says why."""


class InputRejected(FlexlinkError, ValueError):
    """
    Raised if a JointState cannot be used; the message says why (counted and skipped).

    Parameters
    ----------
    reason : str
        One line.
    kind : str
        ``'malformed'`` (not a JointState within the input bounds) or ``'content'`` (a
        JointState without a usable crank sample); the node counts them apart.

    """

    def __init__(self, reason, kind='content'):
        super().__init__(reason)
        self.kind = kind


# Not an error: the node's orderly exit on SIGINT/SIGTERM before it spins.
class StartupInterrupted(SystemExit):
    """SIGINT/SIGTERM before the node spins: exit code 0 (raised in the main thread)."""

    def __init__(self, signal_name):
        super().__init__(0)
        self.signal_name = signal_name
