"""
Tables of the reduced geometrically nonlinear model over the crank angle.

The nonlinear full order (:mod:`core.fe.nonlinear_response`) is projected on one constant
basis V (n x m): U = V eta. The basis is the mass-weighted POD (:func:`.basis.mass_weighted_pod`)
of the lowest frozen modes of (K0, M) at a few crank angles and of three static families:
the responses to the load pieces (which carry the rigid-body axial strain the dropped K_G
linearises) and, per flexible link, the response ``K0^-1 c_L`` to a pair of axial end forces
(which carries the loop's give to the chord shortening and its inertia: without it the
reduced model would lock the shortening, with its inertia missing it is 50-60 % off).
The basis keeps every direction the snapshots need (:func:`basis_size`: singular values down
to 1e-3 of the largest) and no more; the 8 lowest modes per angle suffice against the peer
through the resonance, so the basis is 20 vectors for cho1992 with bearing springs (54 DOFs)
where 20 modes per angle needed 30.

Per-link lumping of the axial force. Each flexible link L carries one axial force, from its
elongation and its chord shortening summed over its elements (the von Karman strain
averaged over the link instead of over each element) ::

    e_L   = c_L^T eta + 1/2 eta^T g_L eta,
            c_L = sum_e b^T T_e V,  g_L = sum_e (T_e V)^T G_e (T_e V)
    e_L'  = (c_L + g_L eta)^T eta' + w (c1_L^T eta + eta^T h_L eta)     (link-frame rate)
    N_L   = (E A / L) (e_L + beta e_L')                                  (Kelvin-Voigt)

(T_e the element gather, Eq. 25; T1_e its derivative in theta_L times dtheta_L/dtheta, so that
``T_e U' + w T1_e U`` is the link-frame rate; G_e A.4 at unit tension.) The elastic force is the
projected linear element force plus the change the lumped strain makes to it, so that with
``g = h = 0`` the model is the Galerkin projection of the linear full order exactly:
``f = K_el eta + beta (K_el eta' + w K1 eta) + sum_L [N_L (c_L + g_L eta) - (E A / L) c_L
(c_L^T eta + beta (c_L^T eta' + w c1_L^T eta))]``. E = number of flexible links (2 with a
rigid crank) instead of 16-24 elements: the nonlinear terms cost O(E m^2) per evaluation.

Every quantity is tabulated at N periodic grid nodes with its derivative in theta (FFT) and
read by cubic Hermite interpolation: one weighted sum of four node rows gives every matrix
at a stage angle.
"""

import dataclasses

import numpy as np

from .basis import frozen_modes, mass_weighted_pod
from .soft_basis import angle_derivatives
from ..fe.nonlinear_strain import AXIAL, element_gather, model_elements

# Grid nodes over one revolution and the angles whose modes and statics span the basis.
GRID_NODES = 120
BASIS_ANGLES = 24
BASIS_MODES = 8
# The basis keeps every POD direction whose singular value is at least this fraction of the
# largest, the snapshot set's numerical rank at that tolerance (cho1992, 8 elements per link:
# 20 directions with bearing springs, 14 with pins, 27 with a flexible crank).
BASIS_TOLERANCE = 1e-3
# Matrices (m x m) and vectors (m) of the linear part, by name.
MATRICES = ('mass', 'gyroscopic', 'coupling_a', 'coupling_w2', 'elastic', 'elastic_rate',
            'geometric_1', 'geometric_a', 'geometric_w2')
VECTORS = ('load_1', 'load_a', 'load_w2')
LINK_FIELDS = ('chord', 'chord_rate', 'shortening', 'shortening_rate')


