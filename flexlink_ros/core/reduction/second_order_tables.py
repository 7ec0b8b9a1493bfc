"""
The reduced model's tables of the second-order outputs, and their numpy evaluation.

The second-order motion of the bent links (chord shortening, :mod:`core.fe.second_order_geometry`)
is on a constant basis U = V q a sum of quadratic forms of q
(:mod:`core.fe.second_order_reduced`). The streaming step evaluates them factored, per sample:

1. the spline of 22 scalars over the crank angle: cos and sin of the three link angles, then
   the 4 x 4 coefficients kappa of Eqs. (3)-(4) (outputs per bending sum S_j), in the power
   form of the model's other cell tables (:mod:`.cells`);
2. the rows of V q that the links' (v, phi) DOFs read, ``y = V_rows q``;
3. the link-frame (v, phi) vector of each link, ``z[slot] += coef * trig * y[row]`` (trig 1,
   or the cos or sin of the link angle for the rotated end-node translations:
   :func:`core.fe.second_order_reduced.gather_harmonics`);
4. ``S_j = 1/2 z^T G_j z`` over the band of each G (upper triangle, off-diagonal doubled);
5. ``out_o += sum_j kappa_oj S_j``.

:func:`build_tables` makes the plain arrays the cache stores (names ``second_*``);
:class:`SecondOrderForms` evaluates them in numpy (the reference the compiled step,
core/estimation/_radau_step.c, equals to rounding) and gives the second-order joint motion
the deformed linkage is drawn with.
"""

import functools

import numpy as np

from .cells import CELL_POWERS, periodic_cell_coefficients
from ..fe.second_order_full import link_forms
from ..fe.second_order_geometry import FORMS, output_coefficients
from ..fe.second_order_reduced import gather_harmonics
from ..kinematics import solve_kinematics
from ...names import OUTPUT_NAMES

# Spline scalars per crank angle: cos, sin of crank, coupler, lever angle, then kappa (4 x 4).
TRIG_SCALARS = 6
SCALARS = TRIG_SCALARS + len(OUTPUT_NAMES) * len(FORMS)
# Link of each bending sum in FORMS (crank, coupler, lever, coupler's first half).
FORM_LINKS = (0, 1, 2, 1)
# The cache's array names, in the order the compiled step takes them.
ARRAY_NAMES = ('second_scalars', 'second_rows', 'second_gather', 'second_gather_coef',
               'second_form', 'second_form_value')


def scalar_samples(mechanism, theta, links):
    """
    Eqs. (3)-(4) coefficients and link-angle cos/sin at crank angles: (N, SCALARS).

    kappa's crank column is zero when the crank is not modelled (rigid: S_crank = 0).
    """
    angle = solve_kinematics(mechanism, theta).angle
    values = np.zeros((theta.size, SCALARS))
    for link in range(3):
        values[:, 2 * link], values[:, 2 * link + 1] = np.cos(angle[link]), np.sin(angle[link])
    kappa = output_coefficients(mechanism, theta)
    if 0 not in links:
        kappa[:, :, 0] = 0.0
    values[:, TRIG_SCALARS:] = kappa.reshape(theta.size, -1)
    return values


def _transverse(pieces):
    """Return the (v, phi) rows of a link's gather pieces (3, 3 (e + 1), n), in node order."""
    return pieces[:, [a for a in range(pieces.shape[1]) if a % 3], :]


def _gather_entries(linkage, used):
    """Return (slot, row of y, scalar or -1, coefficient) per nonzero of the (v, phi) gather."""
    entries, first, count = [], {}, 0
    for link in linkage.links:
        pieces = _transverse(gather_harmonics(linkage, link))
        first[link] = count
        count += pieces.shape[1]
        for slot, a in enumerate(range(pieces.shape[1]), start=first[link]):
            for harmonic, trig in enumerate((-1, 2 * link, 2 * link + 1)):
                for dof in np.flatnonzero(pieces[harmonic, a]):
                    entries.append((slot, used[int(dof)], trig, pieces[harmonic, a, dof]))
    return entries, first


