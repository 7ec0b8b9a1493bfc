"""
The reduced model's soft-basis tables: the step's system in p coordinates and its lift.

With the reduced coordinates q = Phi(theta) eta (:mod:`.soft_basis`), theta' = w and
theta'' = a, ::

    q'  = Phi eta' + w Phi' eta
    q'' = Phi eta'' + 2 w Phi' eta' + (w^2 Phi'' + a Phi') eta

so the reduced system M q'' + C q' + K q = f, projected on Phi, becomes (:func:`transport_terms`)
::

    Phi^T M Phi eta'' + (Phi^T C Phi + 2 w Phi^T M Phi') eta'
        + (Phi^T K Phi + a Phi^T M Phi' + w^2 Phi^T M Phi'' + w Phi^T C Phi') eta = Phi^T f

with the exact transport terms. C (damping and Coriolis) keeps its monomials (1, w^2, w,
w^4); its transport term ``w Phi^T C Phi'`` joins the stiffness's monomials: w times the
damping's constant term and w^2 times the Coriolis term. Its w^3 and w^5 parts (the damping
fit's w^2 and w^4 terms times the frame's turning) are left out: below 2e-5 of the outputs
at 391 rpm and 1e-4 at 600 (measured on the default model), and the step keeps the
reduced model's table layout. What Phi leaves out responds quasi-statically: the residual
``(K^-1 - Phi (Phi^T K Phi)^-1 Phi^T) f`` per load monomial (a, 1, w^2) is added to the
lifted coordinates q = Phi eta + residual, whose size (through the outputs) the estimator
already reports as its error indicator.

Every table is projected at the grid nodes from the reduced model's node values (which are
exact samples: its cubic spline passes through them) and splined again, so the soft
stiffness is not polluted by interpolating the stiff directions between nodes.
"""

import numpy as np

from .cells import MONOMIALS, periodic_cell_coefficients
from .soft_basis import align_modes, angle_derivatives, choose_soft_size, gap_ratios, \
    lowest_modes

# Version of what soft_tables computes: the key of its cache files
# (mechanism_model.with_soft_basis); change it whenever the tables change.
SOFT_TABLES_VERSION = 1
# The step's monomial groups of each node table (the order of MONOMIALS).
SOFT_DAMPING_MONOMIALS = ('1', 'w2', 'w', 'w4')
SOFT_KF_MONOMIALS = ('a', '1', 'w2', 'w')
# Load monomials of the residual (quasi-static) correction.
RESIDUAL_MONOMIALS = ('a', '1', 'w2')
# Monomials of the lift's frame (:func:`coupled_frame`): the first four of MONOMIALS.
LIFT_MONOMIALS = ('a', '1', 'w2', 'w')


def node_values(model, name):
    """Return {monomial: node values (N, ...)} of a block of a reduced model's table."""
    layout, table = model.layout, model.table
    values = {}
    for index, monomial in enumerate(MONOMIALS):
        block = layout.block(table[:, 4 * index], name)
        if np.any(block != 0.0):
            values[monomial] = block
    return values


def _hermite_nodes(values):
    """Node values and slopes (cell units) of the periodic cubic spline: (N, 2, ...)."""
    coefficients = periodic_cell_coefficients(values)
    return coefficients[:, :2]


def transport_terms(mass, frame, first, second):
    """
    Return the projected inertia's transport terms of q = Phi(theta) eta.

    Parameters
    ----------
    mass : ndarray, shape (N, r, r)
        Reduced mass at the nodes.
    frame, first, second : ndarray, shape (N, r, p)
        Phi and its first and second derivative in theta at the nodes.

    Returns
    -------
    coriolis, accel, centripetal : ndarray, shape (N, p, p)
        ``2 Phi^T M Phi'`` (times w, on eta'), ``Phi^T M Phi'`` (times a, on eta) and
        ``Phi^T M Phi''`` (times w^2, on eta).

    """
    left = np.swapaxes(frame, 1, 2) @ mass
    inertia_first, inertia_second = left @ first, left @ second
    return 2.0 * inertia_first, inertia_first, inertia_second


def _project(frame, matrix, right=None):
    """Phi^T X Phi (or Phi^T X right) per node."""
    return np.swapaxes(frame, 1, 2) @ matrix @ (frame if right is None else right)


