"""
The dynamic second-order pass's loads of one step, compiled (_second_order_dynamic.c) or numpy.

Per Radau step the pass (:mod:`.second_order_dynamic_step`) needs, at stage 1 and at the sample,
the reduced static response s = K_r^-1 f_r (its elastic axial force is the reference of the
linear state's: the basis misses most of the static axial stretch), the reduced second-order
load f2 of the linear state q against it, and at the sample K_r^-1 f2_eigenstrain (the part
of q2 the quasi-static correction already holds). :class:`DynamicPassKernel` returns the three
in one call: in C where the extension is built (one call instead of about a hundred numpy
calls), else with :class:`core.reduction.second_order_dynamic_tables.DynamicLoad` (its numpy
twin and reference; a test compares the two).
"""

import numpy as np

from ..reduction.second_order_dynamic_tables import DynamicLoad

try:
    from . import _second_order_dynamic as impl     # _second_order_dynamic.c
except ImportError:     # not built: the numpy form serves
    impl = None


def dynamic_pass_compiled_available():
    """Tell whether the compiled loads (_second_order_dynamic.c) are built."""
    return impl is not None


class DynamicPassKernel:
    """
    The loads of the dynamic pass at stage 1 and at the sample of one step.

    Parameters
    ----------
    arrays : dict of str to ndarray
        A model's ``dynamic_second_order`` tables.
    compiled : bool
        Use the compiled form where it is built; False: numpy (the same numbers to rounding).

    """

    def __init__(self, arrays, compiled=True):
        self.load = DynamicLoad(arrays)
        self.compiled = bool(compiled and impl is not None)
        pieces = self.load.pieces
        self.size = pieces.shape[2]
        links = self.load.arrays['dynamic_links']
        header = [self.size, pieces.shape[1], links.shape[0], self.load.grid_size,
                  self.load.scalars.shape[2]]
        self.context = np.array(header + links[:, :2].ravel().tolist()
                                + self.load.arrays['dynamic_link_values'].ravel().tolist())
        self.out = np.zeros((3, self.size))

    def __call__(self, stored, slots, states, angles):
        """
        Return (3, r): f2 at stage 1, f2 at the sample, K_r^-1 f2_eigenstrain at the sample.

        Parameters
        ----------
        stored : ndarray, shape (2, 4, r r)
            The step's [M, C, K, F] in alternating slots.
        slots : tuple of int
            The slots of stage 1 and of the sample.
        states : ndarray, shape (2, r)
            The linear q at stage 1 and at the sample (contiguous).
        angles : tuple of float
            The crank angles of stage 1 and of the sample [rad].

        Returns
        -------
        ndarray
            Reused by the next call.

        """
        if self.compiled:
            impl.loads(self.context, self.load.pieces, self.load.arrays['dynamic_unit'],
                       self.load.scalars, stored, states, self.out, float(angles[0]),
                       float(angles[1]), int(slots[0]), int(slots[1]))
            return self.out
        r = self.size
        eigen = None
        for point in (0, 1):
            slot = stored[slots[point]]
            statics = np.linalg.solve(slot[2].reshape(r, r), slot[3, :r])
            self.out[point], eigen = self.load.load(states[point], angles[point], 0.0, 0.0,
                                                    statics)
        self.out[2] = np.linalg.solve(stored[slots[1], 2].reshape(r, r), eigen)
        return self.out


__all__ = ['DynamicPassKernel', 'dynamic_pass_compiled_available']