@dataclasses.dataclass
class NonlinearTables:
    """
    The reduced nonlinear model: node values and their theta derivatives, flat per node.

    Attributes
    ----------
    values, slopes : ndarray, shape (N, F)
        Every field at the grid nodes and its derivative in theta [per rad].
    size, links, outputs : int
        m, E (flexible links) and the output channels.
    axial_stiffness : ndarray, shape (E,)
        E A / L of each flexible link [N/m].
    link_length : ndarray, shape (E,)
        L of each flexible link [m].
    bearing : ndarray, shape (m, m)
        Projected bearing springs (constant).
    beta : float
        Kelvin-Voigt damping [s] on the strain rates and the bearing springs.
    basis : ndarray, shape (n, m)
        V, for lifting eta to the full order.

    """

    values: np.ndarray
    slopes: np.ndarray
    size: int
    links: int
    outputs: int
    axial_stiffness: np.ndarray
    link_length: np.ndarray
    bearing: np.ndarray
    beta: float
    basis: np.ndarray

    @property
    def grid_size(self):
        """Return the number of grid nodes N."""
        return self.values.shape[0]

    def layout(self):
        """Return {name: (start, shape)} of the fields in a flat row (computed once)."""
        cached = self.__dict__.get('_layout')
        if cached is None:
            cached = self.__dict__['_layout'] = self._make_layout()
        return cached

    def _make_layout(self):
        m, e = self.size, self.links
        shapes = [(name, (m, m)) for name in MATRICES] + [(name, (m,)) for name in VECTORS]
        shapes += [('output', (self.outputs, m)), ('chord', (e, m)), ('chord_rate', (e, m)),
                   ('shortening', (e, m, m)), ('shortening_rate', (e, m, m))]
        out, start = {}, 0
        for name, shape in shapes:
            out[name] = (start, shape)
            start += _count(shape)
        return out

    def at(self, theta, names=None):
        """
        Return the fields (every one, or ``names``) at crank angles theta (s,), {name: (s, ...)}.

        Cubic Hermite interpolation between the grid nodes with their FFT slopes. Every field
        read at once is a view of one buffer that the next such call overwrites (the rows are
        large: a fresh allocation each time costs more than the interpolation).
        """
        layout = self.layout()
        names = tuple(layout) if names is None else names
        if len(names) == 1:
            start, shape = layout[names[0]]
            columns = slice(start, start + _count(shape))
            return {names[0]: self._interpolate(theta, columns).reshape((-1,) + shape)}
        row = self._interpolate(theta, slice(None), reuse=True)
        return {name: row[:, start:start + _count(shape)].reshape((-1,) + shape)
                for name, (start, shape) in layout.items() if name in names}

    def at_rows(self, theta):
        """Return every field at theta (s,) as flat rows (s, F): a buffer the next call reuses."""
        return self._interpolate(theta, slice(None), reuse=True)

    def _interpolate(self, theta, columns, reuse=False):
        """
        Hermite-interpolated flat rows (s, F') of the columns ``columns``.

        Read from the node values and slopes as the compiled step reads them (the same
        weights, the same order of the sums); no per-cell copy of the tables is kept (it
        would be twice their size).
        """
        theta = np.atleast_1d(np.asarray(theta, dtype=float))
        nodes = self.grid_size
        position = np.mod(theta, 2.0 * np.pi) * (nodes / (2.0 * np.pi))
        cell = np.minimum(position.astype(int), nodes - 1)
        t = position - cell
        spacing = 2.0 * np.pi / nodes
        values, slopes = self.values[:, columns], self.slopes[:, columns]
        out = None
        if reuse:
            out = self.__dict__.get('_row')
            if out is None or out.shape[0] != theta.shape[0]:
                out = self.__dict__['_row'] = np.empty((theta.shape[0], values.shape[1]))
        else:
            out = np.empty((theta.shape[0], values.shape[1]))
        for i, (k, ti) in enumerate(zip(cell.tolist(), t.tolist())):
            following = k + 1 if k + 1 < nodes else 0
            t2, t3 = ti * ti, ti * ti * ti
            out[i] = ((2.0 * t3 - 3.0 * t2 + 1.0) * values[k]
                      + spacing * (t3 - 2.0 * t2 + ti) * slopes[k]
                      + (3.0 * t2 - 2.0 * t3) * values[following]
                      + spacing * (t3 - t2) * slopes[following])
        return out

    def to_arrays(self):
        """Return the arrays to store (npz, no pickling) and the scalars as metadata."""
        arrays = {'values': self.values, 'slopes': self.slopes,
                  'axial_stiffness': self.axial_stiffness, 'link_length': self.link_length,
                  'bearing': self.bearing,
                  'basis': self.basis}
        meta = {'size': self.size, 'links': self.links, 'outputs': self.outputs,
                'beta': self.beta}
        return arrays, meta

    @classmethod
    def from_arrays(cls, arrays, meta):
        """Rebuild from :meth:`to_arrays`."""
        return cls(values=arrays['values'], slopes=arrays['slopes'], size=int(meta['size']),
                   links=int(meta['links']), outputs=int(meta['outputs']),
                   axial_stiffness=arrays['axial_stiffness'],
                   link_length=arrays['link_length'], bearing=arrays['bearing'],
                   beta=float(meta['beta']), basis=arrays['basis'])


