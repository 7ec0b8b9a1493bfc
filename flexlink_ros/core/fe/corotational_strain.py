"""
Co-rotational element force and tangent: the chord's exact stretch and rotation.

The element-averaged von Karman strain (:mod:`core.fe.nonlinear_strain`) is exact to second
order in an element's rotation relative to its link frame: an element turned rigidly by phi
strains ``-phi^4 / 8`` and its bending sees the turn as a linear ``(v2 - v1) / l``. Here each
element carries its own chord frame, exactly as the geometrically exact peer's strain does in a
rigid turn. For element coordinates ``q = (u1, v1, phi1, u2, v2, phi2)`` in the link frame ::

    (dx, dy) = (l + u2 - u1, v2 - v1),  L = |(dx, dy)|,  alpha = atan2(dy, dx)   (the chord)
    theta    = (phi1 - alpha, phi2 - alpha)                 (node rotations against the chord)
    eps      = (L - l) / l + theta^T G_r theta / (2 l)      (chord stretch + averaged bending)
    N        = E A (eps + beta eps'),  m = K_r (theta + beta theta')   (Kelvin-Voigt, objective)
    f        = N l d(eps)/dq + (d theta/dq)^T m

``G_r`` and ``K_r`` are the rotation rows and columns of A.4 at unit tension and of the
bending stiffness A.3: with zero deflection at the chord's ends the Hermite bending and the
averaged shortening depend on the two end rotations alone. A rigid turn of the element
(``alpha = phi1 = phi2``, ``L = l``) strains nothing and, at any rate, dissipates nothing.
To second order in q the strain and the bending energy are the von Karman ones, and to first
order the force is the linear ``K_e (q + beta q')`` (A.3).

Tangents: with ``g = l d(eps)/dq`` and ``H = l d^2(eps)/dq^2`` ::

    df/dq  = (E A / l) g (g + beta H q')^T + N H + (dtheta/dq)^T K_r (dtheta/dq + beta dtheta'/dq)
             - (m_1 + m_2) d^2(alpha)/dq^2
    df/dq' = beta ((E A / l) g g^T + (dtheta/dq)^T K_r (dtheta/dq))

All functions take the :class:`nonlinear_strain.Elements` and are vectorised over any leading
axes (stages, elements), as the von Karman ones.
"""

import numpy as np

# Rows of the two nodal rotations in the element vector.
ROTATIONS = np.array([2, 5])
# d(dx, dy)/dq: the chord's components from the element coordinates.
CHORD_MAP = np.array([[-1.0, 0.0, 0.0, 1.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0, 1.0, 0.0]])
# CHORD_MAP^T E_ij CHORD_MAP: where a second derivative in (dx, dy) lands in q.
_XX, _YY = np.outer(CHORD_MAP[0], CHORD_MAP[0]), np.outer(CHORD_MAP[1], CHORD_MAP[1])
_XY = np.outer(CHORD_MAP[0], CHORD_MAP[1]) + np.outer(CHORD_MAP[1], CHORD_MAP[0])


def _rotation_blocks(elements):
    """``G_r`` and ``K_r``: the rotation blocks of A.4 (unit tension) and of K_b, (E, 2, 2)."""
    return (elements.unit_geometric[:, ROTATIONS][:, :, ROTATIONS],
            elements.bending[:, ROTATIONS][:, :, ROTATIONS])


def _in_q(xx, xy, yy):
    """Place a symmetric (dx, dy) second derivative, entries (..., E), in q: (..., E, 6, 6)."""
    return xx[..., None, None] * _XX + xy[..., None, None] * _XY + yy[..., None, None] * _YY


def chord(elements, q):
    """
    Return each element's chord: length L, angle alpha and node rotations theta against it.

    Returns
    -------
    length, angle : ndarray, shape (..., E)
    theta : ndarray, shape (..., E, 2)

    """
    dx = elements.length + q[..., 3] - q[..., 0]
    dy = q[..., 4] - q[..., 1]
    angle = np.arctan2(dy, dx)
    return np.hypot(dx, dy), angle, q[..., ROTATIONS] - angle[..., None]


def chord_derivatives(elements, q):
    """
    First and second derivatives of the chord in q.

    Returns
    -------
    length_gradient, angle_gradient : ndarray, shape (..., E, 6)
    length_hessian, angle_hessian : ndarray, shape (..., E, 6, 6)

    """
    length, angle, _ = chord(elements, q)
    c, s = np.cos(angle) / length, np.sin(angle) / length
    length_gradient = length[..., None] * (c[..., None] * CHORD_MAP[0]
                                           + s[..., None] * CHORD_MAP[1])
    angle_gradient = c[..., None] * CHORD_MAP[1] - s[..., None] * CHORD_MAP[0]
    length_hessian = length[..., None, None] * _in_q(s * s, -c * s, c * c)
    angle_hessian = _in_q(2.0 * c * s, s * s - c * c, -2.0 * c * s)
    return length_gradient, angle_gradient, length_hessian, angle_hessian


def element_strain(elements, q):
    """Co-rotational element strain ``(L - l)/l + theta^T G_r theta / (2 l)``, (..., E)."""
    length, _, theta = chord(elements, q)
    geometric, _ = _rotation_blocks(elements)
    stretch_x, dy = q[..., 3] - q[..., 0], q[..., 4] - q[..., 1]
    # L - l without cancellation: the strains are ~1e-6 of the lengths
    stretch = ((stretch_x * (2.0 * elements.length + stretch_x) + dy * dy)
               / (length + elements.length))
    shortening = 0.5 * np.einsum('...a,...ab,...b->...', theta, geometric, theta)
    return (stretch + shortening) / elements.length


