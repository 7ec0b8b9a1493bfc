"""
Finite-element model of the flexible four-bar of Cho, Park & Lee (1992), Eqs. 22-36.

Each modelled link is a chain of beam elements (:mod:`core.fe.link`) in its moving frame (x
from its first joint to its second); the DOF layout and the gathers T^T of Eq. 25 are in
:mod:`core.fe.dofs`, the system terms of Eqs. 31-35 and A.4 (one function per equation, with
their derivation) in :mod:`core.fe.system`, the output operators in :mod:`core.fe.outputs`.
:class:`FlexibleLinkage` ties them together: it numbers the DOFs, builds the link matrices
and sums the links' shares of every equation at a set of crank angles (:meth:`assemble`).
"""

import dataclasses

import numpy as np

from . import outputs, system
from .dofs import gather_matrix, number_dofs
from .link import gauss_positions, link_matrices
from ..dynamics import axial_force
from ..kinematics import solve_kinematics
from ..options import ModelOptions

BEARING_MODELS = ('rigid', 'flexible')


def _check_options(mechanism, options):
    """Raise ValueError if ``options`` do not fit ``mechanism`` or name no bearing model."""
    if options.bearings not in BEARING_MODELS:
        raise ValueError(f'`bearings` must be one of {BEARING_MODELS}, '
                         f'got {options.bearings!r}')
    if not mechanism.is_flexible:
        raise ValueError('`mechanism` lacks the material or section data of the FE model')
    if options.bearings == 'flexible' and not mechanism.bearing_stiffness:
        raise ValueError('flexible bearings need `bearing_stiffness` in the mechanism')


def _empty_system(count, n):
    """Zero accumulators of :meth:`FlexibleLinkage.assemble` for N angles and n DOFs."""
    square = (count, n, n)
    return {'mass': np.zeros(square), 'stiffness': np.zeros(square),
            'gyroscopic': np.zeros(square),
            'coupling': {'a': np.zeros(square), 'w2': np.zeros(square)},
            'geometric': {piece: np.zeros(square) for piece in system.PIECES},
            'load': {piece: np.zeros((count, n)) for piece in system.PIECES},
            'link_mass': np.zeros((count, 3, n, n)),
            'link_stiffness': np.zeros((count, 3, n, n))}


