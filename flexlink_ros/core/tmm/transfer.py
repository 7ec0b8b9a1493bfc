"""
Transfer-matrix natural frequencies of a lumped-mass Euler-Bernoulli beam (Kim & Moon).

The beam's mass sits at points joined by massless elastic fields (Pestel & Leckie 1963). The
state vector at a station is::

    z = [-W, theta, M, V]

(deflection with the sign that makes every transfer entry positive, slope, bending moment,
shear force; SI units: m, rad, N m, N). A field of length l carries z by :func:`field_matrix`,
a point mass m at frequency omega by :func:`point_matrix` (inertia force m omega^2 W), and
the left boundary conditions of Eq. 3 leave two unknown columns, so the right boundary
conditions give the 2x2 frequency determinant |D(omega)| of Eq. 4. Roots are bracketed by an
incremental scan from omega = 0 with step d_omega, then refined by bisection (Eq. 5), false
position (Eq. 6) or Newton (Eq. 7, the derivative propagated exactly by the extended transfer
matrix). Mass-lumping methods 1-3 are those of the paper's numerical section.

Convergence: an iterate is accepted when the frequency change from the previous iterate is at
most ``rtol * omega`` (default 1e-12) *and* |D| is at most ``dtol`` (default 1e-6) times the
larger |D| at the bracket ends. The paper stopped at |D| <= 1e-6 in kgf-mm units, which for the
fixed-fixed beam accepts the first false-position iterate 1198.96312 rad/s (Table 5) while the
root is 1198.963684 rad/s; the iteration at which that loose test is first met is reported too.

References
----------
Kim, Y.-S. & Moon, D.-H., "A Study on the Vibration Analysis of Beam" (Korean), Eqs. 2-7,
Tables 1-5. Pestel, E. C. & Leckie, F. A. (1963), Matrix Methods in Elastomechanics.

"""

import dataclasses
import math

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg
from scipy.optimize import brentq

from ..fe import beam as beam_element
from ...errors import ConvergenceError, FlexlinkError

# Standard gravity [m/s^2]: kgf -> N for forces and Young's modulus.
STANDARD_GRAVITY = 9.80665
# Gravity [m/s^2] the paper's exact values imply for mass = specific weight / g (papers.md).
KIM_MOON_GRAVITY = 9.807
# The paper's convergence test: |D| <= 1e-6 with D in kgf and mm units (Tables 2-5).
PAPER_DETERMINANT_TOL = 1e-6
# Default root-search tolerances (see module docstring).
DEFAULT_RTOL = 1e-12
DEFAULT_DTOL = 1e-6
DEFAULT_STEP_RAD_S = 10.0      # the paper's d_omega for Tables 2, 4, 5
MAX_ITERATIONS = 200
# Largest eigenproblem solved dense; above it sparse LU + ARPACK (dense LAPACK on more DOFs
# is slow when OpenBLAS threads compete for the cores).
DENSE_EIGEN_LIMIT = 64
# Bending DOFs (v1, phi1, v2, phi2) within core/beam.py's element order (u1, v1, phi1, ...).
_BENDING = [1, 2, 4, 5]
# Relative gap between a found root and the stiffness-based lumped frequency that means a skip.
VERIFY_RTOL = 1e-4
MAX_SCAN_STEPS = 2_000_000

BOUNDARY_CONDITIONS = ('fixed-fixed', 'fixed-supported', 'cantilever', 'supported')
LUMPING_METHODS = (1, 2, 3)
SEARCHES = ('bisection', 'false-position', 'newton')

# Eq. 3: state entries left unknown at x = 0, and entries that vanish at x = L.
_UNKNOWN_AT_LEFT = {'fixed-fixed': (2, 3), 'fixed-supported': (2, 3), 'cantilever': (2, 3),
                    'supported': (1, 3)}
_ZERO_AT_RIGHT = {'fixed-fixed': (0, 1), 'fixed-supported': (0, 2), 'cantilever': (2, 3),
                  'supported': (0, 2)}
# Which ends are free, and which restrain the rotation, for the stiffness-based reference.
_CLAMPED_ENDS = {'fixed-fixed': (True, True), 'fixed-supported': (True, False),
                 'cantilever': (True, False), 'supported': (False, False)}
