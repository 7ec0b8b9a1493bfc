"""
Mechanism definition: geometry, sections, material, joint masses, bearings, options.

A :class:`Mechanism` is a frozen dataclass, read from a YAML file (SI units) by
core/mechanism_file.py; variants are made with ``dataclasses.replace``. The checks here hold
for every mechanism, however made: ``elements_per_link`` within
1..:data:`MAX_ELEMENTS_PER_LINK` (so ``--elements`` is bounded as well) and a Grashof
crank-rocker (:func:`check_crank_rocker`). Each refusal is a :class:`MechanismError` naming
the field and the bound.

Conventions (DEVELOPERS.md): O2 at the origin, O4 at (+ground length, 0); crank angle
counter-clockwise from O2->O4; open branch = B to the left of A->O4 (above the ground line).
Links are indexed 0 = crank (O2->A), 1 = coupler (A->B), 2 = lever (O4->B); each link's
moving x axis runs from its first joint to its second. Joints are O2 (ground-crank),
A (crank-coupler), B (coupler-lever), O4 (lever-ground).
"""

import dataclasses
import hashlib
import json
import math
import re
from typing import Optional

from ..errors import MechanismError
from ..names import JOINT_NAMES

# The two members of each joint, first then second (-1 is the ground).
JOINT_MEMBERS = {'O2': (-1, 0), 'A': (0, 1), 'B': (1, 2), 'O4': (2, -1)}
BRANCHES = ('open', 'crossed')

# Bound on the models' size any mechanism (a file or a variant) can ask for.
# Beam elements per link: the node allows 0..40 and the estimator's reference model doubles
# the file's count; 80 gives about 730 DOFs (4.3 MB per dense matrix), 10^6 asked 589 TiB.
MAX_ELEMENTS_PER_LINK = 80


@dataclasses.dataclass(frozen=True)
class Link:
    """
    One moving link, uniform along its length.

    Parameters
    ----------
    length : float
        Pin-to-pin length L [m].
    mass : float
        Mass of the link body [kg] (joint masses are separate).
    inertia : float
        Mass moment of inertia about the centre of mass [kg m^2].
    area : float or None
        Cross-section area A [m^2]; needed by the flexible model.
    second_moment : float or None
        Second moment of area I [m^4]; needed by the flexible model.

    """

    length: float
    mass: float
    inertia: float
    area: Optional[float] = None
    second_moment: Optional[float] = None


@dataclasses.dataclass(frozen=True)
class Spring:
    """Coil spring between coupler and lever, T = K (theta_ij - theta0) (Kang 1990, Eq. 1)."""

    stiffness: float
    theta0: float


@dataclasses.dataclass(frozen=True)
class Mechanism:
    """
    A crank-rocker four-bar linkage and the options of its flexible model.

    Parameters
    ----------
    name : str
        Short name (used in cache keys and reports).
    ground_length : float
        Distance O2-O4 [m].
    links : tuple of Link
        Crank, coupler, lever.
    youngs_modulus, density : float or None
        E [Pa] and rho [kg/m^3] of the links (flexible model only).
    joint_masses : dict
        Lumped masses [kg] at joints O2, A, B, O4.
    bearing_stiffness : float or None
        Isotropic bearing spring k [N/m] (Cho 1992, Eq. 23); None for rigid bearings.
    bearing_joints : tuple of str
        Joints carrying the bearing spring when bearings are flexible.
    joint_mass_split : float
        Fraction of a joint mass carried by the joint's first member (ground for O2, crank
        for A, coupler for B, lever for O4); the rest goes to the second member.
    shaft_stiffness : float or None
        Input-shaft torsional stiffness k_t [N m/rad]; None = clamped shaft.
    gravity : tuple of float
        Gravity acceleration (gx, gy) in the ground frame [m/s^2].
    damping_ratio : float
        Modal damping ratio zeta of every frozen mode.
    elements_per_link : int
        Beam elements per link in the flexible model.
    branch : str
        'open' (B to the left of A->O4) or 'crossed'.
    spring : Spring or None
        Optional coil spring between coupler and lever.
    crank_speed : float or None
        Nominal crank speed [rad/s] stated by the source, if any.
    source : str
        Where the data come from.

    """

    name: str
    ground_length: float
    links: tuple
    youngs_modulus: Optional[float] = None
    density: Optional[float] = None
    joint_masses: dict = dataclasses.field(
        default_factory=lambda: dict.fromkeys(JOINT_NAMES, 0.0))
    bearing_stiffness: Optional[float] = None
    bearing_joints: tuple = JOINT_NAMES
    joint_mass_split: float = 0.5
    shaft_stiffness: Optional[float] = None
    gravity: tuple = (0.0, 0.0)
    damping_ratio: float = 0.02
    elements_per_link: int = 3
    branch: str = 'open'
    spring: Optional[Spring] = None
    crank_speed: Optional[float] = None
    source: str = ''

    def __post_init__(self):
        """Bound the sizes every model allocates from (also after ``dataclasses.replace``)."""
        check_elements_per_link(self.elements_per_link)

    @property
    def lengths(self):
        """Ground, crank, coupler and lever lengths [m], in that order."""
        return (self.ground_length,) + tuple(link.length for link in self.links)

    @property
    def is_flexible(self):
        """Tell whether the data needed by the flexible (FE) model are present."""
        return (self.youngs_modulus is not None and self.density is not None
                and all(link.area is not None and link.second_moment is not None
                        for link in self.links))

    def key(self):
        """Stable hash of every field, for cache keys (hex string)."""
        payload = json.dumps(dataclasses.asdict(self), sort_keys=True, default=repr)
        return hashlib.sha256(payload.encode()).hexdigest()