def _form_entries(linkage, first):
    """Return (form, slot i, slot j, value) of the upper band of each G on the (v, phi) DOFs."""
    forms = link_forms(linkage)
    entries = []
    for form, link in enumerate(FORM_LINKS):
        if link not in linkage.links:
            continue
        gmatrix = forms.coupler_half if form == 3 else forms.full[link]
        keep = [a for a in range(gmatrix.shape[0]) if a % 3]
        sub = gmatrix[np.ix_(keep, keep)]
        for i, j in zip(*np.nonzero(np.triu(sub))):
            value = sub[i, j] * (1.0 if i == j else 2.0)
            entries.append((form, first[link] + int(i), first[link] + int(j), value))
    return entries


def build_tables(linkage, basis, grid_size):
    """
    Plain arrays of the factored second-order outputs of a reduced model (cached with it).

    Parameters
    ----------
    linkage : FlexibleLinkage
        The full model the basis belongs to (the reduced model's options).
    basis : ndarray, shape (n, r)
        The reduced model's constant basis V.
    grid_size : int
        Crank-angle grid cells N of the reduced model.

    Returns
    -------
    dict of str to ndarray
        :data:`ARRAY_NAMES`: 'second_scalars' (N, CELL_POWERS, SCALARS) spline coefficients,
        'second_rows' (m, r) the rows of V read, 'second_gather' int32 (P, 3) and
        'second_gather_coef' (P,), 'second_form' int32 (T, 3) and 'second_form_value' (T,).

    """
    theta = 2.0 * np.pi * np.arange(grid_size) / grid_size
    # The system DOFs the links' (v, phi) rows read (not their axial u rows).
    dofs = sorted({int(i) for link in linkage.links
                   for i in np.flatnonzero(np.abs(_transverse(gather_harmonics(linkage, link)))
                                           .sum(axis=(0, 1)))})
    gather, first = _gather_entries(linkage, {dof: k for k, dof in enumerate(dofs)})
    form = _form_entries(linkage, first)
    scalars = scalar_samples(linkage.mechanism, theta, linkage.links)
    return {'second_scalars': periodic_cell_coefficients(scalars),
            'second_rows': np.ascontiguousarray(basis[dofs]),
            'second_gather': np.array([e[:3] for e in gather], dtype=np.int32),
            'second_gather_coef': np.array([e[3] for e in gather], dtype=float),
            'second_form': np.array([e[:3] for e in form], dtype=np.int32),
            'second_form_value': np.array([e[3] for e in form], dtype=float)}


