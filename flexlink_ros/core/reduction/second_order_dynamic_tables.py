"""
The reduced model's tables of the dynamic second-order load, and their numpy evaluation.

The dynamic second-order pass (:mod:`core.fe.second_order_dynamic`) loads the
linear model once more with the second-order terms of the strain energy evaluated on the
linear state U1: per element the axial eigenstrain (EA s_e / l)[1, 0, 0, -1, 0, 0] and the
geometric stiffness of the elastic axial force, -N_e G_e u_e (its Eq. 3), gathered by the
links' T(theta_L). On a constant basis U1 = V q the link-frame nodal vector of link L is ::

    u^L = (B0 + cos(theta_L) Bc + sin(theta_L) Bs) q,     B_h = T_h V

(only the end-node translations rotate: :func:`core.fe.second_order_reduced.gather_harmonics`),
N_e = EA (u_2 - u_1) / l - F_r(theta, w, a) with the rigid-body axial force F_r linear in the
monomials (1 (gravity), w^2, a), and the reduced load is ``f2 = sum_L (B^L)^T f^L``: per link
three constant (3 (e + 1)) x r matrices, the 6 x 6 unit geometric stiffness of its elements,
and a periodic spline of the link angles' cos and sin and of F_r's three coefficients per
element. :func:`build_tables` makes the plain arrays (names ``dynamic_*``, part of a model
built with ``second_order='dynamic'``); :class:`DynamicLoad` evaluates f2 in numpy (the twin of the
compiled loads, core/estimation/_second_order_dynamic.c).
"""

import dataclasses

import numpy as np

from .cells import CELL_POWERS, periodic_cell_coefficients
from ..fe.beam import beam_geometric_stiffness
from ..fe.linkage import FlexibleLinkage
from ..fe.second_order_reduced import gather_harmonics
from ..kinematics import solve_kinematics
from ..numerics import TWO_PI
from ..validity import rigid_element_axial_forces

ARRAY_NAMES = ('dynamic_pieces', 'dynamic_links', 'dynamic_link_values', 'dynamic_unit',
               'dynamic_scalars')
# Monomials of the rigid-body axial force F_r, in the scalars' order: 1 (gravity), w^2, a.
FORCE_MONOMIALS = 3


def rigid_force_coefficients(linkage, theta):
    """
    F_r per element as 1, w^2, a coefficients at crank angles: (N, 3, elements of all links).

    F_r is linear in w^2 and a (the rigid-body accelerations are) plus the gravity term.
    """
    def flat(speed, accel):
        forces = rigid_element_axial_forces(linkage, theta, speed, accel)
        return np.concatenate([forces[link] for link in linkage.links], axis=1)

    constant = flat(0.0, 0.0)
    return np.stack([constant, flat(1.0, 0.0) - constant, flat(0.0, 1.0) - constant], axis=1)


def build_tables(linkage, basis, grid_size):
    """
    Plain arrays of the reduced dynamic second-order load of a reduced model.

    Returns
    -------
    dict of str to ndarray
        'dynamic_pieces' (3, D, r): B0, Bc, Bs of all links stacked by rows;
        'dynamic_links' int32 (L, 3): first row, elements, first element of each link;
        'dynamic_link_values' (L, 2): element length [m], EA [N];
        'dynamic_unit' (L, 6, 6): G_e for unit tension;
        'dynamic_scalars' (N, CELL_POWERS, 2 L + 3 E): spline of cos, sin of each link angle,
        then F_r's 1, w^2, a coefficients of every element.

    """
    mech = linkage.mechanism
    pieces, links, values, units = [], [], [], []
    row = element = 0
    for link in linkage.links:
        mats = linkage.link_matrices[link]
        pieces.append(np.einsum('han,nr->har', gather_harmonics(linkage, link), basis))
        links.append((row, mats.elements, element))
        values.append((mats.element_length, mech.youngs_modulus * mech.links[link].area))
        units.append(beam_geometric_stiffness(1.0, mats.element_length))
        row += pieces[-1].shape[1]
        element += mats.elements
    theta = TWO_PI * np.arange(grid_size) / grid_size
    angle = solve_kinematics(mech, theta).angle
    trig = np.stack([f(angle[link]) for link in linkage.links for f in (np.cos, np.sin)],
                    axis=1)
    forces = rigid_force_coefficients(linkage, theta).reshape(grid_size, -1)
    return {'dynamic_pieces': np.concatenate(pieces, axis=1),
            'dynamic_links': np.array(links, dtype=np.int32),
            'dynamic_link_values': np.array(values, dtype=float),
            'dynamic_unit': np.array(units, dtype=float),
            'dynamic_scalars': periodic_cell_coefficients(np.hstack([trig, forces]))}