def soft_system(model, frame, first, second):
    """
    Return the soft system's node values per monomial: M, C, D (= Phi^T C Phi'), K, f.

    Parameters
    ----------
    model : ReducedModel
        The reduced model (its node values).
    frame, first, second : ndarray, shape (N, r, p)
        Phi and its derivatives in theta at the nodes.

    Returns
    -------
    dict
        'M', 'C', 'K': {monomial: (N, p, p)}; 'f': {monomial: (N, p)}.

    """
    mass = node_values(model, 'M')['1']
    coriolis, accel, centripetal = transport_terms(mass, frame, first, second)
    damping = node_values(model, 'C')
    system = {'M': {'1': _project(frame, mass)},
              'C': {m: _project(frame, damping[m]) if m in damping else 0.0
                    for m in SOFT_DAMPING_MONOMIALS},
              'K': {m: _project(frame, value) for m, value in node_values(model, 'K').items()},
              'f': {m: np.einsum('nri,nr->ni', frame, value)
                    for m, value in node_values(model, 'f').items()}}
    system['C']['w'] = system['C']['w'] + coriolis
    system['K']['a'] = system['K'].get('a', 0.0) + accel
    system['K']['w2'] = system['K'].get('w2', 0.0) + centripetal
    # w Phi^T C Phi': the damping's constant term (times w) and the Coriolis term (times w^2)
    for monomial, stiffness_monomial in (('1', 'w'), ('w', 'w2')):
        if monomial in damping:
            system['K'][stiffness_monomial] = (system['K'].get(stiffness_monomial, 0.0)
                                               + _project(frame, damping[monomial], first))
    return system


def left_out_flexibility(model, frame):
    """
    Return R = K^-1 - Phi (Phi^T K Phi)^-1 Phi^T per node (K at w = a = 0): (N, r, r).

    The static flexibility of the directions Phi leaves out (R K Phi = 0); the lift's
    residual and its coupled frame are R times their loads.
    """
    stiffness = node_values(model, 'K')['1']
    reduced_inverse = np.linalg.inv(_project(frame, stiffness))
    return np.linalg.inv(stiffness) - frame @ reduced_inverse @ np.swapaxes(frame, 1, 2)


def residual_coordinates(model, flexibility):
    """
    Return the quasi-static response of what Phi leaves out, per load monomial: (N, r) each.

    ``R f_m`` with R :func:`left_out_flexibility`.
    """
    loads = node_values(model, 'f')
    return {monomial: (flexibility @ loads[monomial][..., None])[..., 0]
            for monomial in RESIDUAL_MONOMIALS if monomial in loads}


def coupled_frame(model, frame, first, flexibility):
    """
    Return the lift's frame per monomial: Phi, and the stiff response to the soft motion.

    The soft motion loads the left-out directions, which K_0's modes decouple only at rest:
    through ``a K_a + w^2 K_w2`` (geometric and rotating-frame stiffness) and through the
    damping and Coriolis forces of the frame's turning, ``C(w) w Phi' eta`` (the stiff
    directions' modal damping is large). Their quasi-static response ``-R (...)`` (R = K_0^-1
    - Phi (Phi^T K_0 Phi)^-1 Phi^T) is mostly axial stretch: small in the outputs, but the
    elastic axial force the validity indicator reads (without it the indicator is 15-30 %
    low on the default model). The damping fit's w^2 and w^4 terms add w^3 and w^5 terms
    below 0.3 % of the w term at speed_max; they are left out.

    Parameters
    ----------
    model : ReducedModel
        The reduced model (its node values).
    frame, first : ndarray, shape (N, r, p)
        Phi and dPhi/dtheta at the nodes.
    flexibility : ndarray, shape (N, r, r)
        R, :func:`left_out_flexibility`.

    Returns
    -------
    dict of str to ndarray, shape (N, r, p)
        Per LIFT_MONOMIALS: '1': Phi; 'a': -R K_a Phi; 'w2': -R (K_w2 Phi + G Phi');
        'w': -R (C_1 Phi' + K_w Phi) (K_w: stiffness damping).

    """
    stiffness = node_values(model, 'K')
    damping = node_values(model, 'C')
    load = {'a': [(stiffness.get('a'), frame)],
            'w2': [(stiffness.get('w2'), frame), (damping.get('w'), first)],
            'w': [(stiffness.get('w'), frame), (damping.get('1'), first)]}
    coupled = {'1': frame}
    for monomial, terms in load.items():
        coupled[monomial] = -sum(flexibility @ matrix @ basis
                                 for matrix, basis in terms if matrix is not None)
    return coupled


