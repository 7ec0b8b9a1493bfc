"""
Geometrically nonlinear element force and tangent: the element-averaged von Karman strain.

The linear KED model (Cho, Park & Lee 1992) takes each element's axial strain as
``(u2 - u1) / l`` and its bending stiffness change from the rigid-body axial force (A.4). Near a
resonance of the links that is not enough: the chord shortening of the bent elements changes
their axial force, and that force changes their bending stiffness. Here, per element e of
length l with link-frame coordinates ``q = (u1, v1, phi1, u2, v2, phi2)`` ::

    s     = 1/2 q^T G q,      G = int h'^T h' dx       (beam_geometric_stiffness(1, l), A.4)
    eps   = b^T q / l + s / l,  b = (-1, 0, 0, 1, 0, 0)  (element-averaged von Karman strain)
    eps'  = (b + G q)^T q' / l                          (its rate)
    N     = E A (eps + beta eps')                       (Kelvin-Voigt on the nonlinear strain)
    f     = N (b + G q) + K_b q + beta K_b q'           (K_b: the element's bending stiffness)

f is the gradient of the strain energy ``E A l eps^2 / 2 + q^T K_b q / 2`` plus the
Kelvin-Voigt force. Its tangents are ::

    df/dq  = (E A / l) (b + G q)(b + G q + beta G q')^T + N G + K_b
    df/dq' = beta ((E A / l) (b + G q)(b + G q)^T + K_b)

The rigid-body geometric stiffness of A.4 is left out where this force is used: it is the
linearisation of ``N G q`` about the quasi-static axial strain, which the axial coordinates
now carry. With ``nonlinear=False`` the strain is the linear ``b^T q / l``:
``f = K_e q + beta K_e q'`` with the element stiffness A.3, the linear model's force.

Objectivity (what the strain guarantees). q are coordinates in the link's frame and q' the
link-frame rate, so a rigid motion of the link (its frame) strains and damps nothing. For an
element turned rigidly by a large phi relative to its link frame (far node at
(l (cos phi - 1), l sin phi), both slopes phi) ``eps = cos phi - 1 + sin^2 phi / 2 + O(phi^6)
= -phi^4 / 8 + ...``, against -phi^2/2 + ... of the linear strain. A rigid rotation rate phi'
at that angle dissipates ``beta (E A l eps'^2 + q'^T K_b q')`` = O(phi^4 phi'^2) (the
bending part: Hermite slopes are linear in phi, the far node's v is not), nothing at phi = 0;
the linear strain's axial part dissipates ``beta E A l sin^2(phi) phi'^2``.

Everything is vectorised over any leading axes (stages, elements) so that a reduced model can
evaluate the same force with ``q = T_e Phi eta``: :func:`project_force` and
:func:`project_tangent` map element quantities to any generalized coordinates.
"""

import dataclasses

import numpy as np

from .beam import beam_geometric_stiffness, beam_stiffness

# Axial pattern of the element strain: eps = b^T q / l (u2 - u1).
AXIAL = np.array([-1.0, 0.0, 0.0, 1.0, 0.0, 0.0])
# Element coordinates per node.
NODE_DOFS = 3


@dataclasses.dataclass(frozen=True)
class Elements:
    """
    Per-element data of the nonlinear force, stacked over the links' elements.

    Attributes
    ----------
    link : ndarray of int, shape (E,)
        The link each element belongs to.
    first_row : ndarray of int, shape (E,)
        Row of the element's first coordinate in its link vector (3 e).
    length, axial_stiffness : ndarray, shape (E,)
        l [m] and E A [N].
    unit_geometric : ndarray, shape (E, 6, 6)
        G = A.4 at unit tension.
    bending : ndarray, shape (E, 6, 6)
        K_b: A.3 without its axial part (E A / l) b b^T.

    """

    link: np.ndarray
    first_row: np.ndarray
    length: np.ndarray
    axial_stiffness: np.ndarray
    unit_geometric: np.ndarray
    bending: np.ndarray

    def __len__(self):
        """Return the number of elements E."""
        return self.length.shape[0]

    def rows(self, link):
        """Rows of every element of ``link`` in the link vector, shape (e_L, 6)."""
        first = self.first_row[self.link == link]
        return first[:, None] + np.arange(2 * NODE_DOFS)[None, :]


def model_elements(model):
    """Return the :class:`Elements` of every modelled link of a :class:`FlexibleLinkage`."""
    parts = []
    for link in model.links:
        spec, mats = model.mechanism.links[link], model.link_matrices[link]
        count, le = mats.elements, mats.element_length
        ea = model.mechanism.youngs_modulus * spec.area
        full = beam_stiffness(model.mechanism.youngs_modulus, spec.area, spec.second_moment, le)
        parts.append((np.full(count, link), NODE_DOFS * np.arange(count), np.full(count, le),
                      np.full(count, ea),
                      np.broadcast_to(beam_geometric_stiffness(1.0, le), (count, 6, 6)),
                      np.broadcast_to(full - ea / le * np.outer(AXIAL, AXIAL), (count, 6, 6))))
    fields = [np.concatenate(values) for values in zip(*parts)]
    return Elements(*fields)


def element_strain(elements, q, nonlinear=True):
    """
    Element-averaged strain ``eps = b^T q / l + q^T G q / (2 l)`` (von Karman).

    Parameters
    ----------
    elements : Elements
        The element data.
    q : ndarray, shape (..., E, 6)
        Element coordinates in the link frames.
    nonlinear : bool
        False for the linear strain ``b^T q / l``.

    Returns
    -------
    ndarray, shape (..., E)

    """
    stretch = q @ AXIAL
    if nonlinear:
        stretch = stretch + 0.5 * np.einsum('...a,...ab,...b->...', q,
                                            elements.unit_geometric, q)
    return stretch / elements.length


