"""
Mechanism definition: geometry, sections, material, joint masses, bearings, options.

A :class:`Mechanism` is a frozen dataclass built from a YAML file (SI units) by
:func:`load_mechanism`, which rejects unknown keys, non-positive sizes and linkages that are
not the crank-rocker the models assume. Variants are made with ``dataclasses.replace``.

A mechanism file is small and plain, so the loader bounds what a hostile one could ask for:
at most :data:`MAX_FILE_BYTES`, no YAML anchors or aliases (an alias bomb of 1.5 kB expands to
gigabytes), nesting at most :data:`MAX_YAML_DEPTH` deep, strings at most
:data:`MAX_NAME_CHARS` / :data:`MAX_SOURCE_CHARS` long, and ``elements_per_link`` within
1..:data:`MAX_ELEMENTS_PER_LINK` (checked by the dataclass too, so ``dataclasses.replace`` and
``--elements`` are bounded as well). Each refusal is a :class:`MechanismError` naming the
field and the bound.

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
import pathlib
import sys
from typing import Optional

import yaml

from ..names import JOINT_NAMES, LINK_NAMES
from ..errors import MechanismError

# The two members of each joint, first then second (-1 is the ground).
JOINT_MEMBERS = {'O2': (-1, 0), 'A': (0, 1), 'B': (1, 2), 'O4': (2, -1)}
BRANCHES = ('open', 'crossed')

# Bounds on what a mechanism file (or a variant) can set; the README states them.
MAX_FILE_BYTES = 64 * 1024  # the shipped files are about 1.5 kB
MAX_YAML_DEPTH = 8  # the schema nests 3 deep (links.crank.length_m)
MAX_NAME_CHARS = 128
MAX_SOURCE_CHARS = 4096
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
        default_factory=lambda: {name: 0.0 for name in JOINT_NAMES})
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
        """True if the data needed by the flexible (FE) model are present."""
        return (self.youngs_modulus is not None and self.density is not None
                and all(link.area is not None and link.second_moment is not None
                        for link in self.links))

    def key(self):
        """Stable hash of every field, for cache keys (hex string)."""
        payload = json.dumps(dataclasses.asdict(self), sort_keys=True, default=repr)
        return hashlib.sha256(payload.encode()).hexdigest()


def check_elements_per_link(elements):
    """Raise MechanismError unless ``elements`` is an integer in 1..MAX_ELEMENTS_PER_LINK."""
    if (isinstance(elements, bool) or not isinstance(elements, int)
            or not 1 <= elements <= MAX_ELEMENTS_PER_LINK):
        raise MechanismError('elements_per_link', f'expected an integer in '
                             f'1..{MAX_ELEMENTS_PER_LINK}, got {elements!r:.40}')


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
    if crank > shortest:
        name = min(lengths, key=lengths.get)
        raise MechanismError(
            'links', f'not a crank-rocker: the {name} ({shortest:g} m) is shorter than the '
            f'crank ({crank:g} m), so the crank cannot fully rotate')
    s_plus_l = shortest + longest
    p_plus_q = total - s_plus_l
    if s_plus_l > p_plus_q:
        raise MechanismError(
            'links', f'not a crank-rocker: Grashof condition s + l <= p + q fails '
            f'({s_plus_l:g} > {p_plus_q:g} m): no link fully rotates')
    if math.isclose(s_plus_l, p_plus_q, rel_tol=1e-12):
        raise MechanismError(
            'links', f'change-point linkage: s + l = p + q = {s_plus_l:g} m, the links fold '
            'flat and the branch is undefined there')


# ---------------------------------------------------------------------------------------
# YAML loading

_TOP_KEYS = {'name', 'source', 'ground_length_m', 'material', 'links', 'joint_masses_kg',
             'bearings', 'input_shaft', 'gravity_m_s2', 'damping_ratio',
             'elements_per_link', 'branch', 'spring', 'crank_speed_rpm'}
_LINK_KEYS = {'length_m', 'mass_kg', 'inertia_kg_m2', 'area_m2', 'second_moment_m4'}
_MATERIAL_KEYS = {'youngs_modulus_pa', 'density_kg_m3'}
_BEARING_KEYS = {'stiffness_n_m', 'joints', 'mass_split'}
_SHAFT_KEYS = {'torsional_stiffness_nm_rad'}
_SPRING_KEYS = {'stiffness_nm_rad', 'theta0_deg'}


def _check_keys(mapping, allowed, where):
    if not isinstance(mapping, dict):
        raise MechanismError(where, f'expected a mapping, got {type(mapping).__name__}')
    unknown = sorted((str(key) for key in set(mapping) - allowed), key=str)
    if unknown:
        raise MechanismError(f'{where}.{unknown[0]}' if where else unknown[0],
                             f'unknown key (allowed: {", ".join(sorted(allowed))})')


def _as_float(value, field):
    try:
        return float(value)
    except OverflowError:  # an integer of hundreds of digits
        raise MechanismError(field, 'number out of range') from None


def _text(data, key, default, limit):
    value = data.get(key, default)
    if value is None:
        value = default
    if isinstance(value, (dict, list)):
        raise MechanismError(key, f'expected text, got a {type(value).__name__}')
    value = str(value)
    if len(value) > limit:
        raise MechanismError(key, f'{len(value)} characters, at most {limit} allowed')
    return value


def _number(mapping, key, where, positive=True, required=True, default=None,
            minimum=None, maximum=None):
    field = f'{where}.{key}' if where else key
    if key not in mapping or mapping[key] is None:
        if required:
            raise MechanismError(field, 'missing')
        return default
    value = mapping[key]
    if isinstance(value, str):
        # PyYAML (YAML 1.1) reads exponents without a dot or sign, like 2.19e11, as strings.
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MechanismError(field, f'expected a number, got {value!r:.40}')
    value = _as_float(value, field)
    if not math.isfinite(value):
        raise MechanismError(field, f'must be finite, got {value!r}')
    if positive and value <= 0.0:
        raise MechanismError(field, f'must be positive, got {value:g}')
    if minimum is not None and value < minimum:
        raise MechanismError(field, f'must be >= {minimum:g}, got {value:g}')
    if maximum is not None and value > maximum:
        raise MechanismError(field, f'must be <= {maximum:g}, got {value:g}')
    return value


def mechanism_from_dict(data):
    """
    Build and validate a Mechanism from a plain mapping (the YAML schema, SI units).

    Raises
    ------
    MechanismError
        Naming the field: unknown keys, missing or non-positive values, a linkage that is not
        a crank-rocker.

    """
    _check_keys(data, _TOP_KEYS, '')
    name = _text(data, 'name', 'mechanism', MAX_NAME_CHARS)
    source = _text(data, 'source', '', MAX_SOURCE_CHARS)
    ground = _number(data, 'ground_length_m', '')

    material = data.get('material') or {}
    _check_keys(material, _MATERIAL_KEYS, 'material')
    youngs = _number(material, 'youngs_modulus_pa', 'material', required=False)
    density = _number(material, 'density_kg_m3', 'material', required=False)

    links_data = data.get('links')
    if links_data is None:
        raise MechanismError('links', 'missing')
    _check_keys(links_data, set(LINK_NAMES), 'links')
    links = []
    for link_name in LINK_NAMES:
        where = f'links.{link_name}'
        entry = links_data.get(link_name)
        if entry is None:
            raise MechanismError(where, 'missing')
        _check_keys(entry, _LINK_KEYS, where)
        length = _number(entry, 'length_m', where)
        area = _number(entry, 'area_m2', where, required=False)
        second = _number(entry, 'second_moment_m4', where, required=False)
        mass = _number(entry, 'mass_kg', where, required=False)
        if mass is None:
            if area is None or density is None:
                raise MechanismError(f'{where}.mass_kg',
                                     'missing (give mass_kg, or area_m2 and material density)')
            mass = density * area * length
        elif area is not None and density is not None:
            raise MechanismError(f'{where}.mass_kg',
                                 'give either mass_kg or area_m2 with a density, not both')
        inertia = _number(entry, 'inertia_kg_m2', where, required=False,
                          default=mass * length ** 2 / 12.0)  # slender uniform rod
        links.append(Link(length=length, mass=mass, inertia=inertia, area=area,
                          second_moment=second))
    check_crank_rocker(ground, *(link.length for link in links))

    masses_data = data.get('joint_masses_kg') or {}
    _check_keys(masses_data, set(JOINT_NAMES), 'joint_masses_kg')
    joint_masses = {j: _number(masses_data, j, 'joint_masses_kg', positive=False,
                               required=False, default=0.0, minimum=0.0) for j in JOINT_NAMES}

    bearings = data.get('bearings') or {}
    _check_keys(bearings, _BEARING_KEYS, 'bearings')
    bearing_k = _number(bearings, 'stiffness_n_m', 'bearings', required=False)
    bearing_joints = bearings.get('joints', JOINT_NAMES)
    if not isinstance(bearing_joints, (list, tuple)):
        raise MechanismError('bearings.joints', f'expected a list of joints, got '
                             f'{type(bearing_joints).__name__}')
    bearing_joints = tuple(bearing_joints)
    for joint in bearing_joints:
        if not isinstance(joint, str) or joint not in JOINT_NAMES:
            raise MechanismError('bearings.joints', f'unknown joint {joint!r:.40} '
                                 f'(joints: {", ".join(JOINT_NAMES)})')
    if len(set(bearing_joints)) != len(bearing_joints):
        raise MechanismError('bearings.joints', 'a joint is listed twice')
    split = _number(bearings, 'mass_split', 'bearings', positive=False, required=False,
                    default=0.5, minimum=0.0, maximum=1.0)

    shaft = data.get('input_shaft') or {}
    _check_keys(shaft, _SHAFT_KEYS, 'input_shaft')
    shaft_k = _number(shaft, 'torsional_stiffness_nm_rad', 'input_shaft', required=False)

    gravity = data.get('gravity_m_s2', [0.0, 0.0])
    if (not isinstance(gravity, (list, tuple)) or len(gravity) != 2
            or not all(isinstance(g, (int, float)) and not isinstance(g, bool)
                       and math.isfinite(_as_float(g, 'gravity_m_s2')) for g in gravity)):
        raise MechanismError('gravity_m_s2', f'expected [gx, gy] in m/s^2, got {gravity!r:.60}')

    zeta = _number(data, 'damping_ratio', '', positive=False, required=False, default=0.02,
                   minimum=0.0, maximum=1.0)
    elements = data.get('elements_per_link', 3)
    check_elements_per_link(elements)
    branch = data.get('branch', 'open')
    if not isinstance(branch, str) or branch not in BRANCHES:
        raise MechanismError('branch', f'expected one of {BRANCHES}, got {branch!r:.40}')

    spring = None
    if data.get('spring') is not None:
        spring_data = data['spring']
        _check_keys(spring_data, _SPRING_KEYS, 'spring')
        spring = Spring(
            stiffness=_number(spring_data, 'stiffness_nm_rad', 'spring', positive=False,
                              minimum=0.0),
            theta0=math.radians(_number(spring_data, 'theta0_deg', 'spring', positive=False)))
    rpm = _number(data, 'crank_speed_rpm', '', required=False)

    return Mechanism(
        name=name, ground_length=ground, links=tuple(links), youngs_modulus=youngs,
        density=density, joint_masses=joint_masses, bearing_stiffness=bearing_k,
        bearing_joints=bearing_joints, joint_mass_split=split, shaft_stiffness=shaft_k,
        gravity=(float(gravity[0]), float(gravity[1])), damping_ratio=zeta,
        elements_per_link=elements, branch=branch, spring=spring,
        crank_speed=None if rpm is None else rpm * 2.0 * math.pi / 60.0,
        source=source)


def find_config(name):
    """
    Resolve a mechanism or parameter file: a path, or a bare name like 'cho1992'.

    Bare names are looked up in the installed share directory (ament index, then the
    install prefix of this Python, where ``pip install .`` puts it) and then in the source
    tree's ``config/``.
    """
    path = pathlib.Path(name)
    if path.exists():
        return path
    stem = name if name.endswith('.yaml') else name + '.yaml'
    candidates = [pathlib.Path(sys.prefix) / 'share' / 'flexlink_ros' / 'config' / stem,
                  pathlib.Path(__file__).resolve().parents[2] / 'config' / stem]
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.insert(0, pathlib.Path(get_package_share_directory('flexlink_ros'))
                          / 'config' / stem)
    except Exception:  # noqa: BLE001 - no ament index: fall back to the prefix and source tree
        pass
    for candidate in candidates:
        if candidate.exists():
            return candidate
    looked = ', '.join(str(c.parent) for c in candidates)
    raise MechanismError('mechanism', f'no such file: {name} (looked in {looked})')


class _PlainLoader(yaml.SafeLoader):
    """
    SafeLoader for mechanism files: no anchors or aliases, nesting at most MAX_YAML_DEPTH.

    Aliases are refused where they are parsed, before anything is expanded, so an alias
    bomb costs its own size; the depth bound keeps the recursive composer off Python's
    recursion limit.
    """

    def compose_node(self, parent, index):
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent) or getattr(event, 'anchor', None) is not None:
            raise MechanismError('yaml', f'anchors and aliases are not allowed (line '
                                 f'{event.start_mark.line + 1})')
        self._depth = getattr(self, '_depth', 0) + 1
        try:
            if self._depth > MAX_YAML_DEPTH:
                raise MechanismError('yaml', f'nested deeper than {MAX_YAML_DEPTH} levels '
                                     f'(line {event.start_mark.line + 1})')
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


def read_yaml_bounded(path, limit=MAX_FILE_BYTES):
    """
    Parse a small YAML file: at most ``limit`` bytes, UTF-8, no aliases, bounded nesting.

    Raises
    ------
    MechanismError
        Naming the file (or ``yaml``) and the bound or the parse error.

    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise MechanismError(str(path), 'not a regular file')
    with open(path, 'rb') as stream:
        raw = stream.read(limit + 1)
    if len(raw) > limit:
        raise MechanismError(str(path), f'larger than {limit} bytes (a mechanism file is '
                             'a few kB)')
    try:
        return yaml.load(raw.decode('utf-8'), Loader=_PlainLoader)  # noqa: S506 - safe subclass
    except UnicodeDecodeError as exc:
        raise MechanismError(str(path), f'not UTF-8 text ({exc.reason})') from None
    except yaml.YAMLError as exc:
        reason = ' '.join(str(exc).split())[:200]
        raise MechanismError(str(path), f'not valid YAML: {reason}') from None


def load_mechanism(path_or_name):
    """Load and validate a mechanism YAML file (see :func:`mechanism_from_dict`)."""
    path = find_config(str(path_or_name))
    data = read_yaml_bounded(path)
    if not isinstance(data, dict):
        raise MechanismError(str(path), 'expected a YAML mapping at the top level')
    return mechanism_from_dict(data)
