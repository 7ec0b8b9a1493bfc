"""
Checks of a mechanism file beyond its schema: keys as the loader spells them, numbers in SI.

A file with a misspelt key is refused with the closest key the loader knows (difflib). A file
whose numbers are off by orders of magnitude (lengths in mm, sections in mm^2 and mm^4, a
modulus in MPa, a density in g/cm^3, joint masses in g) gives wrong numbers without a word
if it is accepted, so :func:`check_plausible` refuses it with one line that names the file's
own key, its value and the likely cause, for example
``links.coupler.length_m = 250: metres expected, was this mm?``.

The bounds are wide (a linkage from a few millimetres to several metres, rubber to diamond,
foam to tungsten): they catch a slip of units, not an unusual machine.
"""

import difflib
import math

from ..errors import MechanismError
from ..names import JOINT_NAMES, LINK_NAMES

LENGTH_M = (1e-3, 10.0)             # link and ground lengths [m]
YOUNGS_PA = (1e6, 1.5e12)           # rubber-like plastics .. diamond [Pa]
DENSITY_KG_M3 = (50.0, 25000.0)     # foam .. beyond tungsten and osmium [kg/m^3]
# I / A^2 of a real section: a flat strip 1 x 800 bent through its thickness (1e-4) .. a
# thin-walled tube or I-beam (R/t = 600 gives 50): a section in mm^4 over m^2 is 1e12 off.
SHAPE_FACTOR = (1e-4, 50.0)
# Radius of gyration sqrt(I/A) over the link's length: a beam is slender (1/L below 0.3); in
# mm^2 and mm^4 with lengths in m it is 1000 times too large.
GYRATION_OVER_LENGTH_MAX = 0.3
BEARING_N_M = (1e2, 1e12)           # a soft rubber bush .. far stiffer than any bearing [N/m]
SHAFT_NM_RAD = (1e-2, 1e9)          # [N m/rad]
GRAVITY_M_S2_MAX = 100.0            # 10 g; 9810 is mm/s^2
# A pin heavier than this many times all three links together is a mass in grams.
JOINT_MASS_OVER_LINKS_MAX = 20.0
# A given link inertia against the slender rod's m L^2 / 12 (kg mm^2 is 1e6 off).
INERTIA_RATIO = (1e-2, 1e2)
MAX_CRANK_RPM = 1e5


def _refuse(key, value, reason):
    raise MechanismError(f'{key} = {value:g}', reason)


def check_keys(mapping, allowed, where):
    """
    Refuse a key the loader does not know, naming the closest one it does.

    Parameters
    ----------
    mapping : object
        The section as parsed (refused unless a mapping).
    allowed : set of str
        The keys the section takes.
    where : str
        The section's dotted name ('' at the top level).

    """
    if not isinstance(mapping, dict):
        raise MechanismError(where, f'expected a mapping, got {type(mapping).__name__}')
    unknown = sorted((str(key) for key in set(mapping) - allowed), key=str)
    if unknown:
        close = difflib.get_close_matches(unknown[0], sorted(allowed), n=1, cutoff=0.6)
        hint = f'did you mean {close[0]!r}? ' if close else ''
        raise MechanismError(f'{where}.{unknown[0]}' if where else unknown[0],
                             f'unknown key ({hint}allowed: {", ".join(sorted(allowed))})')


def _check_length(key, value):
    if value > LENGTH_M[1]:
        unit = 'mm' if value / 1000.0 <= LENGTH_M[1] else 'not metres'
        _refuse(key, value, f'metres expected, was this {unit}?')
    if value < LENGTH_M[0]:
        _refuse(key, value, f'metres expected, a link shorter than {LENGTH_M[0] * 1e3:g} mm '
                'is not a linkage the beam model holds')


def _check_section(where, length, area, second):
    """Check the section of one link: its shape factor I/A^2 and radius of gyration."""
    shape = second / area ** 2
    gyration = math.sqrt(second / area)
    if shape > SHAPE_FACTOR[1]:
        _refuse(f'{where}.second_moment_m4', second, f'I/A^2 = {shape:.3g} against area_m2 = '
                f'{area:g}, no real section has it: m^4 expected, was this mm^4?')
    if shape < SHAPE_FACTOR[0]:
        _refuse(f'{where}.area_m2', area, f'I/A^2 = {shape:.3g} against second_moment_m4 = '
                f'{second:g}, no real section has it: m^2 expected, was this mm^2?')
    if gyration > GYRATION_OVER_LENGTH_MAX * length:
        _refuse(f'{where}.second_moment_m4', second, f'radius of gyration sqrt(I/A) = '
                f'{gyration:.3g} m against length_m = {length:g}: not a slender link; were '
                'area_m2 and second_moment_m4 given in mm^2 and mm^4?')


