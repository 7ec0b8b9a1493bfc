"""
The reduced geometrically nonlinear estimator: one Radau IIA step per sample, by Newton.

The model is :mod:`core.reduction.nonlinear_tables` (a constant basis of the nonlinear full
order with one lumped axial force per flexible link). Per sample interval h the crank angle
and speed are taken linear between the two samples; at the s stage times the linear part
(mass, Coriolis, convective and elastic stiffness, loads) is read from the tables and the
stage accelerations A solve ::

    r_i = M_i A_i + C_i V_i + K_i Q_i + F(Q_i, V_i) - R_i = 0,
    Q_i = q + c_i h v + h^2 (a a A)_i,   V_i = v + h (a A)_i

with full Newton (Jacobian blocks ``M_i d_ij + h a_ij (C_i + F_v) + h^2 (aa)_ij (K_i + F_q)``,
as :mod:`core.fe.nonlinear_step`). A step whose Newton does not converge is retried as two
half steps (down to 1/64 of the interval); a sample that still fails is counted and the
state is kept (the flag says so). Radau IIA is L-stable, so the stiff axial content of the
basis needs no small step.

With ``nonlinear=False`` the lumped strain's change is zero and the rigid-body geometric
stiffness K_G is added: the Galerkin projection of the linear full order.
"""

import time

import numpy as np
import scipy   # scipy.linalg loads on first use: a linear replay never needs it

from ..integrators import RadauIIA

try:
    from . import _nonlinear_step as compiled_newton
except ImportError:     # not built: the numpy Newton serves
    compiled_newton = None

NEWTON_TOLERANCE = 1e-6
NEWTON_ITERATIONS = 30
# An update this many times the first one has left the start's basin: the cubic strain has
# far roots (deflections of kilometres) that the relative test would accept, so the step is
# halved instead. Converging steps grew it at most 277x (the grid test's random 0.2-6 ms steps).
NEWTON_DIVERGENCE = 1e4
# Largest RMS slope of a link's bending relative to its frame [rad] the von Karman strain
# carries: it keeps v'^2 / 2 of the exact stretch sqrt((1 + u')^2 + v'^2) - 1 and drops
# -v'^4 / 8, a relative error of v'^2 / 4 (1 % at 0.2 rad).
VON_KARMAN_SLOPE = 0.2
# A failed step is halved at most this many times.
MAX_HALVINGS = 6
# The tables' fields the compiled step reads, in its order (_nonlinear_step.c).
STEP_FIELDS = ('mass', 'gyroscopic', 'coupling_a', 'coupling_w2', 'elastic', 'elastic_rate',
               'geometric_1', 'geometric_a', 'geometric_w2', 'load_1', 'load_a', 'load_w2',
               'chord', 'chord_rate', 'shortening', 'shortening_rate', 'output')
# Samples per compiled call offline (the call holds no Python lock; Ctrl-C is seen between).
MARCH_CHUNK = 4096


