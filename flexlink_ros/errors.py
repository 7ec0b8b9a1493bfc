"""
Errors of flexlink_ros.

Every error the core raises on purpose is a :class:`FlexlinkError`. The node logs one and
keeps running; the CLI prints it on one line and exits 1. Bad arguments raise ``ValueError``
naming the argument.
"""


class FlexlinkError(Exception):
    """Root of the errors raised by flexlink_ros."""


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
        import math
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


class OutlierSample(FlexlinkError):
    """
    Raised for an input sample the crank cannot have produced (counted and skipped).

    A speed beyond the mechanism's plausible range, or a change of speed or angle the crank
    cannot make in the sample interval. ``reason`` is one line naming the test it failed.
    """

    def __init__(self, reason):
        self.reason = reason
        super().__init__(f'outlier: {reason}')