# State components from SI (m, 1, N m, N) to the paper's units (mm, 1, kgf mm, kgf).
_TO_KGF_MM = np.array([1e3, 1.0, 1e3 / STANDARD_GRAVITY, 1.0 / STANDARD_GRAVITY])


def check_boundary_condition(bc):
    """Return `bc` if it is one of :data:`BOUNDARY_CONDITIONS`, else raise ValueError."""
    if bc not in BOUNDARY_CONDITIONS:
        raise ValueError(f'`bc` must be one of {", ".join(BOUNDARY_CONDITIONS)}, got {bc!r}')
    return bc


@dataclasses.dataclass(frozen=True)
class UniformBeam:
    """
    Uniform Euler-Bernoulli beam in SI units.

    Attributes
    ----------
    E : float
        Young's modulus [Pa].
    I : float
        Second moment of area about the bending axis [m^4].
    mass_per_length : float
        Mass per unit length rho A [kg/m].
    length : float
        Length L [m].

    """

    E: float
    I: float
    mass_per_length: float
    length: float

    def __post_init__(self):
        for name in ('E', 'I', 'mass_per_length', 'length'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f'`{name}` must be a positive finite number, got {value!r}')

    @classmethod
    def rectangular(cls, E, density, length, width, thickness):
        """
        Beam of rectangular section bending about its thin side.

        Parameters
        ----------
        E : float
            Young's modulus [Pa].
        density : float
            Mass density [kg/m^3].
        length, width, thickness : float
            Dimensions [m]; I = width thickness^3 / 12.

        """
        for name, value in (('density', density), ('width', width), ('thickness', thickness)):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f'`{name}` must be a positive finite number, got {value!r}')
        return cls(E=float(E), I=width * thickness ** 3 / 12.0,
                   mass_per_length=density * width * thickness, length=float(length))

    @classmethod
    def kim_moon(cls):
        """
        The uniform beam of Kim & Moon, Table 1, converted to SI.

        E = 18582 kgf/mm^2 (times 9.80665 N/kgf), specific weight 7.43e-6 kgf/mm^3 turned into
        a density with g = 9.807 m/s^2 (the value the paper's exact frequencies imply),
        L = 200 mm, b = 30 mm, t = 1.5 mm.

        """
        specific_weight = 7.43e-6 * STANDARD_GRAVITY * 1e9      # N/m^3
        return cls.rectangular(E=18582.0 * STANDARD_GRAVITY * 1e6,
                               density=specific_weight / KIM_MOON_GRAVITY,
                               length=0.200, width=0.030, thickness=0.0015)

    @property
    def flexural_rigidity(self):
        """EI [N m^2]."""
        return self.E * self.I

    @property
    def mass(self):
        """Total mass [kg]."""
        return self.mass_per_length * self.length


@dataclasses.dataclass(frozen=True)
class LumpedBeam:
    """
    Point masses on a massless beam of constant EI (the transfer-matrix model).

    Attributes
    ----------
    positions : ndarray, shape (n_masses,)
        Mass locations from the left end [m], non-decreasing, within [0, length].
    masses : ndarray, shape (n_masses,)
        Point masses [kg].
    flexural_rigidity : float
        EI of the massless fields [N m^2].
    length : float
        Beam length [m].

    """

    positions: np.ndarray
    masses: np.ndarray
    flexural_rigidity: float
    length: float

    @property
    def segment_ends(self):
        """Right end of every field [m]: each mass position, then the beam end (list)."""
        return [float(p) for p in self.positions] + [float(self.length)]

    @property
    def point_masses(self):
        """Mass at the right end of every field [kg]: the masses, then 0 at the beam end."""
        return [float(m) for m in self.masses] + [0.0]