def lumped_force(tables, fields, eta, rate, speed, nonlinear=True, tangents=True):
    """
    Change of the elastic force by the per-link lumped nonlinear strain, and its tangents.

    ``sum_L N_L (c_L + g_L eta) - (E A / L) c_L (c_L^T eta + beta (c_L^T eta' + w c1_L^T
    eta))``, zero for ``nonlinear=False``.

    Parameters
    ----------
    tables : NonlinearTables
        The model.
    fields : dict
        :meth:`NonlinearTables.at` at the stage angles (s, ...).
    eta, rate : ndarray, shape (s, m)
        Coordinates and rates at the stages.
    speed : ndarray, shape (s,)
        Crank speed [rad/s] at the stages.
    nonlinear : bool
        False: no change (the linear model).
    tangents : bool
        False: stiffness and damping are None.

    Returns
    -------
    force : ndarray, shape (s, m)
    stiffness, damping : ndarray, shape (s, m, m) or None
        d force / d eta and d force / d eta'.
    axial : ndarray, shape (s, E)
        N_L [N], tension > 0.

    """
    s, m = eta.shape
    chord, chord_rate = fields['chord'], fields['chord_rate']
    k, beta, w = tables.axial_stiffness, tables.beta, speed[:, None]
    linear_strain = np.einsum('slm,sm->sl', chord, eta)
    linear_rate = (np.einsum('slm,sm->sl', chord, rate)
                   + w * np.einsum('slm,sm->sl', chord_rate, eta))
    if not nonlinear:
        axial = k * (linear_strain + beta * linear_rate)
        return np.zeros((s, m)), np.zeros((s, m, m)), np.zeros((s, m, m)), axial
    short, short_rate = fields['shortening'], fields['shortening_rate']
    g_eta = np.einsum('slmk,sk->slm', short, eta)
    h_sym = short_rate + np.swapaxes(short_rate, -1, -2)
    gradient = chord + g_eta
    strain = linear_strain + 0.5 * np.einsum('slm,sm->sl', g_eta, eta)
    strain_rate = (np.einsum('slm,sm->sl', gradient, rate)
                   + w * (np.einsum('slm,sm->sl', chord_rate, eta)
                          + np.einsum('sm,slmk,sk->sl', eta, short_rate, eta)))
    axial = k * (strain + beta * strain_rate)
    force = (np.einsum('sl,slm->sm', axial, gradient)
             - np.einsum('sl,slm->sm', k * (linear_strain + beta * linear_rate), chord))
    if not tangents:
        return force, None, None, axial
    d_axial = k[:, None] * (gradient + beta * (np.einsum('slmk,sk->slm', short, rate)
                                               + w[..., None] * (chord_rate + np.einsum(
                                                   'slmk,sk->slm', h_sym, eta))))
    stiffness = (np.einsum('slm,slk->smk', gradient, d_axial)
                 + np.einsum('sl,slmk->smk', axial, short)
                 - np.einsum('l,slm,slk->smk', k, chord, chord + beta * w[..., None] * chord_rate))
    damping = beta * (np.einsum('l,slm,slk->smk', k, gradient, gradient)
                      - np.einsum('l,slm,slk->smk', k, chord, chord))
    return force, stiffness, damping, axial


def linear_part(tables, fields, speed, accel, nonlinear=True):
    """
    Linear mass, damping, stiffness and load at the stages: (s, m, m) x 3 and (s, m).

    ``C = w G + beta (K_el + K_bear)``, ``K = K_el + K_bear + beta w K1 + a K_a + w^2 K_w2``
    (+ K_G for the linear model), ``R = f_1 + a f_a + w^2 f_w2``.
    """
    w = speed[:, None, None]
    elastic = fields['elastic'] + tables.bearing
    damping = w * fields['gyroscopic'] + tables.beta * elastic
    stiffness = (elastic + tables.beta * w * fields['elastic_rate'] + accel * fields['coupling_a']
                 + w * w * fields['coupling_w2'])
    if not nonlinear:
        stiffness = (stiffness + fields['geometric_1'] + accel * fields['geometric_a']
                     + w * w * fields['geometric_w2'])
    load = fields['load_1'] + accel * fields['load_a'] + speed[:, None] ** 2 * fields['load_w2']
    return fields['mass'], damping, stiffness, load


