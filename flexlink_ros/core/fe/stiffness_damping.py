"""
Stiffness-proportional (Kelvin-Voigt) damping of the KED model, objective.

The peer (:mod:`studies.peer_exudyn`) damps the material strain rates: axial force
``beta E A eps'`` and bending moment ``beta E I kappa'`` in every element, and ``c = beta k`` on
the deflection rate of each bearing spring. This module gives the same damping to the linear
KED model of :mod:`core.fe.linkage`, where the elastic coordinates U are mixed: interior nodes in
the moving link frames, joint (end) node translations in the ground frame.

Derivation. For link L at rigid angle theta_L(t), rate w_L, the local element vector is
``u^L = T^T(theta_L) U`` (Eq. 25; ``FlexibleLinkage.gather``). The (linear) strains of an
element are ``eps = B u^L`` (axial (u2 - u1)/l_e, curvature v''), with ``K_L = int B^T D B``.
Kelvin-Voigt stress resultants ``beta D eps'`` do the virtual work
``-int d(eps)^T beta D eps' = -dU^T beta T K_L u^L'`` (virtual displacements at a frozen
time, ``d u^L = T^T dU``), so the damping force on the system is ::

    F_beta = beta sum_L T K_L u^L' + beta K_b U'
    u^L'   = T^T U' + w_L D1^T U,        D1^T = dT^T/dtheta_L (gather order 1)

i.e. ``F_beta = C_beta U' + D_beta U`` with ::

    C_beta = beta (sum_L T K_L T^T + K_b) = beta K          (symmetric, PSD; Eq. 32's K)
    D_beta = beta sum_L w_L T K_L D1^T,   w_L = g1_L w      (not symmetric, linear in w)

C_beta is the naive ``beta K``; the naive form omits D_beta U. D1^T U is non-zero only on the
end-node translation rows, where ``d(R^T)/dtheta = -S R^T`` (S the +90 degree rotation) gives
``D1^T U = -S u_end^L``: the apparent velocity, in the rotating link frame, of an end node that
stays put in the ground frame. It is a real strain rate: a transverse end deflection v_e rotating
relative to the frame changes the end element's length at the rate w_L v_e (the naive form's
spurious axial force ``beta E A w_L v_e / l_e``). The transverse end rate -w_L u_e is, on the
end element, mostly a rigid rotation of that element in the link frame (v = -w_L u_e x / l_e,
phi = -w_L u_e / l_e): that part produces no strain and is not damped; what is left is the end
rotation rate +w_L u_e / l_e against the element's chord, a bending rate. No explicit
projection is needed: K_L annihilates every element rigid-body field (translations and the
infinitesimal rotation), so ``K_L D1^T U = K_L P (D1^T U)`` with P the projection on
strain-producing fields. Terms of order w_L d d' (the rotation of the deformed shape relative
to the frame, and the change of the chord direction) are second order in the deflection d and
dropped, as everywhere in the linear KED model. Under a rigid rotation of the deformed linkage at
any constant rate (u^L constant in every link frame: ground-frame U' = W S U on the end
translations, zero elsewhere) ``u^L' = 0`` and the element force is zero identically.

Bearings (peer convention): ``c = beta k`` on the ground-frame relative velocity of the two
members (Exudyn's Cartesian spring-damper), ``beta K_b U'``; the input-shaft spring k_t gets
``beta k_t`` on its rotation rate. That damper is objective for the mechanism's own motions but
not under a change of observer: a bearing deflection Delta rotating at W dissipates
``beta k W^2 |Delta|^2`` (as in the peer).

With ``M U'' + (w C1 + C_d) U' + (K + K_G + K_c) U = R`` (:class:`core.fe.system.FrozenSystem`),
beta damping adds C_beta to the damping and ``w Kb1`` (``Kb1 = beta sum g1_L T K_L D1^T``) to the
stiffness; :func:`system_matrices` returns the four matrices in :meth:`FrozenSystem.evaluate`'s
form. Modal damping is then usually off (zeta = 0): beta alone gives every frozen mode
``zeta_i = beta omega_i / 2`` (C_beta = beta K is classical damping at rest).
"""

import numpy as np

from .beam import beam_stiffness

# +90 degree rotation (I_s of Eq. 21).
_S = np.array([[0.0, -1.0], [1.0, 0.0]])


