"""
Dynamic second-order pass of the full-order model: the inertia of the second-order motion.

The quasi-static second order (:mod:`core.fe.second_order_full`) adds the chord shortening of
the bent links to the outputs without any dynamics. This module computes the same motion as the
periodic response of one more LINEAR pass of the full-order model, loaded by the second-order
terms of the beam's strain energy evaluated on the linear state.

Derivation. In each link's nominal (rigid-body) frame the Bernoulli-Euler beam's axial strain to
second order is ``eps = u' + 1/2 v'^2``, and its strain energy ::

    Pi = 1/2 int EA eps^2 dx + 1/2 int EI v''^2 dx

has the variation, to second order in the deflections (u, v), ::

    dPi = int EA u' du' + int EI v'' dv''                   (linear K, Eq. 32)
        + int 1/2 EA v'^2 du'                               (axial eigenstrain)          (1)
        + int N v' dv',   N = EA u' = F_r + N_e             (geometric stiffness)        (2)

The linear model keeps the first line and, of (2), the rigid-body axial force F_r (A.4, in
K_G). Split the state into the linear one and a second-order correction, U = U1 + U2: the terms
of (1) and of (2) with the ELASTIC axial force N_e (:func:`core.validity.elastic_axial_forces`,
element averages) are products of first-order quantities, so they act on U2 as loads computed
from U1. Per element (length l, axial DOFs u_1, u_2 at the element's nodes 0 and 3, link-frame
nodal vector u_e, G_e the element's geometric stiffness for unit tension, so that
``s_e = 1/2 int_e v'^2 dx = 1/2 u_e^T G_e u_e``) ::

    f_e = (EA s_e / l) [1, 0, 0, -1, 0, 0]^T  -  N_e G_e u_e                              (3)

The first term is the eigenstrain -1/2 EA v'^2 (it pulls the element's ends together by s_e if
nothing resists); the second the geometric stiffness of the elastic axial force. Gathered into
the system, ``F2 = sum T f^L`` (Eq. 25, as the loads of Eq. 33), U2 solves the linear equation
of the model with its own mass, gyroscopic and coupling terms and damping ::

    M U2'' + (C_c + C_d) U2' + (K + K_G + K_c) U2 = F2(U1)                              (4)

so the second-order motion carries its own inertia: the mass of joint B and of the links moved
by the shortening load the links in bending. The outputs are the linear output operator of
U1 + U2: the axial DOFs of U2 hold the shortening itself (u' = -1/2 v'^2 for a free element),
and the position of a material point is exactly (x + u) e + v n in the nominal frame. In the
quasi-static limit (no inertia in (4), N_e = 0) the pass reproduces Eqs. (3)-(4) of
:mod:`core.fe.second_order_geometry` with rigid bearings (the frame is statically determinate:
the eigenstrain only rotates the links); test/core/fe/test_second_order_dynamic.py checks that.

U1 is known on the linear response's output grid; the integrator of (4) needs it at its stage
angles, which :func:`periodic_interpolation` gives by trigonometric interpolation over the
revolution (the linear state is periodic and smooth). Left out: the second-order terms of the
kinetic energy (Coriolis and centrifugal products of two elastic quantities) and the feedback
of U2 into the loads (no iteration: near resonance the fixed point diverges, as measured
against the peer).
"""

import numpy as np

from . import beam
from .modes import modal_damping
from .simulate import DEFAULT_STAGES, DEFAULT_STEPS, frozen_eigen, periodic_response
from ..kinematics import solve_kinematics
from ..validity import elastic_axial_forces

# Fewest output points per revolution of the linear pass the pass interpolates its state from.
MIN_POINTS = 24


def periodic_interpolation(values, angles, start_angle, spacing):
    """
    Trigonometric interpolation of one revolution of samples to other crank angles.

    Parameters
    ----------
    values : ndarray, shape (P, ...)
        Samples at ``start_angle + spacing * k``, k = 0..P-1, covering one revolution.
    angles : ndarray, shape (N,)
        Crank angles [rad] to evaluate at.
    start_angle, spacing : float
        Angle of the first sample and signed step between samples [rad].

    Returns
    -------
    ndarray, shape (N, ...)

    """
    count = values.shape[0]
    coefficients = np.fft.fft(values, axis=0) / count
    harmonics = np.fft.fftfreq(count, 1.0 / count)
    position = (np.asarray(angles, dtype=float) - start_angle) / spacing
    phase = np.exp(2j * np.pi * np.outer(position, harmonics) / count)
    return np.tensordot(phase, coefficients, axes=(1, 0)).real


def element_second_order_loads(local, element_length, elements, axial_stiffness, elastic_force):
    """
    Eq. (3): the link-frame second-order load of every element of a link, assembled.

    Parameters
    ----------
    local : ndarray, shape (N, 3 (e + 1))
        Link-frame linear nodal vectors u^L = T^T U1.
    element_length : float
        l [m].
    elements : int
        e.
    axial_stiffness : float
        EA [N].
    elastic_force : ndarray, shape (N, e)
        N_e per element [N] (tension > 0).

    Returns
    -------
    ndarray, shape (N, 3 (e + 1))
        Link-frame nodal loads [N, N m].

    """
    unit = beam.beam_geometric_stiffness(1.0, element_length)
    pull = np.zeros(6)
    pull[0], pull[3] = 1.0, -1.0
    out = np.zeros_like(local)
    for e in range(elements):
        block = slice(3 * e, 3 * e + 6)
        slope_load = local[:, block] @ unit                       # G_e u_e (G_e symmetric)
        shortening = 0.5 * np.einsum('ki,ki->k', slope_load, local[:, block])
        out[:, block] += (axial_stiffness * shortening / element_length)[:, None] * pull
        out[:, block] -= elastic_force[:, e, None] * slope_load
    return out


