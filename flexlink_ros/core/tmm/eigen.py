"""
Beam frequencies from stiffness matrices, without transfer matrices: the references of the TMM.

:func:`lumped_frequencies` solves the flexibility eigenproblem of a :class:`LumpedBeam` (the
same model the transfer matrices see); :func:`fe_frequencies` uses cubic beam elements with
consistent mass (:mod:`core.fe.beam`, Cho 1992 Eqs. A.3 and A.6) on the uniform beam.
"""

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg

from .beams import check_boundary_condition
from ..fe import beam as beam_element

# Largest eigenproblem solved dense; above it sparse LU + ARPACK (dense LAPACK on more DOFs
# is slow when OpenBLAS threads compete for the cores).
DENSE_EIGEN_LIMIT = 64
# Bending DOFs (v1, phi1, v2, phi2) within core/fe/beam.py's element order (u1, v1, phi1, ...).
_BENDING = [1, 2, 4, 5]
# Which ends are free, and which restrain the rotation, for the stiffness-based reference.
_CLAMPED_ENDS = {'fixed-fixed': (True, True), 'fixed-supported': (True, False),
                 'cantilever': (True, False), 'supported': (False, False)}


def _assemble_bending(element_lengths, element_matrix):
    """
    Assemble 4x4 bending blocks (v1, phi1, v2, phi2) of consecutive elements.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (2 (n + 1), 2 (n + 1))

    """
    blocks = np.array([element_matrix(h) for h in element_lengths])  # (n, 4, 4)
    first = 2 * np.arange(len(element_lengths))
    dofs = first[:, None] + np.arange(4)[None, :]
    rows = np.broadcast_to(dofs[:, :, None], blocks.shape).ravel()
    cols = np.broadcast_to(dofs[:, None, :], blocks.shape).ravel()
    size = 2 * (len(element_lengths) + 1)
    return scipy.sparse.coo_matrix((blocks.ravel(), (rows, cols)), shape=(size, size)).tocsr()


def _free_dofs(n_dof, bc):
    """Return the DOFs (v, phi per node) left free by the boundary condition, ndarray of int."""
    clamp_left, clamp_right = _CLAMPED_ENDS[bc]
    fixed = [0] + ([1] if clamp_left else [])
    if bc != 'cantilever':
        fixed += [n_dof - 2] + ([n_dof - 1] if clamp_right else [])
    return np.setdiff1d(np.arange(n_dof), fixed)


def _largest_symmetric(operator, size, count, dense):
    """Largest `count` eigenvalues of a symmetric matrix or operator, ascending."""
    if size <= DENSE_EIGEN_LIMIT or count >= size - 1:
        return scipy.linalg.eigh(dense(), eigvals_only=True,
                                 subset_by_index=[size - count, size - 1])
    linear = scipy.sparse.linalg.LinearOperator((size, size), matvec=operator, dtype=float)
    return np.sort(scipy.sparse.linalg.eigsh(linear, k=count, which='LA', tol=0.0,
                                             return_eigenvectors=False))


