"""
How far a model build is: a percentage from the eigenproblems and damping matrices done.

A build (:func:`.mechanism_model.build_model`) spends most of its time in two loops over the grid:
the frozen eigenproblems of the basis snapshots (:func:`.basis.build_basis`, per angle and
basis speed) and the modal damping matrices (:func:`.build.project_system`, per angle and
damping speed). :class:`BuildProgress` hands the build samples that count both, weighted by
their cost, and reports ``progress(percent, 100, what)``; the caller decides how to show it.
"""

import dataclasses
import inspect

from .basis import FrozenSamples
from .build import reduce_samples

# A basis snapshot's frozen eigenproblem costs about three damping matrices (measured on the
# node's default cho1992 model: 11 ms and 4 ms).
BASIS_WEIGHT = 3
# Percent reported once the full-order pieces are assembled, and reached by the two loops;
# the projections, tables and the cache file take the rest.
ASSEMBLED_PERCENT = 5.0
LOOPS_END_PERCENT = 90.0
BASIS_STEP = 'reduced basis (frozen modes)'
DAMPING_STEP = 'projected damping'


@dataclasses.dataclass(frozen=True)
class FollowedSamples(FrozenSamples):
    """FrozenSamples that count each frozen eigenproblem asked of them."""

    tracker: object = None

    def frozen_at(self, k, w, a=0.0):
        """Stiffness of the frozen eigenproblem (counted as one basis snapshot)."""
        self.tracker.step(BASIS_WEIGHT, BASIS_STEP)
        return super().frozen_at(k, w, a)


class BuildProgress:
    """
    Follow one model build and report its percentage.

    Parameters
    ----------
    report : callable or None
        ``report(percent, 100, what)``; None follows nothing.
    grid_size : int
        Crank-angle grid points of the build.

    """

    def __init__(self, report, grid_size):
        defaults = inspect.signature(reduce_samples).parameters
        basis = grid_size * defaults['basis_speeds'].default
        damping = grid_size * max(defaults['damping_speeds'].default, 3)
        self.report = report
        self.total = BASIS_WEIGHT * basis + damping
        self.done = 0

    def follow(self, samples):
        """
        Return ``samples`` made to count the work done with them (as is without a report).

        Parameters
        ----------
        samples : FrozenSamples
            The assembled full-order pieces.

        """
        if self.report is None:
            return samples
        self.report(ASSEMBLED_PERCENT, 100, 'full-order model assembled')
        fields = {field.name: getattr(samples, field.name)
                  for field in dataclasses.fields(FrozenSamples)}
        damping = samples.damping

        def counted_damping(k, w):
            self.step(1, DAMPING_STEP)
            return damping(k, w)

        fields['damping'] = counted_damping
        return FollowedSamples(**fields, tracker=self)

    def step(self, weight, what):
        """Count ``weight`` units of work done and report the percentage."""
        self.done += weight
        fraction = min(self.done / self.total, 1.0)
        self.report(ASSEMBLED_PERCENT + fraction * (LOOPS_END_PERCENT - ASSEMBLED_PERCENT),
                    100, what)

    def finish(self):
        """Report 100 %."""
        if self.report is not None:
            self.report(100.0, 100, 'model built')