def _check_material(mechanism):
    youngs, density = mechanism.youngs_modulus, mechanism.density
    if youngs is not None and not YOUNGS_PA[0] <= youngs <= YOUNGS_PA[1]:
        cause = ('was this MPa or GPa (steel: 2.1e11 Pa = 210000 MPa = 210 GPa)?'
                 if youngs < YOUNGS_PA[0] else 'beyond any solid')
        _refuse('material.youngs_modulus_pa', youngs, f'Pa expected, {cause}')
    if density is not None and not DENSITY_KG_M3[0] <= density <= DENSITY_KG_M3[1]:
        cause = ('was this g/cm^3 (steel: 7.85 g/cm^3 = 7850 kg/m^3)?'
                 if density < DENSITY_KG_M3[0] else 'beyond any solid')
        _refuse('material.density_kg_m3', density, f'kg/m^3 expected, {cause}')


def check_lengths(ground, lengths):
    """Refuse a ground or link length off by orders of magnitude (before the Grashof sums)."""
    _check_length('ground_length_m', ground)
    for name, length in zip(LINK_NAMES, lengths):
        _check_length(f'links.{name}.length_m', length)


def _check_links(mechanism):
    check_lengths(mechanism.ground_length, [link.length for link in mechanism.links])
    for name, link in zip(LINK_NAMES, mechanism.links):
        where = f'links.{name}'
        if link.area is not None and link.second_moment is not None:
            _check_section(where, link.length, link.area, link.second_moment)
        rod = link.mass * link.length ** 2 / 12.0
        if rod > 0.0 and not INERTIA_RATIO[0] <= link.inertia / rod <= INERTIA_RATIO[1]:
            _refuse(f'{where}.inertia_kg_m2', link.inertia, f'{link.inertia / rod:.3g} times '
                    "a uniform rod's m L^2/12: kg m^2 expected, was this kg mm^2 or g?")


def _check_joints_and_bearings(mechanism):
    links_mass = sum(link.mass for link in mechanism.links)
    for joint in JOINT_NAMES:
        mass = mechanism.joint_masses.get(joint, 0.0)
        if links_mass > 0.0 and mass > JOINT_MASS_OVER_LINKS_MAX * links_mass:
            _refuse(f'joint_masses_kg.{joint}', mass, f'{mass / links_mass:.3g} times the '
                    f'three links together ({links_mass:.3g} kg): kg expected, was this g?')
    k = mechanism.bearing_stiffness
    if k is not None and not BEARING_N_M[0] <= k <= BEARING_N_M[1]:
        cause = ('was this kN/m or N/um?' if k < BEARING_N_M[0] else
                 'stiffer than any bearing: leave bearings rigid instead')
        _refuse('bearings.stiffness_n_m', k, f'N/m expected (ball bearings: 1e7 to 1e9), '
                f'{cause}')
    shaft = mechanism.shaft_stiffness
    if shaft is not None and not SHAFT_NM_RAD[0] <= shaft <= SHAFT_NM_RAD[1]:
        _refuse('input_shaft.torsional_stiffness_nm_rad', shaft,
                'N m/rad expected, was this N mm/rad?')


def check_plausible(mechanism):
    """
    Refuse a mechanism whose numbers are off by orders of magnitude (a slip of units).

    Parameters
    ----------
    mechanism : Mechanism
        As read from a file (the messages name the file's keys).

    Raises
    ------
    MechanismError
        ``<file key> = <value>: <unit expected>, <likely cause>``.

    """
    _check_links(mechanism)
    _check_material(mechanism)
    _check_joints_and_bearings(mechanism)
    gravity = math.hypot(*mechanism.gravity)
    if gravity > GRAVITY_M_S2_MAX:
        _refuse('gravity_m_s2', gravity, 'm/s^2 expected (9.81), was this mm/s^2?')
    if mechanism.crank_speed is not None and \
            abs(mechanism.crank_speed) * 30.0 / math.pi > MAX_CRANK_RPM:
        _refuse('crank_speed_rpm', mechanism.crank_speed * 30.0 / math.pi,
                'rpm expected, a crank beyond 100000 rpm is no linkage')


def check_first_frequency(first_hz, crank_angle, crank_speed=0.0):
    """
    Refuse a frozen structure whose first natural frequency is not positive.

    Parameters
    ----------
    first_hz : float
        The lowest frozen frequency [Hz] (0 where the eigenvalue was not positive).
    crank_angle : float
        Where [rad].
    crank_speed : float
        At which crank speed [rad/s] (the axial forces' geometric stiffness grows with it).

    """
    if first_hz > 0.0:
        return
    where = f'at crank angle {math.degrees(crank_angle):.1f} deg'
    if crank_speed:
        raise MechanismError(
            'mechanism', f'the first frozen frequency {where} and '
            f'{crank_speed * 30 / math.pi:.0f} rpm is {first_hz:g} Hz: the links buckle under '
            'their axial forces at that speed; '
            'lower the speed range (crank_speed_rpm, model.speed_max_rpm, --rpm-max)')
    raise MechanismError(
        'mechanism', f'the first frozen frequency {where} is {first_hz:g} Hz, not positive: '
        'the frozen structure has no stiffness there (SI units expected: lengths in m, '
        'sections in m^2 and m^4, E in Pa, bearing stiffness in N/m)')