class SecondOrderForms:
    """
    The numpy evaluation of :func:`build_tables`'s arrays (the compiled step's reference).

    Parameters
    ----------
    arrays : dict of str to ndarray
        :data:`ARRAY_NAMES` (a model's ``second_order``).

    """

    def __init__(self, arrays):
        self.arrays = {name: np.ascontiguousarray(arrays[name]) for name in ARRAY_NAMES}
        self.scalars = self.arrays['second_scalars']
        self.rows = self.arrays['second_rows']
        gather, coef = self.arrays['second_gather'], self.arrays['second_gather_coef']
        form, value = self.arrays['second_form'], self.arrays['second_form_value']
        self.slots = int(max(gather[:, 0].max(initial=-1), form[:, 1:].max(initial=-1))) + 1
        # One dense (slots x rows) gather per trig scalar (-1: the constant 1).
        self.gathers = {}
        for trig in sorted(set(gather[:, 2].tolist())):
            chosen = gather[:, 2] == trig
            dense = np.zeros((self.slots, self.rows.shape[0]))
            np.add.at(dense, (gather[chosen, 0], gather[chosen, 1]), coef[chosen])
            self.gathers[trig] = dense
        self.g = np.zeros((len(FORMS), self.slots, self.slots))
        np.add.at(self.g, (form[:, 0], form[:, 1], form[:, 2]), value)

    def spline_scalars(self, cells, t):
        """Return the SCALARS (m, SCALARS) at grid cells ``cells``, positions ``t`` in them."""
        powers = np.asarray(t, dtype=float)[..., None] ** np.arange(CELL_POWERS)
        return np.einsum('mp,mps->ms', np.atleast_2d(powers), self.scalars[np.atleast_1d(cells)])

    def sums(self, scalars, q):
        """Return the bending sums S_j (m, len(FORMS)) of states q (m, r) at their scalars."""
        y = np.atleast_2d(q) @ self.rows.T
        z = np.zeros((y.shape[0], self.slots))
        for trig, dense in self.gathers.items():
            factor = 1.0 if trig < 0 else scalars[:, trig:trig + 1]
            z += factor * (y @ dense.T)
        return 0.5 * np.einsum('mi,fij,mj->mf', z, self.g, z)

    def outputs(self, scalars, sums):
        """Return the second-order outputs kappa S, shape (m, len(OUTPUT_NAMES)) [m]."""
        kappa = scalars[:, TRIG_SCALARS:].reshape(-1, len(OUTPUT_NAMES), len(FORMS))
        return np.einsum('mof,mf->mo', kappa, sums)

    def packed(self):
        """
        Return the arrays in the compiled step's form: (values float64, index int32).

        ``index`` = [m rows of V, P gather entries, T form terms], the gather (P x 3), the form
        (T x 3); ``values`` = the scalars' spline coefficients, the rows of V (m x r), the
        gather coefficients, the form values. Two buffers a call, not six.
        """
        a = self.arrays
        counts = [a['second_rows'].shape[0], a['second_gather'].shape[0],
                  a['second_form'].shape[0]]
        index = np.concatenate([np.array(counts), a['second_gather'].ravel(),
                                a['second_form'].ravel()]).astype(np.int32)
        values = np.concatenate([a['second_scalars'].ravel(), a['second_rows'].ravel(),
                                 a['second_gather_coef'], a['second_form_value']])
        return np.ascontiguousarray(values), np.ascontiguousarray(index)

    def link_motion(self, cells, t, q, points):
        """
        Second-order motion of the drawn link points at cells, positions and states.

        Returns
        -------
        ndarray, shape (m, 3, points, 2)
            :func:`link_point_motion` of :meth:`joint_motion` [m].

        """
        return link_point_motion(*self.joint_motion(self.spline_scalars(cells, t), q), points)

    def joint_motion(self, scalars, q):
        """
        Second-order displacements of joints A and B, (m, 2) each [m] (Eq. 3).

        dA = -S_crank e_crank (zero for a rigid crank), dB = the lever tip's second order.
        """
        sums = self.sums(scalars, q)
        d_a = -sums[:, :1] * scalars[:, 0:2]
        return d_a, self.outputs(scalars, sums)[:, 0:2]


def link_point_motion(d_a, d_b, points):
    """
    Second-order motion of ``points`` equally spaced points along each link: (m, 3, points, 2).

    Each link's chord carried to its ends' second-order positions, linearly in between
    (crank O2 -> A, coupler A -> B, lever O4 -> B): the drawn deformed linkage. (The
    shortening's own distribution along a link, of the order of S, is not drawn.)
    """
    f = _fractions(points)
    a, b = d_a[:, None, :], d_b[:, None, :]
    motion = np.empty((d_a.shape[0], 3, points, 2))
    np.multiply(f, a, out=motion[:, 0])
    np.multiply(f, b, out=motion[:, 2])
    np.add((1.0 - f) * a, motion[:, 2], out=motion[:, 1])
    return motion


@functools.lru_cache(maxsize=8)
def _fractions(points):
    """Fractions 0 .. 1 of ``points`` equally spaced points, shape (1, points, 1), read-only."""
    fractions = np.linspace(0.0, 1.0, points)[None, :, None]
    fractions.flags.writeable = False
    return fractions