def lump_masses(beam, segments, method, bc):
    """
    Lump a uniform beam's mass onto points, methods 1-3 of Kim & Moon.

    The beam is cut into `segments` equal parts of length h. Method 1: m/n at every segment
    centre. Method 2: m/(n-1) at each of the n-1 interior division points. Method 3: m/n at
    the interior division points and m/(2n) at each end, except that a free end's share sits
    h/6 inside the tip.

    Parameters
    ----------
    beam : UniformBeam
    segments : int
        Number of equal segments n (method 2 needs n >= 2).
    method : int
        1, 2 or 3.
    bc : str
        One of :data:`BOUNDARY_CONDITIONS` (decides whether the right end is free).

    Returns
    -------
    LumpedBeam

    """
    check_boundary_condition(bc)
    if method not in LUMPING_METHODS:
        raise ValueError(f'`method` must be 1, 2 or 3, got {method!r}')
    if isinstance(segments, bool) or not isinstance(segments, (int, np.integer)) \
            or segments < (2 if method == 2 else 1):
        raise ValueError(f'`segments` must be an integer >= {2 if method == 2 else 1} for '
                         f'method {method}, got {segments!r}')
    n, length, mass = int(segments), beam.length, beam.mass
    h = length / n
    interior = h * np.arange(1, n)
    if method == 1:
        positions, masses = h * (np.arange(n) + 0.5), np.full(n, mass / n)
    elif method == 2:
        positions, masses = interior, np.full(n - 1, mass / (n - 1))
    else:
        right = length - h / 6.0 if bc == 'cantilever' else length
        positions = np.concatenate(([0.0], interior, [right]))
        masses = np.concatenate(([mass / (2 * n)], np.full(n - 1, mass / n), [mass / (2 * n)]))
    return LumpedBeam(positions=positions, masses=masses,
                      flexural_rigidity=beam.flexural_rigidity, length=length)


def field_matrix(length, flexural_rigidity):
    """
    Field transfer matrix of a massless Euler-Bernoulli segment (Pestel & Leckie).

    Parameters
    ----------
    length : float
        Segment length l [m].
    flexural_rigidity : float
        EI [N m^2].

    Returns
    -------
    ndarray, shape (4, 4)
        Maps [-W, theta, M, V] at the segment's left end to its right end.

    """
    span, ei = length, flexural_rigidity
    return np.array([
        [1.0, span, span ** 2 / (2 * ei), span ** 3 / (6 * ei)],
        [0.0, 1.0, span / ei, span ** 2 / (2 * ei)],
        [0.0, 0.0, 1.0, span],
        [0.0, 0.0, 0.0, 1.0],
    ])


def point_matrix(mass, omega):
    """
    Point transfer matrix of a mass m vibrating at omega: V jumps by m omega^2 (-W).

    Returns
    -------
    ndarray, shape (4, 4)

    """
    p = np.eye(4)
    p[3, 0] = mass * omega ** 2
    return p


def frequency_determinant(model, bc, omega, derivative=False):
    """
    Frequency determinant |D(omega)| of Eq. 4 and, optionally, its omega-derivative.

    The two unknown left-end columns of Eq. 3 are carried through the fields and points
    (half the work of carrying the full 4x4 product); the rows that vanish at the right end
    form D. With ``derivative=True`` d(state)/d(omega) is propagated alongside (extended
    transfer matrix): fields are independent of omega, a point adds 2 m omega (-W).

    Parameters
    ----------
    model : LumpedBeam
    bc : str
        One of :data:`BOUNDARY_CONDITIONS`.
    omega : float
        Circular frequency [rad/s].
    derivative : bool
        Also return d|D|/d(omega).

    Returns
    -------
    float or tuple of float
        |D| in SI units (its unit depends on `bc`), or (|D|, d|D|/d(omega)).

    """
    # Pure-float arithmetic: one state column per unknown of Eq. 3, [u, theta, M, V] with
    # u = -W; each field and point matrix is applied entry by entry (see field_matrix).
    ei = model.flexural_rigidity
    columns = []
    for unknown in _UNKNOWN_AT_LEFT[bc]:
        z = [0.0, 0.0, 0.0, 0.0]
        z[unknown] = 1.0
        columns.append(z + [0.0, 0.0, 0.0, 0.0])  # state, then d(state)/d(omega)
    omega2 = omega * omega
    x = 0.0
    for position, mass in zip(model.segment_ends, model.point_masses):
        span = position - x
        x = position
        c2, c3, c1 = span * span / (2.0 * ei), span ** 3 / (6.0 * ei), span / ei
        for z in columns:
            u, t, m, v, du, dt, dm, dv = z
            u, t, m = u + span * t + c2 * m + c3 * v, t + c1 * m + c2 * v, m + span * v
            if derivative:
                du, dt, dm = (du + span * dt + c2 * dm + c3 * dv, dt + c1 * dm + c2 * dv,
                              dm + span * dv)
                dv = dv + mass * omega2 * du + 2.0 * mass * omega * u
            v = v + mass * omega2 * u
            z[:] = (u, t, m, v, du, dt, dm, dv)
    first, second = _ZERO_AT_RIGHT[bc]
    (a, b), (c, d) = [[z[first] for z in columns], [z[second] for z in columns]]
    det = a * d - b * c
    if not derivative:
        return det
    (da, db), (dc, dd) = [[z[4 + first] for z in columns], [z[4 + second] for z in columns]]
    return det, da * d + a * dd - db * c - b * dc