def _count(shape):
    """Return the number of values of an array of ``shape``."""
    out = 1
    for size in shape:
        out *= size
    return out


def link_chord_gradients(model, elements, gather):
    """
    Per flexible link, ``sum_e T_e^T b``: the link's elongation per coordinate.

    ``gather``: element gathers (N, E_el, 6, k) of any coordinates; returns (N, links, k).
    """
    per_element = np.einsum('a,neak->nek', AXIAL, gather)
    return np.stack([per_element[:, elements.link == link].sum(axis=1) for link in model.links],
                    axis=1)


def element_gathers(model, elements, angles):
    """Element gathers T_e and T1_e (per unit crank speed) at crank angles, (N, E, 6, n)."""
    link_angle, g1, _, _ = model.kinematic_coefficients(angles)
    t0 = {link: model.gather(link, link_angle[link], 0) for link in model.links}
    t1 = {link: g1[link][:, None, None] * model.gather(link, link_angle[link], 1)
          for link in model.links}
    return element_gather(elements, t0), element_gather(elements, t1)


def basis_size(singular_values, tolerance=BASIS_TOLERANCE):
    """
    Return how many POD directions the basis keeps: singular values >= tolerance x the largest.

    Dropping a direction above that level drops one the snapshots need: with 20 modes per
    angle, cho1992 with bearing springs has 30 such directions (the 30th at 1.1e-3 of the
    largest, the 31st at 3e-5), and 29 directions were 10 / 20 % off the peer at 391 / 405 rpm.
    """
    values = np.asarray(singular_values, dtype=float)
    if values.size == 0 or not values[0] > 0.0:
        return 0
    return int(np.count_nonzero(values >= tolerance * values[0]))


def basis_snapshots(model, angles=BASIS_ANGLES, modes=BASIS_MODES):
    """
    Return the snapshot columns (n, K) of the basis and the cycle-mean mass (n, n).

    At ``angles`` crank angles: the lowest ``modes`` frozen modes of (K0, M) weighted by
    omega_1 / omega (the soft ones dominate the POD), and the unit-M-norm static responses to
    the load pieces and to each flexible link's pair of axial end forces.
    """
    theta = 2.0 * np.pi * np.arange(angles) / angles
    system = model.assemble(theta)
    elements = model_elements(model)
    gather, _ = element_gathers(model, elements, theta)
    chords = link_chord_gradients(model, elements, gather)
    columns = []
    for k in range(angles):
        mass, stiffness = system.mass[k], system.stiffness[k]
        omega, shapes = frozen_modes(stiffness, mass, min(modes, model.size))
        columns.append(shapes * (omega[0] / omega))
        loads = [system.load[piece][k] for piece in system.load] + list(chords[k])
        static = np.linalg.solve(stiffness, np.array(loads).T)
        norms = np.sqrt(np.einsum('ik,ij,jk->k', static, mass, static))
        columns.append(static / np.where(norms > 0.0, norms, 1.0))
    return np.hstack(columns), system.mass.mean(axis=0)


def reduced_basis(model, angles=BASIS_ANGLES, modes=BASIS_MODES, size=None,
                  tolerance=BASIS_TOLERANCE):
    """
    Return the constant basis V (n, m), M-orthonormal against the cycle-mean mass.

    The POD of :func:`basis_snapshots`; ``size`` directions, or (None) as many as
    :func:`basis_size` keeps at ``tolerance``.
    """
    snapshots, mass = basis_snapshots(model, angles, modes)
    basis, singular = mass_weighted_pod(snapshots, mass, model.size)
    kept = basis_size(singular, tolerance) if size is None else int(size)
    if not 1 <= kept <= model.size:
        raise ValueError(f'basis size must be 1 ... {model.size}, got {kept}')
    return basis[:, :kept]