def load_for_model(mechanism, options, model):
    """
    Return the :class:`DynamicLoad` of a reduced model built with ``options``.

    The model's own tables if it has them (``second_order='dynamic'``), else built (not
    cached) for its basis.
    """
    if model.dynamic_second_order is not None:
        return DynamicLoad(model.dynamic_second_order)
    if options.elements_per_link is not None:
        mechanism = dataclasses.replace(mechanism, elements_per_link=options.elements_per_link)
    linkage = FlexibleLinkage(mechanism, options)
    return DynamicLoad(build_tables(linkage, model.basis, model.grid_size))


class DynamicLoad:
    """
    The numpy evaluation of :func:`build_tables`'s arrays: f2(q) at a crank state.

    Parameters
    ----------
    arrays : dict of str to ndarray
        :data:`ARRAY_NAMES`.

    """

    def __init__(self, arrays):
        self.arrays = {name: np.ascontiguousarray(arrays[name]) for name in ARRAY_NAMES}
        self.pieces = self.arrays['dynamic_pieces']
        self.scalars = self.arrays['dynamic_scalars']
        self.grid_size = self.scalars.shape[0]
        self.link_count = self.arrays['dynamic_links'].shape[0]
        self.elements = int(self.arrays['dynamic_links'][:, 1].sum())
        self.links = []
        for (row, elements, first), (length, ea), unit in zip(
                self.arrays['dynamic_links'].tolist(), self.arrays['dynamic_link_values'],
                self.arrays['dynamic_unit']):
            rows = slice(row, row + 3 * (elements + 1))
            blocks = 3 * np.arange(elements)[:, None] + np.arange(6)[None, :]
            self.links.append((rows, blocks, slice(first, first + elements), float(length),
                               float(ea), unit))

    def spline_scalars(self, angle):
        """Return the spline's scalars at a crank angle [rad] (cos/sin, then F_r terms)."""
        x = (angle % TWO_PI) * self.grid_size / TWO_PI
        k = min(int(x), self.grid_size - 1)
        t = x - k
        return np.dot(t ** np.arange(CELL_POWERS), self.scalars[k])

    def load(self, q, angle, speed, accel, static_q=None):
        """
        Return the reduced second-order load f2 (r,) of the linear state q at a crank state.

        Also its eigenstrain part alone (the load whose static response the quasi-static
        correction is): ``(f2, f2_eigenstrain)``. ``static_q``: the reduced static response
        K_r^-1 f_r at the crank state; the elastic axial force is then that of V (q - static_q)
        (the basis misses most of the static axial stretch F_r / EA: from V q alone, N - F_r is
        off by F_r).
        """
        return self.load_at_scalars(q, self.spline_scalars(angle), speed, accel, static_q)

    def load_at_scalars(self, q, scalars, speed, accel, static_q=None):
        """:meth:`load` with the spline's scalars at the crank angle given."""
        trig = 2 * self.link_count
        coef = scalars[trig:].reshape(FORCE_MONOMIALS, self.elements)
        rigid = coef[0] + speed * speed * coef[1] + accel * coef[2]
        out = np.zeros((2, self.pieces.shape[2]))
        for n, (rows, blocks, elements, length, ea, unit) in enumerate(self.links):
            gather = (self.pieces[0, rows] + scalars[2 * n] * self.pieces[1, rows]
                      + scalars[2 * n + 1] * self.pieces[2, rows])
            reference = rigid[elements]
            if static_q is not None:
                axial = (gather @ static_q)[blocks[:, [0, 3]]]
                reference = ea / length * (axial[:, 1] - axial[:, 0])
            out += element_loads(gather @ q, blocks, length, ea, unit, reference) @ gather
        return out[0], out[1]


def element_loads(local, blocks, length, ea, unit, rigid_force):
    """
    Eq. (3) of :mod:`core.fe.second_order_dynamic` on one link, vectorised over its elements.

    ``local`` the link-frame nodal vector u^L (3 (e + 1),), ``blocks`` (e, 6) its element
    index blocks, ``rigid_force`` F_r per element: returns the assembled link-frame load and
    its eigenstrain part, (2, 3 (e + 1)).
    """
    element = local[blocks]                                     # (e, 6)
    slope = element @ unit                                      # G_e u_e
    shortening = 0.5 * np.einsum('ei,ei->e', slope, element)
    elastic = ea / length * (element[:, 3] - element[:, 0]) - rigid_force
    loads = np.zeros((2,) + element.shape)
    loads[:, :, 0] += ea * shortening / length
    loads[:, :, 3] -= ea * shortening / length
    loads[0] -= elastic[:, None] * slope
    out = np.zeros((2, local.size))
    for part in (0, 1):
        np.add.at(out[part], blocks, loads[part])
    return out
