"""
What the geometrically nonlinear model cannot carry: the validity of a nonlinear estimate.

Two limits, each a dimensionless indicator that reaches 1 at its bound:

- **The strain's truncation.** The co-rotational strain (:mod:`core.fe.corotational_strain`,
  the full order's default) is exact in an element's rigid turn and second order in its
  bending against its chord: there phi is the node rotations' largest angle to the chord
  (``element_rotations(..., frame='chord')``), and the same bound applies. The
  element-averaged von Karman strain
  (:mod:`core.fe.nonlinear_strain`) is exact to second order in each element's rotation phi
  relative to its link frame; an element turned rigidly by phi strains ``-phi^4 / 8`` instead
  of 0, an axial force ``E A phi^4 / 8`` the model invents. :func:`element_rotations` gives
  phi per element (the largest of the two end slopes and the chord angle) from element
  coordinates that any estimator has (``q_e = T_e x``, or ``T_e Phi eta`` of a reduced
  state), and :func:`rotation_indicator` is ``(max phi / ROTATION_LIMIT)^4``: the invented
  strain against the one at the bound.
- **A fold of the periodic orbit.** Where a Floquet multiplier of the periodic orbit
  approaches +1 two periodic solutions meet (a jump between ramp-up and ramp-down): which one
  the machine is on depends on its history, and a periodic answer is not unique.
  :func:`fold_indicator` is ``FOLD_MARGIN / min |1 - mu|`` over the multipliers (1 at the
  margin, large at the fold, infinite on it); a multiplier outside the unit circle (an
  unstable orbit) counts as a fold.

:func:`nonlinear_validity` combines them (the larger indicator, valid below 1). Pure numpy, no
ROS: the streaming estimator evaluates :func:`element_rotations` and
:func:`rotation_indicator` per sample, and the full order's orbit carries its multipliers.
"""

import dataclasses

import numpy as np

from .nonlinear_strain import element_coordinates, element_gather, model_elements

# Element rotation relative to its link frame [rad] at which the rotation indicator is 1.
# Measured against the Exudyn peer (cho1992, 269-440 rpm): every orbit whose largest element
# rotation stayed at or below 0.117 rad met the targets (at most 4.8 % RMS); at 0.125 and
# 0.192 rad (405 rpm with pins, 440 rpm with springs) 5-7 %, but 1.3 / 2.9 % at 0.132 rad
# (391 rpm, springs). There the invented strain phi^4 / 8 (3e-5) is several times the links'
# largest axial strain (7e-6).
ROTATION_LIMIT = 0.12
# Distance of the nearest Floquet multiplier to +1 at which the fold indicator is 1.
FOLD_MARGIN = 0.1
# Indicators at or above this are not valid.
THRESHOLD = 1.0


@dataclasses.dataclass(frozen=True)
class NonlinearValidity:
    """
    The nonlinear model's validity (see :func:`nonlinear_validity`).

    Attributes
    ----------
    rotation : float
        :func:`rotation_indicator` of the largest element rotation (0 when not given).
    fold : float
        :func:`fold_indicator` of the orbit's multipliers (0 when not given).
    max_rotation : float
        The largest element rotation relative to its link frame [rad].
    fold_distance : float
        ``min |1 - mu|`` over the multipliers (inf when not given).
    frame : str
        What the rotations are measured against: 'link' (the von Karman strain's
        truncation) or 'chord' (the co-rotational strain's).

    """

    rotation: float
    fold: float
    max_rotation: float
    fold_distance: float
    frame: str = 'link'

    @property
    def indicator(self):
        """Return the larger of the two indicators."""
        return max(self.rotation, self.fold)

    @property
    def valid(self):
        """Return True below :data:`THRESHOLD`."""
        return self.indicator < THRESHOLD

    @property
    def reason(self):
        """Return why not valid, in words ('' when valid)."""
        if self.valid:
            return ''
        if self.fold >= self.rotation:
            return (f'a Floquet multiplier is {self.fold_distance:.3f} from +1 (margin '
                    f'{FOLD_MARGIN:g}): near a fold the periodic response is not unique')
        if self.frame == 'chord':
            return (f'element bending rotation {self.max_rotation:.3f} rad against its chord '
                    f'beyond {ROTATION_LIMIT:g} rad: the element strain is second order in it')
        return (f'element rotation {self.max_rotation:.3f} rad beyond {ROTATION_LIMIT:g} rad: '
                'the von Karman strain invents an axial force growing as phi^4')