def frequency_determinants(model, bc, omegas):
    """
    |D| of Eq. 4 at many frequencies at once (vectorised :func:`frequency_determinant`).

    Parameters
    ----------
    model : LumpedBeam
    bc : str
    omegas : ndarray, shape (k,)
        Circular frequencies [rad/s].

    Returns
    -------
    ndarray, shape (k,)

    """
    omega2 = np.asarray(omegas, dtype=float) ** 2
    ei = model.flexural_rigidity
    state = np.zeros((4, omega2.size, 2))
    for column, unknown in enumerate(_UNKNOWN_AT_LEFT[bc]):
        state[unknown, :, column] = 1.0
    u, t, m, v = state
    x = 0.0
    for position, mass in zip(model.segment_ends, model.point_masses):
        span = position - x
        x = position
        u, t, m = (u + span * t + span * span / (2 * ei) * m + span ** 3 / (6 * ei) * v,
                   t + span / ei * m + span * span / (2 * ei) * v, m + span * v)
        v = v + (mass * omega2)[:, None] * u
    state = (u, t, m, v)
    first, second = (state[row] for row in _ZERO_AT_RIGHT[bc])
    return first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0]


def determinant_to_kgf_mm(bc):
    """
    Factor turning an SI |D| into the paper's kgf-mm units (Tables 2-5).

    Returns
    -------
    float

    """
    rows, cols = _ZERO_AT_RIGHT[bc], _UNKNOWN_AT_LEFT[bc]
    return float(np.prod(_TO_KGF_MM[list(rows)]) / np.prod(_TO_KGF_MM[list(cols)]))


@dataclasses.dataclass(frozen=True)
class RootResult:
    """
    One refined root of |D(omega)| = 0.

    Attributes
    ----------
    frequency_rad_s : float
        Converged natural frequency.
    iterations : int
        Iterates computed until both tolerances held.
    iterations_paper_criterion : int or None
        First iterate meeting the paper's |D| <= 1e-6 (kgf-mm units), None if never met.
    bracket : tuple of float
        Scan interval (omega_1, omega_2) with a sign change.
    history : tuple of float
        Every iterate [rad/s].

    """

    frequency_rad_s: float
    iterations: int
    iterations_paper_criterion: object
    bracket: tuple
    history: tuple