def lumped_frequencies(model, bc, modes=None):
    """
    Lowest natural frequencies of a lumped model from its flexibility, no transfer matrices.

    Independent of the transfer matrices: massless cubic beam elements (exact for a massless
    Euler-Bernoulli beam under point loads, core/fe/beam.py bending part) join nodes at the ends
    and at every mass. With S = diag(sqrt(m)) on the translations that carry mass, the
    frequencies are 1/sqrt(mu) for the eigenvalues mu of S K^-1 S (flexibility form, the
    rotations and massless translations condensed exactly by the solve with K). Small models
    use :func:`scipy.linalg.eigh`, larger ones sparse LU and ARPACK.

    Parameters
    ----------
    model : LumpedBeam
        The lumped-mass beam (:func:`core.tmm.beams.lump_masses`).
    bc : str
        Boundary condition, one of :data:`BOUNDARY_CONDITIONS`.
    modes : int, optional
        How many (default: all, :func:`available_modes`).

    Returns
    -------
    ndarray, shape (modes,)
        Ascending natural frequencies [rad/s].

    """
    check_boundary_condition(bc)
    nodes = np.unique(np.concatenate(([0.0, model.length], model.positions)))
    ei = model.flexural_rigidity
    stiffness = _assemble_bending(
        np.diff(nodes),
        lambda h: beam_element.beam_stiffness(ei, 1.0, 1.0, h)[np.ix_(_BENDING, _BENDING)])
    mass = np.zeros(2 * nodes.size)
    for position, m in zip(model.positions, model.masses):
        mass[2 * int(np.argmin(np.abs(nodes - position)))] += m
    free = _free_dofs(mass.size, bc)
    k_free = stiffness[free][:, free].tocsc()
    massive = np.flatnonzero(mass[free] > 0)
    root_mass = np.sqrt(mass[free][massive])
    count = massive.size if modes is None else min(int(modes), massive.size)

    def flexibility(x):
        load = np.zeros(free.size)
        load[massive] = root_mass * np.ravel(x)
        return root_mass * solve(load)[massive]

    def dense():
        flex = scipy.linalg.solve(k_free.toarray(), np.eye(free.size)[:, massive],
                                  assume_a='pos')[massive]
        return root_mass[:, None] * flex * root_mass[None, :]

    solve = scipy.sparse.linalg.splu(k_free).solve if massive.size > DENSE_EIGEN_LIMIT \
        else None
    inverse = _largest_symmetric(flexibility, massive.size, count, dense)
    return np.sort(1.0 / np.sqrt(inverse))


def fe_frequencies(beam, bc, elements, modes=3):
    """
    Lowest natural frequencies by cubic beam finite elements with consistent mass.

    Bending part (DOFs v, phi) of :func:`flexlink_ros.core.fe.beam.beam_stiffness` and
    :func:`flexlink_ros.core.fe.beam.beam_mass` (Cho 1992, Eqs. A.3 and A.6), solved by
    :func:`scipy.linalg.eigh`. Frequency error falls like h^4.

    Parameters
    ----------
    beam : UniformBeam
        The uniform beam.
    bc : str
        Boundary condition, one of :data:`BOUNDARY_CONDITIONS`.
    elements : int
        Number of equal elements (>= 1).
    modes : int
        How many frequencies (at most the number of free DOFs).

    Returns
    -------
    ndarray, shape (modes,)
        Ascending natural frequencies [rad/s].

    """
    check_boundary_condition(bc)
    if isinstance(elements, bool) or not isinstance(elements, (int, np.integer)) \
            or elements < 1:
        raise ValueError(f'`elements` must be a positive integer, got {elements!r}')
    n = int(elements)
    h = beam.length / n
    bending = np.ix_(_BENDING, _BENDING)
    stiffness = _assemble_bending(
        np.full(n, h), lambda h: beam_element.beam_stiffness(beam.E, 1.0, beam.I, h)[bending])
    mass = _assemble_bending(
        np.full(n, h), lambda h: beam_element.beam_mass(beam.mass_per_length, 1.0, h)[bending])
    free = _free_dofs(2 * (n + 1), bc)
    if isinstance(modes, bool) or not isinstance(modes, (int, np.integer)) or modes < 1:
        raise ValueError(f'`modes` must be a positive integer, got {modes!r}')
    if modes > free.size:
        raise ValueError(f'`modes` = {modes} exceeds the {free.size} DOFs of {n} elements')
    k_free = stiffness[free][:, free]
    m_free = mass[free][:, free]
    # M x = (1/omega^2) K x: the lowest frequencies are the largest, best-resolved eigenvalues
    # (K x = omega^2 M x loses them to round-off relative to the highest mode on fine meshes)
    if free.size <= DENSE_EIGEN_LIMIT or modes >= free.size - 1:
        inverse = scipy.linalg.eigh(m_free.toarray(), k_free.toarray(), eigvals_only=True,
                                    subset_by_index=[free.size - modes, free.size - 1])
    else:
        inverse = 1.0 / scipy.sparse.linalg.eigsh(k_free.tocsc(), k=modes, M=m_free.tocsc(),
                                                  sigma=0.0, which='LM', tol=0.0,
                                                  return_eigenvectors=False)
    return np.sort(1.0 / np.sqrt(inverse))