def link_local_rate(model, link, link_angle, link_rate, displacement, velocity):
    """
    Link-frame element rates ``u^L' = T^T U' + w_L (dT^T/dtheta_L) U``.

    Parameters
    ----------
    model : FlexibleLinkage
        The FE model (:class:`core.fe.linkage.FlexibleLinkage`).
    link : int
        A modelled link.
    link_angle, link_rate : ndarray, shape (N,)
        theta_L [rad] and w_L [rad/s].
    displacement, velocity : ndarray, shape (N, n)
        U and U'.

    Returns
    -------
    ndarray, shape (N, 3 (e + 1))

    """
    angle = np.atleast_1d(np.asarray(link_angle, dtype=float))
    rate = np.broadcast_to(np.asarray(link_rate, dtype=float), angle.shape)
    t0 = model.gather(link, angle, 0)
    t1 = model.gather(link, angle, 1)
    disp, vel = np.atleast_2d(displacement), np.atleast_2d(velocity)
    return (np.einsum('kan,kn->ka', t0, vel)
            + rate[:, None] * np.einsum('kan,kn->ka', t1, disp))


def link_damping_matrices(model, link, link_angle, link_rate, beta):
    """
    One link's share ``C_L = beta T K_L T^T`` and ``D_L = beta w_L T K_L D1^T``.

    So that the link's damping force is ``C_L U' + D_L U = beta T K_L u^L'``.

    Returns
    -------
    damping, rotation : ndarray, shape (N, n, n)

    """
    angle = np.atleast_1d(np.asarray(link_angle, dtype=float))
    rate = np.broadcast_to(np.asarray(link_rate, dtype=float), angle.shape)
    k_local = model.link_matrices[link].stiffness
    t0 = model.gather(link, angle, 0)
    t1 = model.gather(link, angle, 1)
    damping = beta * np.einsum('kai,ab,kbj->kij', t0, k_local, t0, optimize=True)
    rotation = beta * rate[:, None, None] * np.einsum('kai,ab,kbj->kij', t0, k_local, t1,
                                                      optimize=True)
    return damping, rotation


def bearing_damping_matrix(model, beta):
    """``beta K_b``: c = beta k on every bearing spring and beta k_t on the shaft, (n, n)."""
    return beta * np.asarray(model.bearing_stiffness)


def element_damping_matrices(model, crank_angle, beta):
    """
    ``C_el = beta sum_L T K_L T^T`` and ``Kb1 = beta sum_L g1_L T K_L D1^T`` at crank angles.

    ``Kb1`` is D_beta per unit crank speed: ``D_beta = w Kb1``.

    Returns
    -------
    damping, rotation_per_speed : ndarray, shape (N, n, n)

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    angle, g1, _, _ = model.kinematic_coefficients(theta)
    n = model.size
    damping = np.zeros((theta.shape[0], n, n))
    rotation = np.zeros_like(damping)
    for link in model.links:
        c, d = link_damping_matrices(model, link, angle[link], g1[link], beta)
        damping += c
        rotation += d
    return damping, rotation


def stiffness_damping_terms(model, crank_angle, speed, beta):
    """
    C_beta and D_beta of the assembled model at crank angles and crank speed w.

    ``C_beta = beta (sum_L T K_L T^T + K_b)`` (= beta K), ``D_beta = w Kb1``; the damping force
    is ``C_beta U' + D_beta U``. (The crank acceleration does not enter: only rates do.)

    Returns
    -------
    damping, stiffness : ndarray, shape (N, n, n)

    """
    damping, rotation = element_damping_matrices(model, crank_angle, beta)
    return damping + bearing_damping_matrix(model, beta), speed * rotation


def damping_force(model, crank_angle, speed, beta, displacement, velocity):
    """Objective damping force ``C_beta U' + D_beta U`` [N, N m], shape (N, n)."""
    c, d = stiffness_damping_terms(model, crank_angle, speed, beta)
    return (np.einsum('kij,kj->ki', c, np.atleast_2d(velocity))
            + np.einsum('kij,kj->ki', d, np.atleast_2d(displacement)))


def naive_damping_force(model, crank_angle, beta, velocity):
    """Non-objective ``beta K U'`` on the mixed coordinates (no D_beta U), shape (N, n)."""
    c, _ = stiffness_damping_terms(model, crank_angle, 0.0, beta)
    return np.einsum('kij,kj->ki', c, np.atleast_2d(velocity))