def refine_root(model, bc, bracket, search='false-position', rtol=DEFAULT_RTOL,
                dtol=DEFAULT_DTOL, max_iterations=MAX_ITERATIONS, paper_scale=None,
                illinois=True):
    """
    Refine a bracketed root of |D(omega)| by bisection, false position or Newton.

    Bisection takes the midpoint (Eq. 5); false position the secant through the bracket ends
    (Eq. 6); Newton steps omega - |D|/|D|' (Eq. 7) from the bracket end with the smaller |D|,
    with the exact derivative of :func:`frequency_determinant` and a bisection step whenever
    a Newton step would leave the current bracket. Every method keeps the bracket (sign
    change) up to date. The paper's false position is plain regula falsi, whose one end can
    stay put while the other crawls (on a 5000 rad/s bracket it needs thousands of
    iterations); with `illinois` (default) the retained end's |D| is halved whenever the same
    end is kept twice in a row (Dowell & Jarratt 1971), which restores superlinear
    convergence and leaves the first two iterates as in the paper.

    Parameters
    ----------
    model : LumpedBeam
    bc : str
    bracket : tuple of float
        (omega_1, omega_2) [rad/s] with |D| of opposite signs at the ends.
    search : str
        'bisection', 'false-position' or 'newton'.
    rtol : float
        Relative tolerance on the change of frequency between iterates.
    dtol : float
        Tolerance on |D| relative to the larger |D| at the bracket ends.
    max_iterations : int
    paper_scale : float, optional
        SI-to-kgf-mm factor of |D| for the paper's criterion (default from `bc`).
    illinois : bool
        Illinois modification of false position (False: the paper's plain Eq. 6).

    Returns
    -------
    RootResult

    Raises
    ------
    ConvergenceError
        If the tolerances are not met within `max_iterations`.

    """
    if search not in SEARCHES:
        raise ValueError(f'`search` must be one of {", ".join(SEARCHES)}, got {search!r}')
    if paper_scale is None:
        paper_scale = determinant_to_kgf_mm(bc)
    newton = search == 'newton'

    def evaluate(omega):
        return frequency_determinant(model, bc, omega, derivative=newton)

    def value(result):
        return result[0] if newton else result

    low, high = float(bracket[0]), float(bracket[1])
    at_low, at_high = evaluate(low), evaluate(high)
    f_low, f_high = value(at_low), value(at_high)
    if f_low * f_high > 0:
        raise ValueError(f'`bracket` ({low}, {high}) does not change the sign of |D|')
    reference = max(abs(f_low), abs(f_high))
    start_low = abs(f_low) <= abs(f_high)
    previous = low if start_low else high
    current_value = f_low if start_low else f_high
    slope = (at_low if start_low else at_high)[1] if newton else None
    history = []
    paper_iteration = None
    kept_before = None  # bracket end retained by the previous iterate
    for iteration in range(1, max_iterations + 1):
        if search == 'bisection':
            omega = 0.5 * (low + high)
        elif search == 'false-position':
            omega = low + f_low / (f_low - f_high) * (high - low)
        else:
            omega = previous - current_value / slope if slope != 0.0 else math.nan
            if not (low < omega < high):
                omega = 0.5 * (low + high)
        if omega in (low, high) and history:
            omega = previous  # bracket collapsed to adjacent floats: nothing left to gain
        result = evaluate(omega)
        f = value(result)
        history.append(omega)
        if paper_iteration is None and abs(f * paper_scale) <= PAPER_DETERMINANT_TOL:
            paper_iteration = iteration
        converged = (abs(omega - previous) <= rtol * abs(omega)
                     and abs(f) <= dtol * reference) or f == 0.0
        if converged:
            return RootResult(omega, iteration, paper_iteration, (bracket[0], bracket[1]),
                              tuple(history))
        if f * f_low > 0:
            low, f_low = omega, f
            kept = 'high'
        else:
            high, f_high = omega, f
            kept = 'low'
        if illinois and search == 'false-position' and kept == kept_before:
            if kept == 'high':
                f_high *= 0.5
            else:
                f_low *= 0.5
        kept_before = kept
        previous, current_value = omega, f
        if newton:
            slope = result[1]
    raise ConvergenceError(f'{search} root search in ({bracket[0]:g}, {bracket[1]:g}) rad/s',
                           max_iterations, abs(f) / reference)