class NonlinearStepper:
    """
    The estimator's state (eta, eta') and its Radau IIA step (see the module notes).

    Parameters
    ----------
    tables : NonlinearTables
        The reduced nonlinear model.
    nonlinear : bool
        False: the linear model in the same basis (for checks).
    stages : int
        Radau IIA stages (2: order 3).
    compiled : bool
        Newton in C (_nonlinear_step.c) where it is built; False: the numpy reference.

    """

    def __init__(self, tables, nonlinear=True, stages=2, compiled=True):
        self.tables = tables
        self.nonlinear = bool(nonlinear)
        self.method = RadauIIA(stages)
        self.compiled = bool(compiled) and compiled_newton is not None
        self.q = np.zeros(tables.size)
        self.v = np.zeros(tables.size)
        self.guess = None
        self.iterations = 0
        self.axial = np.zeros(tables.links)
        self.slope = np.zeros(tables.links)     # written in place by the compiled march
        # output operator at the last step's end (the last stage: c_s = 1)
        self.output_operator = None

    def start(self, angle, speed):
        """Start from the quasi-static deflection at (angle, speed), at rest in eta."""
        fields = self.tables.at(angle)
        _, _, stiffness, load = linear_part(self.tables, fields, np.array([speed]), 0.0,
                                            self.nonlinear)
        self.q = np.linalg.solve(stiffness[0], load[0])
        self.v = np.zeros_like(self.q)
        self.guess = None
        self.output_operator = fields['output'][0].copy()

    def outputs(self, angle):
        """Output deflections [m] at crank angle ``angle`` for the current state, (channels,)."""
        return self.tables.at(angle, ('output',))['output'][0] @ self.q

    def _residual(self, h, acc, fields, speed, linear, tangents):
        """Residual (s m,), Jacobian (s m, s m) or None, and N_L at stage accelerations."""
        method = self.method
        mass, damping, stiffness, load = linear
        disp = self.q[None] + (method.c[:, None] * h) * self.v[None] + h * h * (method.a2 @ acc)
        vel = self.v[None] + h * (method.a @ acc)
        force, f_q, f_v, axial = lumped_force(self.tables, fields, disp, vel, speed,
                                              self.nonlinear, tangents)
        residual = (np.einsum('sij,sj->si', mass, acc) + np.einsum('sij,sj->si', damping, vel)
                    + np.einsum('sij,sj->si', stiffness, disp) + force - load)
        jacobian = (method.step_matrix(h, mass, damping + f_v, stiffness + f_q) if tangents
                    else None)
        return residual.ravel(), jacobian, axial

    def _newton(self, h, fields, speed, accel):
        """
        Solve one step's stage accelerations; None if Newton does not converge.

        Simplified Newton from the predicted start (:meth:`_predicted`): the Jacobian is
        formed at the first iteration and formed again only when an iteration contracts the
        update by less than half. An update ``NEWTON_DIVERGENCE`` times the first one is not
        converging (the caller halves the step).
        """
        linear = linear_part(self.tables, fields, speed, accel, self.nonlinear)
        s, m = speed.shape[0], self.tables.size
        acc, factor, previous, first = self._predicted(h), None, np.inf, np.inf
        for count in range(1, NEWTON_ITERATIONS + 1):
            residual, jacobian, axial = self._residual(h, acc, fields, speed, linear,
                                                       factor is None)
            if jacobian is not None:
                factor = scipy.linalg.lu_factor(jacobian, check_finite=False)
            update = scipy.linalg.lu_solve(factor, -residual, check_finite=False)
            acc = acc + update.reshape(s, m)
            size, scale = np.abs(update).max(), np.abs(acc).max()
            if not np.isfinite(size):
                return None
            if size <= NEWTON_TOLERANCE * scale or size == 0.0:
                self.iterations += count
                self.axial = axial[-1]
                return acc
            if count == 1:
                first = size
            elif size > NEWTON_DIVERGENCE * first:
                return None
            if size > 0.5 * previous:
                factor = None
            previous = size
        return None

    def _predicted(self, h):
        """
        Newton's start: the last step's stage accelerations extrapolated to this step's stages.

        Linear in time through its last two stages (``guess`` = (stage accelerations, its h));
        zero without a last step.
        """
        method, size = self.method, self.tables.size
        if self.guess is None:
            return np.zeros((method.stages, size))
        acc, last_h = self.guess
        if method.stages == 1:
            return acc.copy()
        fraction = method.c * h / ((method.c[-1] - method.c[-2]) * last_h)
        return acc[-1] + fraction[:, None] * (acc[-1] - acc[-2])

    def _link_slopes(self, angle):
        """RMS slope of each link's bending [rad]: sqrt(2 S_L / L), S_L = eta^T g_L eta / 2."""
        shortening = self.tables.at(angle, ('shortening',))['shortening'][0]
        doubled = np.einsum('m,lmk,k->l', self.q, shortening, self.q)
        return np.sqrt(np.maximum(doubled, 0.0) / self.tables.link_length)

    def _native_arguments(self):
        """Return the compiled march's constant arguments: tables, tableau, sizes (made once)."""
        cached = self.__dict__.get('_native')
        if cached is None:
            tables, method = self.tables, self.method
            layout = tables.layout()
            offsets = np.array([layout[name][0] for name in STEP_FIELDS], dtype=float)
            arrays = (tables.values, tables.slopes, offsets, tables.bearing,
                      tables.axial_stiffness, tables.link_length, method.a, method.a2,
                      method.c)
            sizes = (tables.grid_size, tables.values.shape[1], method.stages, tables.size,
                     tables.links, tables.outputs)
            self._guess_buffer = np.zeros(method.stages * tables.size + 1)
            self._guess_view = self._guess_buffer[:-1].reshape(method.stages, tables.size)
            one = (np.empty(2), np.empty(2), np.empty(2), np.empty((1, tables.outputs)),
                   np.empty((1, tables.links)), np.empty((1, tables.links)), np.empty(1),
                   np.empty(1))
            self._work = np.empty(compiled_newton.workspace(method.stages, tables.size,
                                                            tables.links, tables.outputs))
            cached = self._native = (
                tuple(np.ascontiguousarray(a, dtype=float) for a in arrays), sizes,
                (float(tables.beta), self.nonlinear, NEWTON_TOLERANCE, NEWTON_ITERATIONS,
                 NEWTON_DIVERGENCE), one)
        return cached

    def _call_march(self, times, angles, speeds, out, halvings):
        """Run the compiled march over ``times`` etc. (float64 arrays) into ``out``."""
        arrays, sizes, constants, _ = self._native_arguments()
        tables, buffer = self.tables, self._guess_buffer
        if self.output_operator is None:
            self.output_operator = np.zeros((tables.outputs, tables.size))
        if self.guess is not None and self.guess[0] is not self._guess_view:
            buffer[:-1], buffer[-1] = self.guess[0].ravel(), self.guess[1]
        iterations, has_guess = compiled_newton.march(
            *arrays, times, angles, speeds, self.q, self.v, buffer, self.axial, self.slope,
            self.output_operator, *out, self._work, *sizes, len(times) - 1, *constants, halvings,
            self.guess is not None)
        self.iterations += iterations
        self.guess = (self._guess_view, buffer[-1]) if has_guess else None

    def step_to(self, h, angle0, angle, speed0, speed, halvings=MAX_HALVINGS):
        """
        Step to a sample whose angle may be wrapped: (its unwrapped angle, converged).

        The angle is unwrapped from ``angle0`` by the speeds (:func:`unwrap_next`), then
        :meth:`step` steps to it: in one compiled call where built (the same numbers).
        """
        if self.compiled:
            stepped = self._step_one(h, angle0, angle, speed0, speed, halvings, True)
            if stepped is not None:
                return stepped
        theta = unwrap_next(angle0, angle, speed0, speed, h)   # raises on a non-finite turn
        return theta, self.step(h, angle0, theta, speed0, speed, halvings)

    def _step_one(self, h, angle0, angle, speed0, speed, halvings, unwrap):
        """
        Step one sample interval with the compiled Stepper: (angle stepped to, converged).

        The node's per-sample call: the Stepper holds the march's buffers and is made again
        only when a start (or the numpy step) replaces the state's arrays. None where the
        unwrapping is not finite (nothing changed).
        """
        kernel, kept = self.__dict__.get('_kernel'), self.__dict__.get('_kernel_arrays')
        if (kernel is None or kept[0] is not self.q or kept[1] is not self.v
                or kept[2] is not self.axial or kept[3] is not self.slope
                or kept[4] is not self.output_operator):
            kernel = self._make_kernel()
        if self.guess is not None and self.guess[0] is not self._guess_view:
            buffer = self._guess_buffer
            buffer[:-1], buffer[-1] = self.guess[0].ravel(), self.guess[1]
        stepped = kernel.step(h, angle0, angle, speed0, speed, self.guess is not None,
                              halvings, unwrap)
        if stepped is None:
            return None
        theta, iterations, has_guess, converged = stepped
        self.iterations += iterations
        self.guess = (self._guess_view, self._guess_buffer[-1]) if has_guess else None
        return theta, converged != 0

    def _make_kernel(self):
        """Make (and keep) the compiled Stepper of the state's current arrays."""
        arrays, sizes, constants, one = self._native_arguments()
        if self.output_operator is None:
            self.output_operator = np.zeros((self.tables.outputs, self.tables.size))
        state = (self.q, self.v, self._guess_buffer, self.axial, self.slope,
                 self.output_operator)
        self._kernel = compiled_newton.Stepper(*arrays, *one[:3], *state, *one[3:], self._work,
                                               *sizes, 1, *constants, MAX_HALVINGS, False)
        self._kernel_arrays = (self.q, self.v, self.axial, self.slope, self.output_operator)
        return self._kernel

    def march(self, times, angles, speeds, halvings=MAX_HALVINGS):
        """
        Step the state through samples 1.. of ``times`` [s], unwrapped ``angles``, ``speeds``.

        The compiled step, one call for every sample (sample 0 is where the state is).
        Returns per sample the outputs (K, channels), axial forces and link slopes (K, E),
        converged (K,) and the step's own time [ns] (K,); a sample whose step does not
        converge keeps the state and reads the outputs at its angle.
        """
        tables, count = self.tables, len(times) - 1
        out = (np.empty((count, tables.outputs)), np.empty((count, tables.links)),
               np.empty((count, tables.links)), np.empty(count), np.empty(count))
        self._call_march(*(np.ascontiguousarray(values, dtype=float)
                           for values in (times, angles, speeds)), out, int(halvings))
        return out[0], out[1], out[2], out[3].astype(bool), out[4].astype(np.int64)

    def step(self, h, angle0, angle1, speed0, speed1, halvings=MAX_HALVINGS):
        """
        Advance the state over an interval of length h [s] between two samples.

        Returns True if every (sub)step converged; the state is unchanged otherwise (and for
        a non-finite input or a step that is not positive).
        """
        if self.compiled:          # the compiled step checks the input itself
            return self._step_one(h, angle0, angle1, speed0, speed1, halvings, False)[1]
        if not (np.isfinite([h, angle0, angle1, speed0, speed1]).all() and h > 0.0):
            return False
        c = self.method.c
        angles = angle0 + c * (angle1 - angle0)
        speed = speed0 + c * (speed1 - speed0)
        accel = (speed1 - speed0) / h
        fields = self.tables.at(angles)
        acc = self._newton(h, fields, speed, accel)
        output = fields['output'][-1]
        if acc is None:
            if halvings == 0:
                return False
            saved = (self.q, self.v, self.guess)
            middle_angle, middle_speed = 0.5 * (angle0 + angle1), 0.5 * (speed0 + speed1)
            self.guess = None
            if not (self.step(0.5 * h, angle0, middle_angle, speed0, middle_speed, halvings - 1)
                    and self.step(0.5 * h, middle_angle, angle1, middle_speed, speed1,
                                  halvings - 1)):
                self.q, self.v, self.guess = saved
                return False
            return True
        self.q = self.q + h * self.v + h * h * (self.method.a2[-1] @ acc)
        self.v = self.v + h * (self.method.a[-1] @ acc)
        self.guess = (acc.copy(), h)
        self.output_operator = output.copy()
        self.slope = self._link_slopes(angle1)
        return True