def element_rotations(q, length, frame='link'):
    """
    Return every element's rotation relative to its link frame or chord [rad], shape (..., E).

    Parameters
    ----------
    q : ndarray, shape (..., E, 6)
        Element coordinates ``(u1, v1, phi1, u2, v2, phi2)`` in the link frames.
    length : ndarray, shape (E,)
        Element lengths l [m].
    frame : str
        'link': the largest of ``|phi1|``, ``|phi2|`` and the chord's angle
        ``alpha = atan2(v2 - v1, l + u2 - u1)``; 'chord': the larger of ``|phi1 - alpha|`` and
        ``|phi2 - alpha|`` (the bending the co-rotational strain keeps to second order).

    Returns
    -------
    ndarray

    """
    if frame not in ('link', 'chord'):
        raise ValueError(f"`frame` must be 'link' or 'chord', got {frame!r}")
    q = np.asarray(q, dtype=float)
    chord = np.arctan2(q[..., 4] - q[..., 1], length + q[..., 3] - q[..., 0])
    if frame == 'chord':
        return np.maximum(np.abs(q[..., 2] - chord), np.abs(q[..., 5] - chord))
    return np.max(np.abs(np.stack([q[..., 2], q[..., 5], chord], axis=-1)), axis=-1)


def rotation_indicator(rotation, limit=ROTATION_LIMIT):
    """``(phi / limit)^4``: the truncated strain ``phi^4 / 8`` against that at the limit."""
    return (np.asarray(rotation, dtype=float) / limit) ** 4


def fold_distance(multipliers):
    """
    Return the periodic orbit's distance from a fold: ``min |1 - mu|``; 0 if any ``|mu| >= 1``.

    An empty set of multipliers is infinitely far (nothing known).
    """
    mu = np.asarray(multipliers, dtype=complex).ravel()
    if mu.size == 0:
        return float('inf')
    if np.any(np.abs(mu) >= 1.0):
        return 0.0
    return float(np.min(np.abs(1.0 - mu)))


def fold_indicator(multipliers, margin=FOLD_MARGIN):
    """``margin / min |1 - mu|`` (:func:`fold_distance`): 1 at the margin, inf at a fold."""
    distance = fold_distance(multipliers)
    return float('inf') if distance == 0.0 else margin / distance


def nonlinear_validity(rotations=None, multipliers=None, frame='link'):
    """
    Judge a nonlinear estimate by its element rotations and/or its orbit's multipliers.

    Parameters
    ----------
    rotations : array_like or None
        Element rotations [rad] (:func:`element_rotations`; any shape, e.g. samples x
        elements): the largest counts.
    multipliers : array_like or None
        Floquet multipliers of the periodic orbit at the speed.
    frame : str
        What ``rotations`` are measured against (:func:`element_rotations`).

    Returns
    -------
    NonlinearValidity

    """
    largest = 0.0 if rotations is None else float(np.max(np.abs(rotations), initial=0.0))
    distance = float('inf') if multipliers is None else fold_distance(multipliers)
    fold = 0.0 if multipliers is None else fold_indicator(multipliers)
    return NonlinearValidity(rotation=float(rotation_indicator(largest)), fold=fold,
                             max_rotation=largest, fold_distance=distance, frame=frame)


def orbit_rotations(model, response):
    """
    Return the element rotations along a full-order periodic orbit, shape (P, E) [rad].

    ``model`` a :class:`core.fe.linkage.FlexibleLinkage`; ``response`` its
    :class:`core.fe.simulate.PeriodicResponse` (displacements at the output points).
    Measured against each element's chord where the orbit's strain is co-rotational
    (:func:`orbit_frame`), else against its link frame.
    """
    elements = model_elements(model)
    link_angle = model.kinematic_coefficients(response.crank_angle)[0]
    gathers = {link: model.gather(link, link_angle[link], 0) for link in model.links}
    q = element_coordinates(element_gather(elements, gathers), response.displacement)
    return element_rotations(q, elements.length, orbit_frame(response))


def orbit_frame(response):
    """'chord' for an orbit of the co-rotational strain, else 'link'."""
    return 'chord' if response.info.get('strain') == 'corotational' else 'link'


def orbit_validity(model, response):
    """:func:`nonlinear_validity` of a periodic orbit: its rotations and its multipliers."""
    return nonlinear_validity(orbit_rotations(model, response), response.floquet_multipliers,
                              orbit_frame(response))


def validity_record(validity):
    """Return the JSON form of a :class:`NonlinearValidity`."""
    return {'valid': validity.valid, 'indicator': validity.indicator,
            'rotation_indicator': validity.rotation, 'fold_indicator': validity.fold,
            'max_element_rotation_rad': validity.max_rotation,
            'rotation_frame': validity.frame,
            'fold_distance': validity.fold_distance, 'reason': validity.reason}


__all__ = ['ROTATION_LIMIT', 'FOLD_MARGIN', 'THRESHOLD', 'NonlinearValidity',
           'element_rotations', 'rotation_indicator', 'fold_distance', 'fold_indicator',
           'nonlinear_validity', 'orbit_rotations', 'orbit_frame', 'orbit_validity',
           'validity_record']