def scan_brackets(model, bc, count, step=DEFAULT_STEP_RAD_S, start=0.0,
                  max_steps=MAX_SCAN_STEPS):
    """
    Bracket the lowest `count` roots by stepping omega from `start` in increments `step`.

    An interval is kept when |D| changes sign across it (a scan point where |D| is exactly 0
    is a root and brackets itself). Two roots closer than `step` cancel and are missed; use
    :func:`lumped_frequencies` to check.

    Returns
    -------
    brackets : list of tuple of float
        `count` intervals (omega_1, omega_2) [rad/s].
    evaluations : int
        Determinants evaluated by the scan.

    """
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f'`step` must be a positive number of rad/s, got {step!r}')
    brackets = []
    evaluations = 0
    chunk = 256  # scan points evaluated per vectorised call
    previous = None
    while len(brackets) < count:
        if evaluations > max_steps:
            raise ConvergenceError(f'frequency scan with step {step:g} rad/s', evaluations,
                                   math.nan)
        omegas = start + step * np.arange(evaluations, evaluations + chunk)
        values = frequency_determinants(model, bc, omegas)
        for omega, f in zip(omegas, values):
            evaluations += 1
            if previous is not None:
                if previous[1] == 0.0 and previous[0] > 0:
                    brackets.append((previous[0], previous[0]))
                elif previous[1] * f < 0:
                    brackets.append((previous[0], float(omega)))
            previous = (float(omega), float(f))
            if len(brackets) == count:
                break
    return brackets, evaluations


def available_modes(model, bc):
    """
    Number of natural frequencies of a lumped model: masses whose deflection is free.

    Returns
    -------
    int

    """
    eps = 1e-12 * model.length
    # every boundary condition of Eq. 3 pins the left end; all but the cantilever the right
    pinned = model.positions <= eps
    if bc != 'cantilever':
        pinned = pinned | (model.positions >= model.length - eps)
    return int(np.sum(~pinned & (model.masses > 0)))


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
    """DOFs (v, phi per node) left free by the boundary condition, ndarray of int."""
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
    Euler-Bernoulli beam under point loads, core/beam.py bending part) join nodes at the ends
    and at every mass. With S = diag(sqrt(m)) on the translations that carry mass, the
    frequencies are 1/sqrt(mu) for the eigenvalues mu of S K^-1 S (flexibility form, the
    rotations and massless translations condensed exactly by the solve with K). Small models
    use :func:`scipy.linalg.eigh`, larger ones sparse LU and ARPACK.

    Parameters
    ----------
    model : LumpedBeam
    bc : str
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


@dataclasses.dataclass(frozen=True)
class TmmResult:
    """
    Lowest natural frequencies by the transfer-matrix method.

    Attributes
    ----------
    frequencies_rad_s : ndarray, shape (modes,)
    roots : tuple of RootResult
        Per mode: iterations, paper-criterion iterations, bracket, iterate history.
    scan_evaluations : int
        Determinants evaluated by the incremental scan.

    """

    frequencies_rad_s: np.ndarray
    roots: tuple
    scan_evaluations: int

    @property
    def iterations(self):
        """Refinement iterations per mode, list of int."""
        return [root.iterations for root in self.roots]


def tmm_frequencies(beam, bc, segments, method=3, modes=3, search='false-position',
                    step=DEFAULT_STEP_RAD_S, rtol=DEFAULT_RTOL, dtol=DEFAULT_DTOL,
                    verify=True, illinois=True):
    """
    Lowest `modes` natural frequencies of a lumped beam by transfer matrices (Eqs. 2-7).

    Parameters
    ----------
    beam : UniformBeam
    bc : str
        One of :data:`BOUNDARY_CONDITIONS`.
    segments : int
        Number of equal segments.
    method : int
        Mass-lumping method 1, 2 or 3.
    modes : int
        How many frequencies, at most :func:`available_modes`.
    search : str
        'bisection', 'false-position' or 'newton'.
    step : float
        Scan increment d_omega [rad/s].
    rtol, dtol : float
        Tolerances of :func:`refine_root`.
    illinois : bool
        Illinois-modified false position (False: the paper's plain Eq. 6).
    verify : bool
        Check with :func:`lumped_frequencies` that the scan skipped no root (two roots
        within one step); raises FlexlinkError naming a smaller step if it did.

    Returns
    -------
    TmmResult

    """
    check_boundary_condition(bc)
    model = lump_masses(beam, segments, method, bc)
    limit = available_modes(model, bc)
    if isinstance(modes, bool) or not isinstance(modes, (int, np.integer)) or modes < 1:
        raise ValueError(f'`modes` must be a positive integer, got {modes!r}')
    if modes > limit:
        raise ValueError(f'`modes` = {modes} exceeds the {limit} modes of {segments} segments '
                         f'with lumping method {method} ({bc})')
    if search not in SEARCHES:
        raise ValueError(f'`search` must be one of {", ".join(SEARCHES)}, got {search!r}')
    brackets, evaluations = scan_brackets(model, bc, modes, step)
    scale = determinant_to_kgf_mm(bc)
    roots = tuple(
        RootResult(a, 0, 0, (a, b), ()) if a == b else
        refine_root(model, bc, (a, b), search, rtol, dtol, paper_scale=scale,
                    illinois=illinois)
        for a, b in brackets)
    frequencies = np.array([root.frequency_rad_s for root in roots])
    if verify:
        reference = lumped_frequencies(model, bc, modes)
        # loose on purpose: beam modes are far apart, and the stiffness-based reference
        # loses ~eps (L/h)^4 to round-off on fine models while the transfer matrices do not
        mismatch = np.abs(frequencies - reference) > VERIFY_RTOL * reference
        if np.any(mismatch):
            k = int(np.argmax(mismatch))
            raise FlexlinkError(
                f'the scan with step {step:g} rad/s skipped a root below {frequencies[k]:.6g} '
                f'rad/s (mode {k + 1} is {reference[k]:.6g} rad/s); use a smaller step')
    return TmmResult(frequencies_rad_s=frequencies, roots=roots, scan_evaluations=evaluations)


