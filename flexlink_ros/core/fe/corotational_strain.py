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


def _rotation_blocks(elements):
    """``G_r`` and ``K_r``: the rotation blocks of A.4 (unit tension) and of K_b, (E, 2, 2)."""
    rows = np.ix_(np.arange(len(elements)), ROTATIONS, ROTATIONS)
    return elements.unit_geometric[rows], elements.bending[rows]


def chord(elements, q):
    """
    The chord of each element: length L, angle alpha and node rotations theta against it.

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
    c, s = np.cos(angle), np.sin(angle)
    length_gradient = np.stack([c, s], axis=-1) @ CHORD_MAP
    angle_gradient = (np.stack([-s, c], axis=-1) / length[..., None]) @ CHORD_MAP
    length_r = np.stack([np.stack([s * s, -c * s], -1), np.stack([-c * s, c * c], -1)], -2)
    angle_r = np.stack([np.stack([2 * c * s, s * s - c * c], -1),
                        np.stack([s * s - c * c, -2 * c * s], -1)], -2)
    length_hessian = CHORD_MAP.T @ (length_r / length[..., None, None]) @ CHORD_MAP
    angle_hessian = CHORD_MAP.T @ (angle_r / (length ** 2)[..., None, None]) @ CHORD_MAP
    return length_gradient, angle_gradient, length_hessian, angle_hessian


def _theta_gradient(angle_gradient):
    """``d theta / dq`` (..., E, 2, 6): each node rotation less the chord's angle."""
    unit = np.zeros((2, 6))
    unit[0, ROTATIONS[0]] = unit[1, ROTATIONS[1]] = 1.0
    return unit - angle_gradient[..., None, :]


def element_strain(elements, q):
    """Co-rotational element strain ``(L - l)/l + theta^T G_r theta / (2 l)``, (..., E)."""
    length, _, theta = chord(elements, q)
    geometric, _ = _rotation_blocks(elements)
    stretch_x, dy = q[..., 3] - q[..., 0], q[..., 4] - q[..., 1]
    # L - l without cancellation: the strains are ~1e-6 of the lengths
    stretch = (stretch_x * (2.0 * elements.length + stretch_x) + dy * dy) / (length
                                                                              + elements.length)
    shortening = 0.5 * np.einsum('...a,...ab,...b->...', theta, geometric, theta)
    return (stretch + shortening) / elements.length


def strain_energy(elements, q):
    """Strain energy ``sum (E A l eps^2 + theta^T K_r theta) / 2`` [J], shape (...)."""
    _, _, theta = chord(elements, q)
    _, bending = _rotation_blocks(elements)
    strain = element_strain(elements, q)
    axial = 0.5 * elements.axial_stiffness * elements.length * strain ** 2
    return (axial + 0.5 * np.einsum('...a,...ab,...b->...', theta, bending, theta)).sum(-1)


def _kinematics(elements, q, rate):
    """Everything the force and its tangents share, as a dict of arrays."""
    length_gradient, angle_gradient, length_hessian, angle_hessian = chord_derivatives(
        elements, q)
    _, _, theta = chord(elements, q)
    geometric, bending = _rotation_blocks(elements)
    theta_gradient = _theta_gradient(angle_gradient)
    theta_moment = np.einsum('...ab,...b->...a', geometric, theta)
    gradient = length_gradient + np.einsum('...ka,...k->...a', theta_gradient, theta_moment)
    hessian = (length_hessian + np.swapaxes(theta_gradient, -1, -2) @ geometric @ theta_gradient
               - theta_moment.sum(-1)[..., None, None] * angle_hessian)
    return {'theta': theta, 'theta_gradient': theta_gradient, 'gradient': gradient,
            'hessian': hessian, 'angle_hessian': angle_hessian, 'bending': bending,
            'theta_rate': np.einsum('...ka,...a->...k', theta_gradient, rate)}


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
    strain_rate = np.einsum('...a,...a->...', kin['gradient'], rate) / elements.length
    axial = elements.axial_stiffness * (strain + beta * strain_rate)
    moment = np.einsum('...ab,...b->...a', kin['bending'], kin['theta'] + beta * kin['theta_rate'])
    bending = np.einsum('...ka,...k->...a', kin['theta_gradient'], moment)
    return axial[..., None] * kin['gradient'] + bending, axial


def element_tangent(elements, q, rate, beta):
    """
    Tangents of :func:`element_force`: ``df/dq`` and ``df/dq'`` (module notes).

    Returns
    -------
    stiffness, damping : ndarray, shape (..., E, 6, 6)

    """
    kin = _kinematics(elements, q, rate)
    _, axial = _force(elements, q, rate, beta, kin)
    gradient, hessian, theta_gradient = kin['gradient'], kin['hessian'], kin['theta_gradient']
    scale = (elements.axial_stiffness / elements.length)[..., None, None]
    outer = scale * gradient[..., :, None] * gradient[..., None, :]
    bending = np.swapaxes(theta_gradient, -1, -2) @ kin['bending'] @ theta_gradient
    damping = beta * (outer + bending)
    curvature_rate = np.einsum('...ab,...b->...a', hessian, rate)
    angle_rate = np.einsum('...ab,...b->...a', kin['angle_hessian'], rate)
    moment = np.einsum('...ab,...b->...a', kin['bending'], kin['theta'] + beta * kin['theta_rate'])
    moment_rate = np.einsum('...ka,...kb->...ab', theta_gradient,
                            kin['bending'].sum(-1)[..., :, None] * angle_rate[..., None, :])
    stiffness = (outer + beta * scale * gradient[..., :, None] * curvature_rate[..., None, :]
                 + axial[..., None, None] * hessian + bending - beta * moment_rate
                 - moment.sum(-1)[..., None, None] * kin['angle_hessian'])
    return stiffness, damping


__all__ = ['chord', 'chord_derivatives', 'element_strain', 'strain_energy', 'element_force',
           'element_tangent']