def unwrap_with_speed(time_s, angles, speeds=None):
    """
    Unwrap crank angles, by the speeds where given (steps of more than half a turn).

    Each step's angle change is taken as the one nearest to ``mean speed x h`` modulo 2 pi;
    without speeds, as the nearest to zero (np.unwrap) and the speeds from its gradient.
    """
    if speeds is None:
        theta = np.unwrap(angles)
        return theta, np.gradient(theta, time_s)
    speeds = np.asarray(speeds, dtype=float)
    predicted = 0.5 * (speeds[1:] + speeds[:-1]) * np.diff(time_s)
    change = np.diff(angles) - predicted
    change = predicted + change - 2.0 * np.pi * np.round(change / (2.0 * np.pi))
    return angles[0] + np.concatenate([[0.0], np.cumsum(change)]), speeds


def unwrap_next(angle0, angle1, speed0, speed1, h):
    """
    Unwrap one sample's crank angle from the last one's: :func:`unwrap_with_speed` of a pair.

    Plain floats (the streaming update's per-sample call); the same arithmetic.
    """
    predicted = 0.5 * (speed1 + speed0) * h
    change = (angle1 - angle0) - predicted
    two_pi = 2.0 * np.pi
    return angle0 + (predicted + change - two_pi * round(change / two_pi))