def _sandwich(gather, matrix, right):
    """``sum_e (T_e V)^T K_e (R_e V)`` over the elements, (N, m, m)."""
    return np.einsum('neam,eab,nebk->nmk', gather, matrix, right)


def node_fields(model, basis, elements, theta):
    """Every field of :class:`NonlinearTables` at crank angles theta, {name: (N, ...)}."""
    system = model.assemble(theta)
    gather, rate = element_gathers(model, elements, theta)
    gather, rate = gather @ basis, rate @ basis
    project = (lambda matrix: np.swapaxes(basis, 0, 1) @ matrix @ basis)
    axial = (elements.axial_stiffness / elements.length)[:, None, None]
    element_stiffness = elements.bending + axial * np.outer(AXIAL, AXIAL)
    fields = {'mass': project(system.mass), 'gyroscopic': project(system.gyroscopic),
              'coupling_a': project(system.coupling['a']),
              'coupling_w2': project(system.coupling['w2']),
              'elastic': _sandwich(gather, element_stiffness, gather),
              'elastic_rate': _sandwich(gather, element_stiffness, rate)}
    for piece in ('1', 'a', 'w2'):
        fields['geometric_' + piece] = project(system.geometric[piece])
        fields['load_' + piece] = system.load[piece] @ basis
    fields['output'] = model.output_operator(theta) @ basis
    fields['chord'] = link_chord_gradients(model, elements, gather)
    fields['chord_rate'] = link_chord_gradients(model, elements, rate)
    unit, chosen = elements.unit_geometric, [elements.link == link for link in model.links]
    fields['shortening'] = np.stack([_sandwich(gather[:, sel], unit[sel], gather[:, sel])
                                     for sel in chosen], axis=1)
    fields['shortening_rate'] = np.stack([_sandwich(gather[:, sel], unit[sel], rate[:, sel])
                                          for sel in chosen], axis=1)
    return fields


def build_nonlinear_tables(model, beta, grid_nodes=GRID_NODES, basis=None, **basis_options):
    """
    Build the reduced nonlinear model of a :class:`FlexibleLinkage` (see the module notes).

    Parameters
    ----------
    model : FlexibleLinkage
        The FE model (any crank model, rigid or flexible bearings, gravity on or off).
    beta : float
        Kelvin-Voigt damping [s] (the nonlinear full order's ``beta``).
    grid_nodes : int
        Crank-angle grid nodes N.
    basis : ndarray, shape (n, m) or None
        A basis to use instead of :func:`reduced_basis` (``basis_options`` go there).

    Returns
    -------
    NonlinearTables

    """
    if not (np.isfinite(beta) and beta >= 0.0):
        raise ValueError(f'`beta` must be >= 0 [s], got {beta!r}')
    basis = reduced_basis(model, **basis_options) if basis is None else np.asarray(basis)
    elements = model_elements(model)
    theta = 2.0 * np.pi * np.arange(grid_nodes) / grid_nodes
    fields = node_fields(model, basis, elements, theta)
    link_length = np.array([model.mechanism.links[link].length for link in model.links])
    link_ea = np.array([elements.axial_stiffness[elements.link == link][0]
                        for link in model.links])
    tables = NonlinearTables(values=None, slopes=None, size=basis.shape[1],
                             links=len(model.links), outputs=fields['output'].shape[1],
                             axial_stiffness=link_ea / link_length, link_length=link_length,
                             bearing=basis.T @ np.asarray(model.bearing_stiffness) @ basis,
                             beta=float(beta), basis=basis)
    layout = tables.layout()
    flat = np.concatenate([fields[name].reshape(grid_nodes, -1) for name in layout], axis=1)
    tables.values = flat
    tables.slopes = angle_derivatives(flat)[0]
    return tables


__all__ = ['GRID_NODES', 'BASIS_MODES', 'BASIS_TOLERANCE', 'NonlinearTables', 'basis_size',
           'basis_snapshots', 'reduced_basis', 'build_nonlinear_tables',
           'node_fields', 'element_gathers', 'link_chord_gradients']