def fe_frequencies(beam, bc, elements, modes=3):
    """
    Lowest natural frequencies by cubic beam finite elements with consistent mass.

    Bending part (DOFs v, phi) of :func:`flexlink_ros.core.fe.beam.beam_stiffness` and
    :func:`flexlink_ros.core.fe.beam.beam_mass` (Cho 1992, Eqs. A.3 and A.6), solved by
    :func:`scipy.linalg.eigh`. Frequency error falls like h^4.

    Parameters
    ----------
    beam : UniformBeam
    bc : str
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
    stiffness = _assemble_bending(
        np.full(n, h),
        lambda h: beam_element.beam_stiffness(beam.E, 1.0, beam.I, h)[np.ix_(_BENDING,
                                                                             _BENDING)])
    mass = _assemble_bending(
        np.full(n, h),
        lambda h: beam_element.beam_mass(beam.mass_per_length, 1.0, h)[np.ix_(_BENDING,
                                                                               _BENDING)])
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


# Characteristic equations of the continuous beam, written to stay bounded for large beta L,
# with the approximate location of root k (k = 1, 2, ...).
_CHARACTERISTIC = {
    'fixed-fixed': (lambda x: np.cos(x) - 1.0 / np.cosh(x), lambda k: (k + 0.5) * np.pi),
    'fixed-supported': (lambda x: np.sin(x) - np.cos(x) * np.tanh(x),
                        lambda k: (k + 0.25) * np.pi),
    'cantilever': (lambda x: np.cos(x) + 1.0 / np.cosh(x), lambda k: (k - 0.5) * np.pi),
    'supported': (lambda x: np.sin(x), lambda k: k * np.pi),
}


def exact_beta_l(bc, modes=3):
    """
    Roots beta L of the Euler-Bernoulli characteristic equation for boundary condition `bc`.

    cos(bL) cosh(bL) = 1 (fixed-fixed), tan(bL) = tanh(bL) (fixed-supported),
    cos(bL) cosh(bL) = -1 (cantilever), sin(bL) = 0 (supported).

    Returns
    -------
    ndarray, shape (modes,)

    """
    check_boundary_condition(bc)
    equation, guess = _CHARACTERISTIC[bc]
    roots = [brentq(equation, guess(k) - 0.4, guess(k) + 0.4, xtol=1e-15, rtol=1e-15)
             for k in range(1, modes + 1)]
    return np.array(roots)


def exact_frequencies(beam, bc, modes=3):
    """
    Exact Euler-Bernoulli frequencies (beta L)^2 sqrt(EI / (m L^4)) [rad/s].

    Returns
    -------
    ndarray, shape (modes,)

    """
    scale = math.sqrt(beam.flexural_rigidity / (beam.mass_per_length * beam.length ** 4))
    return exact_beta_l(bc, modes) ** 2 * scale