def estimate_nonlinear(tables, stamps_ns, angles, speeds=None, nonlinear=True, compiled=True):
    """
    Estimate the output deflections of a crank signal with the reduced nonlinear model.

    Samples with a non-finite angle or speed are refused (counted, their outputs NaN) and
    left out of the stepping: the next good sample steps from the last good one.

    Parameters
    ----------
    tables : NonlinearTables
        The model.
    stamps_ns : ndarray of int, shape (K,)
        Sample stamps [ns], increasing.
    angles : ndarray, shape (K,)
        Crank angles [rad] (wrapped or not).
    speeds : ndarray, shape (K,) or None
        Crank speeds [rad/s]; None to differentiate the unwrapped angles.
    nonlinear : bool
        False: the linear model in the same basis.
    compiled : bool
        The step in C where built (False: the numpy reference).

    Returns
    -------
    dict
        'outputs' (K, channels) [m], 'converged' (K,) bool, 'newton_iterations' (total),
        'axial_force' (K, E) [N], 'refused' (samples refused: bad input or a failed step),
        'bad_input' (of them, non-finite input), 'link_slope' (K, E) (RMS bending slope of
        each link [rad]), 'beyond_von_karman' (samples with a slope above
        :data:`VON_KARMAN_SLOPE`), 'update_ns' (K,) (perf_counter_ns of each sample's step and
        outputs).

    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    theta = np.asarray(angles, dtype=float)
    if stamps.ndim != 1 or stamps.shape != theta.shape or np.any(np.diff(stamps) <= 0):
        raise ValueError('stamps must be increasing and match the angles, one per sample')
    good = np.isfinite(theta)
    if speeds is not None:
        speeds = np.asarray(speeds, dtype=float)
        if speeds.shape != theta.shape:
            raise ValueError('speeds must match the angles, one per sample')
        good &= np.isfinite(speeds)
        speeds = speeds[good]
    count = theta.shape[0]
    out = {'outputs': np.full((count, tables.outputs), np.nan),
           'axial_force': np.full((count, tables.links), np.nan),
           'link_slope': np.full((count, tables.links), np.nan),
           'converged': np.zeros(count, dtype=bool), 'update_ns': np.zeros(count, np.int64),
           'newton_iterations': 0, 'bad_input': int((~good).sum())}
    if good.any():
        marched = _march(tables, stamps[good], theta[good], speeds, nonlinear, compiled)
        for name in ('outputs', 'axial_force', 'link_slope', 'converged', 'update_ns'):
            out[name][good] = marched[name]
        out['newton_iterations'] = marched['newton_iterations']
    out['refused'] = int((~out['converged']).sum())
    with np.errstate(invalid='ignore'):
        out['beyond_von_karman'] = int((out['link_slope'] > VON_KARMAN_SLOPE).any(axis=1).sum())
    return out


def _march(tables, stamps, theta, speeds, nonlinear, compiled):
    """Step the model through finite samples; the arrays of :func:`estimate_nonlinear`."""
    time_s = (stamps - stamps[0]) * 1e-9
    theta, speeds = unwrap_with_speed(time_s, theta, speeds)
    stepper = NonlinearStepper(tables, nonlinear, compiled=compiled)
    stepper.start(theta[0], speeds[0])
    count = theta.shape[0]
    outputs = np.empty((count, tables.outputs))
    axial = np.zeros((count, tables.links))
    slope = np.zeros((count, tables.links))
    converged = np.ones(count, dtype=bool)
    update_ns = np.zeros(count, dtype=np.int64)
    outputs[0] = stepper.outputs(theta[0])
    slope[0] = stepper._link_slopes(theta[0])
    if stepper.compiled:
        for first in range(0, count - 1, MARCH_CHUNK):
            span = slice(first, min(count, first + MARCH_CHUNK + 1))
            rows = slice(first + 1, span.stop)
            (outputs[rows], axial[rows], slope[rows], converged[rows],
             update_ns[rows]) = stepper.march(time_s[span], theta[span], speeds[span])
    else:
        _march_in_python(stepper, time_s, theta, speeds,
                         (outputs, axial, slope, converged, update_ns))
    return {'outputs': outputs, 'converged': converged, 'axial_force': axial,
            'link_slope': slope, 'newton_iterations': stepper.iterations,
            'update_ns': update_ns}


def _march_in_python(stepper, time_s, theta, speeds, arrays):
    """Step the numpy reference sample by sample into ``arrays`` (as the compiled march)."""
    outputs, axial, slope, converged, update_ns = arrays
    clock = time.perf_counter_ns
    for k in range(1, theta.shape[0]):
        begin = clock()
        converged[k] = stepper.step(time_s[k] - time_s[k - 1], theta[k - 1], theta[k],
                                    speeds[k - 1], speeds[k])
        if not converged[k]:
            stepper.output_operator = stepper.tables.at(theta[k], ('output',))['output'][0]
        outputs[k], axial[k] = stepper.output_operator @ stepper.q, stepper.axial
        slope[k] = stepper.slope
        update_ns[k] = clock() - begin


__all__ = ['NonlinearStepper', 'lumped_force', 'linear_part', 'unwrap_with_speed', 'unwrap_next',
           'estimate_nonlinear']
