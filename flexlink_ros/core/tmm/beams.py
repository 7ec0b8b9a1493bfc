"""
Beams of Kim & Moon: the uniform Euler-Bernoulli beam and its lumped-mass models.

A :class:`UniformBeam` (SI units; :meth:`UniformBeam.kim_moon` is the paper's Table 1 beam) is
turned into point masses on a massless beam of constant EI (:class:`LumpedBeam`) by one of the
paper's mass-lumping methods 1-3 (:func:`lump_masses`).
"""

import dataclasses
import math

import numpy as np

# Standard gravity [m/s^2]: kgf -> N for forces and Young's modulus.
STANDARD_GRAVITY = 9.80665
# Gravity [m/s^2] the paper's exact values imply for mass = specific weight / g (papers.md).
KIM_MOON_GRAVITY = 9.807

BOUNDARY_CONDITIONS = ('fixed-fixed', 'fixed-supported', 'cantilever', 'supported')
LUMPING_METHODS = (1, 2, 3)


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
        Return the uniform beam of Kim & Moon, Table 1, converted to SI.

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
        The uniform beam.
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