def element_resultants(model, link, local_rate, beta):
    """
    Damping resultants of every element of a link from its link-frame rates u^L'.

    Axial force ``N = beta E A (u2' - u1') / l_e`` (= beta E A eps' for a uniform stretch
    rate) and the end moments of ``beta K_e u_e'`` (for a uniform curvature rate kappa' the
    element's end moments are -/+ beta E I kappa' and its shear forces zero).

    Parameters
    ----------
    model : FlexibleLinkage
        The FE model (:class:`core.fe.linkage.FlexibleLinkage`).
    link : int
        A modelled link.
    local_rate : ndarray, shape (N, 3 (e + 1))
        From :func:`link_local_rate`.
    beta : float
        Stiffness-proportional damping [s].

    Returns
    -------
    dict
        'axial' (N, e) [N]; 'nodal' (N, e, 6): beta K_e u_e' per element in the
        (u1, v1, phi1, u2, v2, phi2) order [N, N m].

    """
    mats = model.link_matrices[link]
    rate = np.atleast_2d(local_rate)
    spec = model.mechanism.links[link]
    axial = (beta * model.mechanism.youngs_modulus * spec.area / mats.element_length
             * np.diff(rate[:, 0::3], axis=1))
    k_e = _element_stiffness(model, link)
    nodal = np.stack([beta * rate[:, 3 * e:3 * e + 6] @ k_e.T for e in range(mats.elements)],
                     axis=1)
    return {'axial': axial, 'nodal': nodal}


def _element_stiffness(model, link):
    """Return the (6, 6) element stiffness A.3 of a link's elements (all equal)."""
    spec = model.mechanism.links[link]
    return beam_stiffness(model.mechanism.youngs_modulus, spec.area, spec.second_moment,
                          model.link_matrices[link].element_length)


def ground_translation_dofs(model):
    """Pairs (iX, iY) of the ground-frame translation DOFs (joint nodes), from ``dof_names``."""
    names = model.dof_names
    return [(i, names.index(name[:-1] + 'Y')) for i, name in enumerate(names)
            if name.endswith('.X')]


def rigid_rotation_velocity(model, displacement, rate):
    """
    U' of the deformed linkage turning rigidly at ``rate`` [rad/s] (observer change).

    Every link-frame component of U stays constant and the ground-frame translations turn:
    ``(X, Y)' = rate S (X, Y)``. With every link rate equal to ``rate`` this keeps u^L constant.
    """
    disp = np.atleast_2d(np.asarray(displacement, dtype=float))
    out = np.zeros_like(disp)
    for ix, iy in ground_translation_dofs(model):
        out[:, ix] = -rate * disp[:, iy]
        out[:, iy] = rate * disp[:, ix]
    return out


def system_matrices(model, crank_angle, speed, beta, accel=0.0):
    """
    M, C, K, R of the full-order equation with beta damping, in ``FrozenSystem.evaluate`` form.

    ``M U'' + C U' + K U = R`` with ``C = w C1 + C_beta`` and ``K = K + K_G + K_c + D_beta``
    at crank speed w and acceleration a (no modal damping: :func:`core.fe.simulate.
    periodic_response` adds both, ``beta`` and ``zeta``).

    Parameters
    ----------
    model : FlexibleLinkage
        The FE model (:class:`core.fe.linkage.FlexibleLinkage`).
    crank_angle : ndarray, shape (N,)
        Crank angles [rad].
    speed, accel : float
        Crank speed w [rad/s] and acceleration a [rad/s^2].
    beta : float
        Stiffness-proportional damping [s].

    Returns
    -------
    mass, damping, stiffness : ndarray, shape (N, n, n)
    load : ndarray, shape (N, n)

    """
    theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
    system = model.assemble(theta)
    mass, gyro, stiffness, load = system.evaluate(speed, accel)
    c_beta, d_beta = stiffness_damping_terms(model, theta, speed, beta)
    return mass, gyro + c_beta, stiffness + d_beta, load


__all__ = ['link_local_rate', 'link_damping_matrices', 'bearing_damping_matrix',
           'element_damping_matrices', 'stiffness_damping_terms', 'damping_force',
           'naive_damping_force', 'element_resultants', 'ground_translation_dofs',
           'rigid_rotation_velocity', 'system_matrices']