def _stack(pieces, monomials, shape):
    """Stack {monomial: values} in ``monomials`` order (zeros where absent): (N, groups, ...)."""
    def value(monomial):
        piece = pieces.get(monomial, 0.0)
        return np.reshape(piece, shape) if np.size(piece) == np.prod(shape) else piece
    return np.stack([np.broadcast_to(value(m), shape) for m in monomials], axis=1)


def _node_table(pieces, monomials, shape, dtype):
    """Hermite node table (N, groups * 2, width) of pieces over monomials."""
    stacked = _stack(pieces, monomials, shape).reshape(shape[0], len(monomials), -1)
    nodes = _hermite_nodes(stacked.reshape(shape[0], -1)).reshape(
        shape[0], 2, len(monomials), -1)
    return np.ascontiguousarray(nodes.transpose(0, 2, 1, 3).reshape(
        shape[0], 2 * len(monomials), -1), dtype=dtype)


def soft_tables(model, size=-1, accel_limit=5000.0):
    """
    Build the soft-basis tables of a reduced model (arrays named ``soft_*``).

    Parameters
    ----------
    model : ReducedModel
        The reduced model.
    size : int
        p (-1: the smallest with a usable spectral gap, :func:`.soft_basis.choose_soft_size`).
    accel_limit : float
        Acceleration range of the gap check [rad/s^2].

    Returns
    -------
    dict of str to ndarray
        'soft_mass' (N, 2, p p), 'soft_damping' (N, 8, p p) and 'soft_kf' (N, 8, p p + p)
        float32 node tables (the soft basis has no stiff directions: the
        outputs move by < 1e-6 of their size), the lift's power-form
        cell tables 'soft_phi' (N, 16, r p: :func:`coupled_frame` per monomial a, 1, w2, w
        times powers of t), 'soft_dphi' (N, 4, r p: dPhi/dtheta) and
        'soft_residual' (N, 12, r: monomials a, 1, w2 times powers of t), and 'soft_gap'
        (the worst frequency ratio at the gap, the gap ratios at every size).

    Raises
    ------
    FlexlinkError
        No usable spectral gap (or none at ``size``).

    """
    mass = node_values(model, 'M')['1']
    stiffness = node_values(model, 'K')
    ratios = gap_ratios(mass, stiffness, float(model.speed_max), float(accel_limit))
    size = choose_soft_size(ratios, size)
    _, modes = lowest_modes(mass, stiffness['1'], size)
    frame = align_modes(mass, modes)
    first, second = angle_derivatives(frame)
    system = soft_system(model, frame, first, second)
    nodes, r = frame.shape[:2]
    square = (nodes, size, size)
    kf = np.concatenate([_stack(system['K'], SOFT_KF_MONOMIALS, square).reshape(nodes, len(
        SOFT_KF_MONOMIALS), -1), _stack(system['f'], SOFT_KF_MONOMIALS, (nodes, size))], axis=2)
    flexibility = left_out_flexibility(model, frame)
    residual = residual_coordinates(model, flexibility)
    return {
        'soft_mass': _node_table({'1': system['M']['1']}, ('1',), square, np.float32),
        'soft_damping': _node_table(system['C'], SOFT_DAMPING_MONOMIALS, square, np.float32),
        'soft_kf': _node_table(dict(enumerate(kf.transpose(1, 0, 2))),
                               range(len(SOFT_KF_MONOMIALS)), (nodes, size * size + size),
                               np.float32),
        'soft_phi': _node_table(coupled_frame(model, frame, first, flexibility), LIFT_MONOMIALS,
                                (nodes, r * size), np.float32),
        'soft_dphi': _node_table({'1': first}, ('1',), (nodes, r * size), np.float32),
        'soft_residual': _node_table(residual, RESIDUAL_MONOMIALS, (nodes, r), np.float32),
        'soft_gap': np.sqrt(ratios)}


