"""
Transfer matrices of a lumped-mass beam and the frequency determinant (Kim & Moon, Eqs. 2-4).

The beam's mass sits at points joined by massless elastic fields (Pestel & Leckie 1963). The
state vector at a station is::

    z = [-W, theta, M, V]

(deflection with the sign that makes every transfer entry positive, slope, bending moment,
shear force; SI units: m, rad, N m, N). A field of length l carries z by :func:`field_matrix`,
a point mass m at frequency omega by :func:`point_matrix` (inertia force m omega^2 W), and
the left boundary conditions of Eq. 3 leave two unknown columns, so the right boundary
conditions give the 2x2 frequency determinant |D(omega)| of Eq. 4.

References
----------
Kim, Y.-S. & Moon, D.-H., "A Study on the Vibration Analysis of Beam" (Korean), Eqs. 2-7,
Tables 1-5. Pestel, E. C. & Leckie, F. A. (1963), Matrix Methods in Elastomechanics.

"""

import numpy as np

from .beams import STANDARD_GRAVITY

# Eq. 3: state entries left unknown at x = 0, and entries that vanish at x = L.
_UNKNOWN_AT_LEFT = {'fixed-fixed': (2, 3), 'fixed-supported': (2, 3), 'cantilever': (2, 3),
                    'supported': (1, 3)}
_ZERO_AT_RIGHT = {'fixed-fixed': (0, 1), 'fixed-supported': (0, 2), 'cantilever': (2, 3),
                  'supported': (0, 2)}
# State components from SI (m, 1, N m, N) to the paper's units (mm, 1, kgf mm, kgf).
_TO_KGF_MM = np.array([1e3, 1.0, 1e3 / STANDARD_GRAVITY, 1.0 / STANDARD_GRAVITY])


def field_matrix(length, flexural_rigidity):
    """
    Field transfer matrix of a massless Euler-Bernoulli segment (Pestel & Leckie).

    Parameters
    ----------
    length : float
        Segment length l [m].
    flexural_rigidity : float
        EI [N m^2].

    Returns
    -------
    ndarray, shape (4, 4)
        Maps [-W, theta, M, V] at the segment's left end to its right end.

    """
    span, ei = length, flexural_rigidity
    return np.array([
        [1.0, span, span ** 2 / (2 * ei), span ** 3 / (6 * ei)],
        [0.0, 1.0, span / ei, span ** 2 / (2 * ei)],
        [0.0, 0.0, 1.0, span],
        [0.0, 0.0, 0.0, 1.0],
    ])


def point_matrix(mass, omega):
    """
    Point transfer matrix of a mass m vibrating at omega: V jumps by m omega^2 (-W).

    Returns
    -------
    ndarray, shape (4, 4)

    """
    p = np.eye(4)
    p[3, 0] = mass * omega ** 2
    return p


def frequency_determinant(model, bc, omega, derivative=False):
    """
    Frequency determinant |D(omega)| of Eq. 4 and, optionally, its omega-derivative.

    The two unknown left-end columns of Eq. 3 are carried through the fields and points
    (half the work of carrying the full 4x4 product); the rows that vanish at the right end
    form D. With ``derivative=True`` d(state)/d(omega) is propagated alongside (extended
    transfer matrix): fields are independent of omega, a point adds 2 m omega (-W).

    Parameters
    ----------
    model : LumpedBeam
        The lumped-mass beam (:func:`core.tmm.beams.lump_masses`).
    bc : str
        One of :data:`BOUNDARY_CONDITIONS`.
    omega : float
        Circular frequency [rad/s].
    derivative : bool
        Also return d|D|/d(omega).

    Returns
    -------
    float or tuple of float
        |D| in SI units (its unit depends on `bc`), or (|D|, d|D|/d(omega)).

    """
    # Pure-float arithmetic: one state column per unknown of Eq. 3, [u, theta, M, V] with
    # u = -W; each field and point matrix is applied entry by entry (see field_matrix).
    ei = model.flexural_rigidity
    columns = []
    for unknown in _UNKNOWN_AT_LEFT[bc]:
        z = [0.0, 0.0, 0.0, 0.0]
        z[unknown] = 1.0
        columns.append(z + [0.0, 0.0, 0.0, 0.0])  # state, then d(state)/d(omega)
    omega2 = omega * omega
    x = 0.0
    for position, mass in zip(model.segment_ends, model.point_masses):
        span = position - x
        x = position
        c2, c3, c1 = span * span / (2.0 * ei), span ** 3 / (6.0 * ei), span / ei
        for z in columns:
            u, t, m, v, du, dt, dm, dv = z
            u, t, m = u + span * t + c2 * m + c3 * v, t + c1 * m + c2 * v, m + span * v
            if derivative:
                du, dt, dm = (du + span * dt + c2 * dm + c3 * dv, dt + c1 * dm + c2 * dv,
                              dm + span * dv)
                dv = dv + mass * omega2 * du + 2.0 * mass * omega * u
            v = v + mass * omega2 * u
            z[:] = (u, t, m, v, du, dt, dm, dv)
    first, second = _ZERO_AT_RIGHT[bc]
    (a, b), (c, d) = [[z[first] for z in columns], [z[second] for z in columns]]
    det = a * d - b * c
    if not derivative:
        return det
    (da, db), (dc, dd) = [[z[4 + first] for z in columns], [z[4 + second] for z in columns]]
    return det, da * d + a * dd - db * c - b * dc


def frequency_determinants(model, bc, omegas):
    """
    |D| of Eq. 4 at many frequencies at once (vectorised :func:`frequency_determinant`).

    Parameters
    ----------
    model : LumpedBeam
        The lumped-mass beam (:func:`core.tmm.beams.lump_masses`).
    bc : str
        Boundary condition, one of :data:`BOUNDARY_CONDITIONS`.
    omegas : ndarray, shape (k,)
        Circular frequencies [rad/s].

    Returns
    -------
    ndarray, shape (k,)

    """
    omega2 = np.asarray(omegas, dtype=float) ** 2
    ei = model.flexural_rigidity
    state = np.zeros((4, omega2.size, 2))
    for column, unknown in enumerate(_UNKNOWN_AT_LEFT[bc]):
        state[unknown, :, column] = 1.0
    u, t, m, v = state
    x = 0.0
    for position, mass in zip(model.segment_ends, model.point_masses):
        span = position - x
        x = position
        u, t, m = (u + span * t + span * span / (2 * ei) * m + span ** 3 / (6 * ei) * v,
                   t + span / ei * m + span * span / (2 * ei) * v, m + span * v)
        v = v + (mass * omega2)[:, None] * u
    state = (u, t, m, v)
    first, second = (state[row] for row in _ZERO_AT_RIGHT[bc])
    return first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0]


def determinant_to_kgf_mm(bc):
    """
    Factor turning an SI |D| into the paper's kgf-mm units (Tables 2-5).

    Returns
    -------
    float

    """
    rows, cols = _ZERO_AT_RIGHT[bc], _UNKNOWN_AT_LEFT[bc]
    return float(np.prod(_TO_KGF_MM[list(rows)]) / np.prod(_TO_KGF_MM[list(cols)]))