def strain_gradient(elements, q, nonlinear=True):
    """``l d(eps)/dq = b + G q`` (``b`` alone for the linear strain), shape (..., E, 6)."""
    if not nonlinear:
        return np.broadcast_to(AXIAL, q.shape)
    return AXIAL + np.einsum('...ab,...b->...a', elements.unit_geometric, q)


def element_force(elements, q, rate, beta, nonlinear=True):
    """
    Element force ``f = N (b + G q) + K_b (q + beta q')`` and axial force N.

    Parameters
    ----------
    elements : Elements
        The element data.
    q, rate : ndarray, shape (..., E, 6)
        Element coordinates and their link-frame rates.
    beta : float
        Kelvin-Voigt damping [s] on the strain rate and the bending rate.
    nonlinear : bool
        False: linear strain, ``f = K_e (q + beta q')``.

    Returns
    -------
    force : ndarray, shape (..., E, 6)
    axial_force : ndarray, shape (..., E)
        N = E A (eps + beta eps') [N], tension > 0.

    """
    gradient = strain_gradient(elements, q, nonlinear)
    strain = element_strain(elements, q, nonlinear)
    strain_rate = np.einsum('...a,...a->...', gradient, rate) / elements.length
    axial = elements.axial_stiffness * (strain + beta * strain_rate)
    bending = np.einsum('...ab,...b->...a', elements.bending, q + beta * rate)
    return axial[..., None] * gradient + bending, axial


def element_tangent(elements, q, rate, beta, nonlinear=True, axial=None):
    """
    Tangents of :func:`element_force`: ``df/dq`` and ``df/dq'``.

    ``df/dq = (EA/l) g (g + beta G q')^T + N G + K_b`` and
    ``df/dq' = beta ((EA/l) g g^T + K_b)`` with ``g = b + G q`` (``g = b``, no ``N G``, for
    the linear strain). ``axial``: N of :func:`element_force` at (q, rate) when known.

    Returns
    -------
    stiffness, damping : ndarray, shape (..., E, 6, 6)

    """
    gradient = strain_gradient(elements, q, nonlinear)
    scale = (elements.axial_stiffness / elements.length)[..., None, None]
    outer = scale * gradient[..., :, None] * gradient[..., None, :]
    damping = beta * (outer + elements.bending)
    stiffness = outer + elements.bending
    if nonlinear:
        if axial is None:
            _, axial = element_force(elements, q, rate, beta, nonlinear)
        rate_term = np.einsum('...ab,...b->...a', elements.unit_geometric, rate)
        stiffness = (stiffness + beta * scale * gradient[..., :, None] * rate_term[..., None, :]
                     + axial[..., None, None] * elements.unit_geometric)
    return stiffness, damping


def strain_energy(elements, q, nonlinear=True):
    """Strain energy ``sum (E A l eps^2 + q^T K_b q) / 2`` [J] over the elements, shape (...)."""
    strain = element_strain(elements, q, nonlinear)
    axial = 0.5 * elements.axial_stiffness * elements.length * strain ** 2
    bending = 0.5 * np.einsum('...a,...ab,...b->...', q, elements.bending, q)
    return (axial + bending).sum(axis=-1)


def element_gather(elements, link_gathers):
    """
    Element rows of the links' gathers: ``q_e = T_e x`` for any coordinates x.

    Parameters
    ----------
    elements : Elements
        The element data.
    link_gathers : dict of int to ndarray, shape (..., 3 (e + 1), m)
        Per link, its link vector per coordinate (T^T of Eq. 25, or T^T Phi for a basis).

    Returns
    -------
    ndarray, shape (..., E, 6, m)

    """
    parts = [gather[..., elements.rows(link), :] for link, gather in link_gathers.items()]
    return np.concatenate(parts, axis=-3)


def element_coordinates(gather, x):
    """Element coordinates ``q_e = T_e x``: gather (..., E, 6, m), x (..., m) -> (..., E, 6)."""
    shape = gather.shape
    flat = gather.reshape(shape[:-3] + (shape[-3] * shape[-2], shape[-1]))
    return (flat @ x[..., None])[..., 0].reshape(shape[:-1])


def project_force(gather, force):
    """Generalized force ``sum_e T_e^T f_e`` from element forces, shape (..., m)."""
    shape = gather.shape
    flat = gather.reshape(shape[:-3] + (shape[-3] * shape[-2], shape[-1]))
    return (np.swapaxes(flat, -1, -2) @ force.reshape(flat.shape[:-1] + (1,)))[..., 0]


def project_tangent(gather, tangent, right=None):
    """
    Generalized tangent ``sum_e T_e^T K_e R_e`` (R = T unless ``right`` is given), (..., m, m).

    ``gather`` (..., E, 6, m); ``tangent`` (..., E, 6, 6).
    """
    right = gather if right is None else right
    inner = tangent @ right
    shape = gather.shape
    flat = gather.reshape(shape[:-3] + (shape[-3] * shape[-2], shape[-1]))
    inner = inner.reshape(flat.shape[:-1] + (right.shape[-1],))
    return np.swapaxes(flat, -1, -2) @ inner


__all__ = ['AXIAL', 'Elements', 'model_elements', 'element_strain', 'strain_gradient',
           'element_force', 'element_tangent', 'strain_energy', 'element_gather',
           'element_coordinates', 'project_force', 'project_tangent']