# A mechanism's name is part of cache file names: letters, digits, _ . - only, no leading dot
# (so that no path can be spelt with it).
NAME_PATTERN = re.compile(r'[A-Za-z0-9_-][A-Za-z0-9_.-]*')


def check_name(name):
    """Return ``name`` if it matches NAME_PATTERN, else raise MechanismError naming `name`."""
    if not NAME_PATTERN.fullmatch(name):
        raise MechanismError('name', f'{name!r:.80} is not a plain name (letters, digits, '
                             '_ . - only, not starting with a dot)')
    return name


def check_elements_per_link(elements):
    """Raise MechanismError unless ``elements`` is an integer in 1..MAX_ELEMENTS_PER_LINK."""
    if (isinstance(elements, bool) or not isinstance(elements, int)
            or not 1 <= elements <= MAX_ELEMENTS_PER_LINK):
        raise MechanismError('elements_per_link', f'expected an integer in '
                             f'1..{MAX_ELEMENTS_PER_LINK}, got {elements!r:.40}')


# What a Grashof linkage is when this link, not the crank, is the shortest.
GRASHOF_KINDS = {
    'ground': 'a double crank (drag link), crank and lever both turn fully',
    'coupler': 'a double rocker, crank and lever only rock',
    'lever': 'a rocker-crank, the lever turns fully and the crank only rocks (swap the two)'}


def check_crank_rocker(ground, crank, coupler, lever):
    """
    Raise MechanismError unless the four lengths make a Grashof crank-rocker.

    The crank must be the shortest link and s + l < p + q (Grashof); equality is a
    change-point linkage whose links fold flat, which the models cannot follow.
    """
    lengths = {'ground': ground, 'crank': crank, 'coupler': coupler, 'lever': lever}
    shortest = min(lengths.values())
    longest = max(lengths.values())
    total = sum(lengths.values())
    s_plus_l = shortest + longest
    p_plus_q = total - s_plus_l
    if crank > shortest:
        name = min(lengths, key=lengths.get)
        kind = GRASHOF_KINDS[name] if s_plus_l <= p_plus_q else 'no link turns fully'
        raise MechanismError(
            'links', f'not a crank-rocker: the {name} ({shortest:g} m) is shorter than the '
            f'crank ({crank:g} m): {kind}')
    if s_plus_l > p_plus_q:
        raise MechanismError(
            'links', f'not a crank-rocker: Grashof condition s + l <= p + q fails '
            f'({s_plus_l:g} > {p_plus_q:g} m): no link fully rotates')
    if math.isclose(s_plus_l, p_plus_q, rel_tol=1e-12):
        raise MechanismError(
            'links', f'change-point linkage: s + l = p + q = {s_plus_l:g} m, the links fold '
            'flat and the branch is undefined there')


# Re-exports for importers not yet moved; at the end: core/mechanism_file.py imports this module.