def second_order_load(linkage, displacement, crank_angle, speed, include_elastic_force=True):
    """
    F2 = sum T f^L: the system load of Eq. (4) from linear nodal vectors U1.

    Parameters
    ----------
    linkage : FlexibleLinkage
        The FE model.
    displacement : ndarray, shape (N, n)
        U1 at the crank angles.
    crank_angle : ndarray, shape (N,)
        Crank angles [rad].
    speed : float
        Crank speed [rad/s] (for the rigid-body part of the axial force).
    include_elastic_force : bool
        Keep the geometric-stiffness term of N_e (False: the eigenstrain alone).

    Returns
    -------
    ndarray, shape (N, n)

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    u = np.atleast_2d(displacement)
    angle = solve_kinematics(linkage.mechanism, theta).angle
    forces = elastic_axial_forces(linkage, u, theta, speed)
    mech = linkage.mechanism
    out = np.zeros_like(u)
    for link in linkage.links:
        mats = linkage.link_matrices[link]
        gather = linkage.gather(link, angle[link])
        local = np.einsum('kan,kn->ka', gather, u)
        elastic = forces[link] if include_elastic_force else np.zeros_like(forces[link])
        loads = element_second_order_loads(local, mats.element_length, mats.elements,
                                           mech.youngs_modulus * mech.links[link].area,
                                           elastic)
        out += np.einsum('kan,ka->kn', gather, loads)
    return out


def pass_matrices(linkage, response, zeta, matrices=None):
    """
    ``matrices(angles) -> (M, C_c + C_d, K + K_G + K_c, F2)`` of Eq. (4) for periodic_response.

    U1 at the integrator's stage angles comes from :func:`periodic_interpolation` of
    ``response``'s displacement. M, C and K are the linear pass's: modal damping ``zeta``, or
    the first three of ``matrices(angles)`` when the linear pass was run with ``matrices``
    (another damping model, e.g. :func:`core.fe.stiffness_damping.system_matrices`).
    """
    speed = response.info['speed_rad_s']
    start = float(response.crank_angle[0])
    spacing = float(response.crank_angle[1] - response.crank_angle[0])

    def modal(angles):
        system = linkage.assemble(angles)
        mass, gyro, stiffness, _ = system.evaluate(speed, 0.0)
        values, shapes = frozen_eigen(system, speed)
        return mass, gyro + modal_damping(mass, values, shapes, zeta), stiffness

    linear = modal if matrices is None else (lambda angles: matrices(angles)[:3])

    def second(angles):
        state = periodic_interpolation(response.displacement, angles, start, spacing)
        return (*linear(angles), second_order_load(linkage, state, angles, speed))

    return second


def dynamic_pass(linkage, response, zeta=None, steps=DEFAULT_STEPS, stages=DEFAULT_STAGES,
                 matrices=None):
    """
    Eq. (4) over one steady revolution: the second-order motion with its inertia.

    Parameters
    ----------
    linkage : FlexibleLinkage
        The model ``response`` was computed with.
    response : PeriodicResponse
        The linear pass, ``periodic_response(linkage, speed, method='full', ...)``, with at
        least :data:`MIN_POINTS` output points per revolution (its state is interpolated from
        them: at 391 rpm, 30 points change the pass's outputs by 4e-5 of their peak against
        720 points, 60 by 3e-9).
    zeta : float or None
        Modal damping ratio of the pass (None: the linear pass's).
    steps, stages : int
        Integration of the pass (steps a multiple of the response's points).
    matrices : callable or None
        The ``matrices`` the linear pass was run with (:func:`core.fe.simulate.periodic_response`),
        whose M, C and K the pass then uses in place of modal damping.

    Returns
    -------
    dict
        'crank_angle' (P,), 'linear' (P, 4), 'second' (P, 4) (the pass's outputs), 'total'
        (P, 4) [m]; 'displacement' U2 (P, n); 'info' of the pass.

    """
    if response.info['method'] != 'full':
        raise ValueError('the dynamic pass needs the full-order linear state (method full)')
    if response.crank_angle.shape[0] < MIN_POINTS:
        raise ValueError(f'the dynamic pass needs at least {MIN_POINTS} output points per '
                         f'revolution of the linear pass, got {response.crank_angle.shape[0]}')
    zeta = response.info['zeta'] if zeta is None else float(zeta)
    if zeta is None and matrices is None:
        zeta = linkage.mechanism.damping_ratio
    points = response.crank_angle.shape[0]
    second = periodic_response(linkage, response.info['speed_rad_s'], method='full',
                               steps=steps, points=points, stages=stages,
                               start_angle=float(response.crank_angle[0]),
                               matrices=pass_matrices(linkage, response, zeta, matrices))
    return {'crank_angle': response.crank_angle, 'linear': response.outputs,
            'second': second.outputs, 'total': response.outputs + second.outputs,
            'displacement': second.displacement, 'info': dict(second.info, zeta=zeta)}


__all__ = ['MIN_POINTS', 'periodic_interpolation', 'element_second_order_loads',
           'second_order_load', 'pass_matrices', 'dynamic_pass']