class SoftLift:
    """
    The lift from the soft coordinates to the reduced model's: q = Phi_c eta + residual.

    ``q' = Phi_c eta' + w Phi' eta + w residual'`` (the residual's rate along the crank angle;
    its rate through the speed and acceleration is left out). The stiff coordinates' rates
    matter where they meet their large damping (the validity indicator's mode-acceleration
    form). Reads the float32 Hermite node tables ``soft_phi``, ``soft_dphi`` and
    ``soft_residual`` of :func:`soft_tables` with the step's Hermite weights (monomial times
    h00, h10 on node k and h01, h11 on node k + 1, MONOMIALS order), as the step reads M.

    Parameters
    ----------
    soft : dict of str to ndarray
        :func:`soft_tables`.

    """

    def __init__(self, soft):
        self.phi, self.dphi = soft['soft_phi'], soft['soft_dphi']
        self.residual = soft['soft_residual']
        self.record_size = self.residual.shape[2]
        self.size = self.phi.shape[2] // self.record_size

    def packed(self):
        """Return (phi, dphi, residual) as the compiled step takes them."""
        return self.phi, self.dphi, self.residual

    def _nodes(self, table, hermite, k, groups):
        """Hermite weights times the node rows of cell k (nodes k and k + 1)."""
        k1 = (k + 1) % table.shape[0]
        return (np.dot(hermite[0, :2 * groups], table[k])
                + np.dot(hermite[1, :2 * groups], table[k1]))

    def state(self, weights, hermite, k, z, speed, out, cells_per_radian):
        """
        Write the lifted state [q, q', 1] of z = [eta, eta', 1] at cell k into ``out``.

        Parameters
        ----------
        weights : ndarray
            Power-form row weights at the crank state (monomial times t^p).
        hermite : ndarray, shape (2, 2 len(MONOMIALS))
            Hermite weights at the crank state (NumpyStep.evaluate).
        k : int
            Grid cell.
        z : ndarray
            Soft state [eta, eta', 1].
        speed : float
            Crank speed [rad/s].
        out : ndarray
            2 r + 1 values, written in place.
        cells_per_radian : float
            Grid cells per radian (for the residual's rate).

        """
        r, p = self.record_size, self.size
        coupled = self._nodes(self.phi, hermite, k, len(LIFT_MONOMIALS)).reshape(r, p)
        first = self._nodes(self.dphi, hermite[:, 2:], k, 1).reshape(r, p)
        out[:r] = coupled @ z[:p] + self._nodes(self.residual, hermite, k,
                                                len(RESIDUAL_MONOMIALS))
        out[r:2 * r] = coupled @ z[p:2 * p] + speed * (
            first @ z[:p] + self._nodes(self.residual, self.rate_weights(weights,
                                                                         cells_per_radian),
                                        k, len(RESIDUAL_MONOMIALS)))
        out[2 * r] = 1.0

    @staticmethod
    def rate_weights(weights, cells_per_radian):
        """Return d/dtheta of the Hermite weights at power-form weights ``weights`` [per rad]."""
        monomials, t = weights[0::4], weights[5]      # power 0 of each; t of monomial '1'
        slope = 6.0 * t * t - 6.0 * t
        rates = np.empty((2, 2 * monomials.size))
        rates[0, 0::2], rates[0, 1::2] = monomials * slope, monomials * (3 * t * t - 4 * t + 1)
        rates[1, 0::2], rates[1, 1::2] = -monomials * slope, monomials * (3 * t * t - 2 * t)
        return rates * cells_per_radian

    def nodes(self, eta, speed):
        """Return q at the grid nodes of soft coordinates ``eta`` (N, p), at a = 0."""
        r, p = self.record_size, self.size
        # Node values (V rows) of monomials 1, w2, w: rows 2, 4, 6 of (a, 1, w2, w) x (V, S).
        frame = (self.phi[:, 2] + speed * speed * self.phi[:, 4]
                 + speed * self.phi[:, 6]).astype(float).reshape(-1, r, p)
        residual = self.residual[:, 2] + speed * speed * self.residual[:, 4]
        return np.einsum('nrp,np->nr', frame, eta) + residual