class FlexibleLinkage:
    """
    DOF layout and assembly of the flexible four-bar (Cho, Park & Lee 1992, Secs. 2.2-2.3).

    Parameters
    ----------
    mechanism : Mechanism
        Needs material, sections and ``elements_per_link``; ``bearing_stiffness`` for
        flexible bearings.
    options : ModelOptions
        Crank, bearing, geometric stiffness and gravity options (default: the full model).

    Attributes
    ----------
    links : tuple of int
        Modelled links (0 crank, 1 coupler, 2 lever).
    dofs : DofMap
        The DOF layout (:func:`core.fe.dofs.number_dofs`).
    size : int
        Number of system DOFs n.
    dof_names : tuple of str
        Name of each DOF ('A.X', 'coupler.n1.v', 'B.lever.phi', ...).
    link_matrices : dict of int to LinkMatrices
        Matrices of every modelled link.
    bearing_stiffness : ndarray, shape (n, n)
        Bearing springs (Eq. 23) and the shaft spring k_t.

    """

    def __init__(self, mechanism, options=None):
        options = ModelOptions.full_model() if options is None else options
        _check_options(mechanism, options)
        if not options.gravity:
            mechanism = dataclasses.replace(mechanism, gravity=(0.0, 0.0))
        self.mechanism = mechanism
        self.options = options
        self.links = (1, 2) if options.rigid_crank else (0, 1, 2)
        self.dofs = number_dofs(mechanism, options, self.links)
        self.size = self.dofs.size
        self.dof_names = self.dofs.names
        self.bearing_stiffness = self.dofs.bearing_stiffness
        self.link_matrices = {}
        for link in self.links:
            spec = mechanism.links[link]
            self.link_matrices[link] = link_matrices(
                mechanism.youngs_modulus, spec.area, spec.second_moment, mechanism.density,
                spec.length, mechanism.elements_per_link, self.dofs.end_masses[link])

    # -- DOF layout -------------------------------------------------------------------------

    def end_masses(self, link):
        """Point masses [kg] at the first and last node of a modelled link (joint shares)."""
        return self.dofs.end_masses[link]

    def dof_index(self, name):
        """Index of the DOF called ``name`` (see ``dof_names``)."""
        return self.dofs.index(name)

    def gather(self, link, link_angle, order=0):
        """
        T^T of a link (Eq. 25) or its derivative in theta_L, at N link angles.

        Parameters
        ----------
        link : int
            A modelled link.
        link_angle : ndarray, shape (N,)
            theta_L [rad].
        order : int
            0 for T^T, 1 for dT^T/dtheta_L, 2 for d^2T^T/dtheta_L^2.

        Returns
        -------
        ndarray, shape (N, 3 (e + 1), n)

        """
        return gather_matrix(self.dofs, link, link_angle, order)

    def gauss_positions(self, link):
        """Gauss points of every element of a link [m], shape (e, GAUSS_POINTS)."""
        return gauss_positions(self.link_matrices[link])

    # -- assembly ---------------------------------------------------------------------------

    def kinematic_coefficients(self, crank_angle):
        """
        Link angles and the coefficients g1 = dtheta_L/dtheta, g2 = d^2theta_L/dtheta^2.

        Parameters
        ----------
        crank_angle : float or ndarray, shape (N,)
            Crank angles [rad].

        Returns
        -------
        angle, g1, g2 : ndarray, shape (3, N)
        states : dict
            LinkageState per unit piece: 'w2' (speed 1, accel 0), 'a' (speed 0, accel 1).

        """
        theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
        unit_speed = solve_kinematics(self.mechanism, theta, 1.0, 0.0)
        unit_accel = solve_kinematics(self.mechanism, theta, 0.0, 1.0)
        return (unit_speed.angle, unit_speed.omega, unit_speed.alpha,
                {'w2': unit_speed, 'a': unit_accel})

    def assemble(self, crank_angle):
        """
        Frozen system at crank angles (Eqs. 31-35 and A.4), see :class:`FrozenSystem`.

        Parameters
        ----------
        crank_angle : float or ndarray, shape (N,)
            Crank angles [rad].

        Returns
        -------
        FrozenSystem

        """
        theta = np.atleast_1d(np.asarray(crank_angle, dtype=float))
        angle, g1, g2, states = self.kinematic_coefficients(theta)
        out = _empty_system(theta.shape[0], self.size)
        forces = self._axial_forces(theta, states) if self.options.geometric_stiffness else None
        gravity = complex(*self.mechanism.gravity)
        for link in self.links:
            mats = self.link_matrices[link]
            t0, t1, t2 = (self.gather(link, angle[link], order) for order in range(3))
            p1, p2 = g1[link][:, None, None], g2[link][:, None, None]
            m_tt = system.system_mass(t0, mats)
            out['link_mass'][:, link] = m_tt
            out['link_stiffness'][:, link] = system.system_stiffness(t0, mats)
            out['mass'] += m_tt
            out['stiffness'] += out['link_stiffness'][:, link]
            transport = system.transport_matrix(t0, t1, mats)
            out['gyroscopic'] += system.convective_damping(p1, transport)
            coupling = system.convective_stiffness(t0, t1, t2, mats, p1, p2, transport, m_tt)
            for piece, value in coupling.items():
                out['coupling'][piece] += value
            accelerations = {piece: np.stack([states[piece].point(link, x)[2]
                                              for x in mats.nodes], axis=1)
                             for piece in ('a', 'w2')}
            load = system.system_load(t0, mats, angle[link], gravity, accelerations)
            for piece, value in load.items():
                out['load'][piece] += value
            if forces is not None:
                geometric = system.geometric_stiffness(t0, mats, forces[link])
                for piece, value in geometric.items():
                    out['geometric'][piece] += value
        out['stiffness'] += self.bearing_stiffness
        return system.FrozenSystem(crank_angle=theta, **out)

    def _axial_forces(self, theta, states):
        """
        Axial forces at the Gauss points: {link: {piece: array (N, e, GAUSS_POINTS)}}.

        From the rigid-body analysis, linear in (gravity, a, w^2): '1' = gravity at rest,
        'a' and 'w2' = unit crank acceleration and unit speed squared without gravity.
        ``dynamics.axial_force(mechanism, state, link, x)`` is called with x of shape (m,)
        and must return the tension [N], shape (N, m) for the N angles of ``state``.
        """
        still = solve_kinematics(self.mechanism, theta, 0.0, 0.0)
        weightless = dataclasses.replace(self.mechanism, gravity=(0.0, 0.0))
        cases = {'1': (self.mechanism, still), 'a': (weightless, states['a']),
                 'w2': (weightless, states['w2'])}
        out = {link: {} for link in self.links}
        for piece, (mech, state) in cases.items():
            for link in self.links:
                x = self.gauss_positions(link)
                values = np.asarray(axial_force(mech, state, link, x.ravel()), dtype=float)
                out[link][piece] = values.reshape(theta.shape[0], *x.shape)
        return out

    # -- outputs ----------------------------------------------------------------------------

    def point_operator(self, link, x, crank_angle):
        """Return the deflection of point x of a link per DOF: :func:`outputs.point_operator`."""
        return outputs.point_operator(self, link, x, crank_angle)

    def output_operator(self, crank_angle):
        """Return the output deflections per DOF, (N, 4, n): :func:`outputs.output_operator`."""
        return outputs.output_operator(self, crank_angle)

    def shape_operator(self, crank_angle, points_per_element=8):
        """Return positions and deflection operators of links: :func:`outputs.shape_operator`."""
        return outputs.shape_operator(self, crank_angle, points_per_element)

    def element_axial_forces(self, displacement, crank_angle):
        """Return element axial forces of system vectors: :func:`outputs.element_axial_forces`."""
        return outputs.element_axial_forces(self, displacement, crank_angle)


__all__ = ['BEARING_MODELS', 'FlexibleLinkage']