def strain_energy(elements, q):
    """Strain energy ``sum (E A l eps^2 + theta^T K_r theta) / 2`` [J], shape (...)."""
    _, _, theta = chord(elements, q)
    _, bending = _rotation_blocks(elements)
    strain = element_strain(elements, q)
    axial = 0.5 * elements.axial_stiffness * elements.length * strain ** 2
    return (axial + 0.5 * np.einsum('...a,...ab,...b->...', theta, bending, theta)).sum(-1)


def _dot(matrix, vector):
    """Batched ``matrix @ vector``: (..., a, b) and (..., b) -> (..., a)."""
    return (matrix @ vector[..., None])[..., 0]


def _placed(pair):
    """Place a pair over the node rotations (..., 2) in an element vector (..., 6)."""
    out = np.zeros(pair.shape[:-1] + (6,))
    out[..., ROTATIONS] = pair
    return out


def _through_theta(block, angle_gradient):
    """``(dtheta/dq)^T B (dtheta/dq)`` for a symmetric 2 x 2 B (..., E, 2, 2), (..., E, 6, 6)."""
    padded = np.zeros(block.shape[:-2] + (6, 6))
    padded[..., ROTATIONS[:, None], ROTATIONS[None, :]] = block
    row = _placed(block.sum(-1))
    cross = row[..., :, None] * angle_gradient[..., None, :]
    total = block.sum((-1, -2))[..., None, None]
    return (padded - cross - np.swapaxes(cross, -1, -2)
            + total * angle_gradient[..., :, None] * angle_gradient[..., None, :])


def _kinematics(elements, q, rate):
    """Everything the force and its tangents share, as a dict of arrays."""
    length_gradient, angle_gradient, length_hessian, angle_hessian = chord_derivatives(
        elements, q)
    _, _, theta = chord(elements, q)
    geometric, bending = _rotation_blocks(elements)
    theta_moment = _dot(geometric, theta)
    # (dtheta/dq)^T x for a pair x: x at the node rotations less (x1 + x2) d(alpha)/dq
    gradient = (length_gradient + _placed(theta_moment)
                - theta_moment.sum(-1)[..., None] * angle_gradient)
    hessian = (length_hessian + _through_theta(geometric, angle_gradient)
               - theta_moment.sum(-1)[..., None, None] * angle_hessian)
    theta_rate = rate[..., ROTATIONS] - np.sum(angle_gradient * rate, -1)[..., None]
    return {'theta': theta, 'angle_gradient': angle_gradient, 'gradient': gradient,
            'hessian': hessian, 'angle_hessian': angle_hessian, 'bending': bending,
            'theta_rate': theta_rate}


def element_force(elements, q, rate, beta):
    """
    Element force ``f = N g + (dtheta/dq)^T m`` and axial force N (module notes).

    Parameters
    ----------
    elements : nonlinear_strain.Elements
        The element data.
    q, rate : ndarray, shape (..., E, 6)
        Element coordinates and their link-frame rates.
    beta : float
        Kelvin-Voigt damping [s] on the strain rate and the chord-relative rotation rates.

    Returns
    -------
    force : ndarray, shape (..., E, 6)
    axial_force : ndarray, shape (..., E)
        N = E A (eps + beta eps') [N], tension > 0.

    """
    kin = _kinematics(elements, q, rate)
    return _force(elements, q, rate, beta, kin)


def _force(elements, q, rate, beta, kin):
    """Force and axial force from the shared kinematics."""
    strain = element_strain(elements, q)
    strain_rate = np.sum(kin['gradient'] * rate, -1) / elements.length
    axial = elements.axial_stiffness * (strain + beta * strain_rate)
    kin['moment'] = _dot(kin['bending'], kin['theta'] + beta * kin['theta_rate'])
    bending = (_placed(kin['moment'])
               - kin['moment'].sum(-1)[..., None] * kin['angle_gradient'])
    return axial[..., None] * kin['gradient'] + bending, axial


def element_tangent(elements, q, rate, beta):
    """
    Tangents of :func:`element_force`: ``df/dq`` and ``df/dq'`` (module notes).

    Returns
    -------
    stiffness, damping : ndarray, shape (..., E, 6, 6)

    """
    return force_and_tangent(elements, q, rate, beta)[2:]


def force_and_tangent(elements, q, rate, beta):
    """:func:`element_force` and :func:`element_tangent` in one evaluation (4 arrays)."""
    kin = _kinematics(elements, q, rate)
    force, axial = _force(elements, q, rate, beta, kin)
    gradient, hessian, angle_gradient = kin['gradient'], kin['hessian'], kin['angle_gradient']
    scale = (elements.axial_stiffness / elements.length)[..., None, None]
    outer = scale * gradient[..., :, None] * gradient[..., None, :]
    bending = _through_theta(kin['bending'], angle_gradient)
    damping = beta * (outer + bending)
    curvature_rate = _dot(hessian, rate)
    angle_rate = _dot(kin['angle_hessian'], rate)
    moment = kin['moment']
    # sum_k (dtheta_k/dq) (K_r 1)_k (d^2 alpha/dq^2 q')^T: the rates' turn with the chord
    row_sums = kin['bending'].sum(-1)
    turned = _placed(row_sums) - row_sums.sum(-1)[..., None] * angle_gradient
    moment_rate = turned[..., :, None] * angle_rate[..., None, :]
    stiffness = (outer + beta * scale * gradient[..., :, None] * curvature_rate[..., None, :]
                 + axial[..., None, None] * hessian + bending - beta * moment_rate
                 - moment.sum(-1)[..., None, None] * kin['angle_hessian'])
    return force, axial, stiffness, damping


__all__ = ['chord', 'chord_derivatives', 'element_strain', 'strain_energy', 'element_force',
           'element_tangent', 'force_and_tangent']
