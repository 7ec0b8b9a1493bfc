"""
Mechanism files: YAML in SI units, read with bounds and validated into a Mechanism.

A mechanism file is small and plain, so the loader bounds what a hostile one could ask for:
at most :data:`MAX_FILE_BYTES`, no YAML anchors or aliases (an alias bomb of 1.5 kB expands to
gigabytes), nesting at most :data:`MAX_YAML_DEPTH` deep, strings at most
:data:`MAX_NAME_CHARS` / :data:`MAX_SOURCE_CHARS` long, and ``elements_per_link`` within
1..:data:`MAX_ELEMENTS_PER_LINK` (checked by the dataclass too, so ``dataclasses.replace`` and
``--elements`` are bounded as well). Each refusal is a :class:`MechanismError` naming the
field and the bound. Unknown keys (with the closest known one), non-positive sizes, numbers
off by orders of magnitude (:mod:`.mechanism_checks`: lengths in mm, sections in mm^4, ...)
and linkages that are not the crank-rocker the models assume are refused the same way.

Bare names such as 'cho1992' are found in the installed share directories (those of
``AMENT_PREFIX_PATH`` as the ament index finds them, then this Python's prefix) and then in
the source tree (:func:`find_config`); the core reads them without importing ROS.
"""

import math
import os
import pathlib
import sys

import yaml

from .mechanism import (BRANCHES, check_crank_rocker, check_elements_per_link, check_name,
                        Link, Mechanism, Spring)
from .mechanism_checks import check_keys, check_lengths, check_plausible
from ..errors import MechanismError
from ..names import JOINT_NAMES, LINK_NAMES

# Bounds on what a mechanism file can set; the README states them.
MAX_FILE_BYTES = 64 * 1024  # the shipped files are about 1.5 kB
MAX_YAML_DEPTH = 8  # the schema nests 3 deep (links.crank.length_m)
MAX_NAME_CHARS = 128
MAX_SOURCE_CHARS = 4096
MAX_STIFFNESS_DAMPING_S = 1.0  # beta [s]; the peer's is 1e-4 s (1 s overdamps f > 0.3 Hz)
PACKAGE = 'flexlink_ros'
# Marker of a package in an ament prefix (the ament resource index).
AMENT_PACKAGE_MARKERS = pathlib.Path('share', 'ament_index', 'resource_index', 'packages')

_TOP_KEYS = {'name', 'source', 'ground_length_m', 'material', 'links', 'joint_masses_kg',
             'bearings', 'input_shaft', 'gravity_m_s2', 'damping_ratio',
             'elements_per_link', 'branch', 'spring', 'crank_speed_rpm',
             'stiffness_damping_s'}
_LINK_KEYS = {'length_m', 'mass_kg', 'inertia_kg_m2', 'area_m2', 'second_moment_m4'}
_MATERIAL_KEYS = {'youngs_modulus_pa', 'density_kg_m3'}
_BEARING_KEYS = {'stiffness_n_m', 'joints', 'mass_split'}
_SHAFT_KEYS = {'torsional_stiffness_nm_rad'}
_SPRING_KEYS = {'stiffness_nm_rad', 'theta0_deg'}


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


def _material_from(data):
    """Young's modulus and density of the 'material' section (either may be None)."""
    material = data.get('material') or {}
    check_keys(material, _MATERIAL_KEYS, 'material')
    youngs = _number(material, 'youngs_modulus_pa', 'material', required=False)
    density = _number(material, 'density_kg_m3', 'material', required=False)
    return youngs, density


def _link_from(entry, where, density):
    """One Link of the 'links' section; its mass from area and density if not given."""
    if entry is None:
        raise MechanismError(where, 'missing')
    check_keys(entry, _LINK_KEYS, where)
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
    return Link(length=length, mass=mass, inertia=inertia, area=area, second_moment=second)


def _links_from(data, density):
    """Crank, coupler and lever of the 'links' section."""
    links_data = data.get('links')
    if links_data is None:
        raise MechanismError('links', 'missing')
    check_keys(links_data, set(LINK_NAMES), 'links')
    return tuple(_link_from(links_data.get(name), f'links.{name}', density)
                 for name in LINK_NAMES)


def _joint_masses_from(data):
    """Lumped joint masses [kg] of the 'joint_masses_kg' section (0 where not given)."""
    masses_data = data.get('joint_masses_kg') or {}
    check_keys(masses_data, set(JOINT_NAMES), 'joint_masses_kg')
    return {j: _number(masses_data, j, 'joint_masses_kg', positive=False,
                       required=False, default=0.0, minimum=0.0) for j in JOINT_NAMES}


def _bearings_from(data):
    """Stiffness, joints and joint-mass split of the 'bearings' section."""
    bearings = data.get('bearings') or {}
    check_keys(bearings, _BEARING_KEYS, 'bearings')
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
    return bearing_k, bearing_joints, split


def _shaft_from(data):
    """Torsional stiffness of the 'input_shaft' section (None: clamped)."""
    shaft = data.get('input_shaft') or {}
    check_keys(shaft, _SHAFT_KEYS, 'input_shaft')
    return _number(shaft, 'torsional_stiffness_nm_rad', 'input_shaft', required=False)


def _gravity_from(data):
    """Gravity (gx, gy) [m/s^2] of 'gravity_m_s2'."""
    gravity = data.get('gravity_m_s2', [0.0, 0.0])
    if (not isinstance(gravity, (list, tuple)) or len(gravity) != 2
            or not all(isinstance(g, (int, float)) and not isinstance(g, bool)
                       and math.isfinite(_as_float(g, 'gravity_m_s2')) for g in gravity)):
        raise MechanismError('gravity_m_s2', f'expected [gx, gy] in m/s^2, got {gravity!r:.60}')
    return (float(gravity[0]), float(gravity[1]))


def _model_options_from(data):
    """Damping ratio, elements per link and branch of the top level."""
    zeta = _number(data, 'damping_ratio', '', positive=False, required=False, default=0.02,
                   minimum=0.0, maximum=1.0)
    elements = data.get('elements_per_link', 3)
    check_elements_per_link(elements)
    branch = data.get('branch', 'open')
    if not isinstance(branch, str) or branch not in BRANCHES:
        raise MechanismError('branch', f'expected one of {BRANCHES}, got {branch!r:.40}')
    return zeta, elements, branch


def _stiffness_damping_from(data):
    """Stiffness damping beta [s] of 'stiffness_damping_s' (0 if not given; not in Mechanism)."""
    return _number(data, 'stiffness_damping_s', '', positive=False, required=False,
                   default=0.0, minimum=0.0, maximum=MAX_STIFFNESS_DAMPING_S)


def _spring_from(data):
    """Return the coupler-lever Spring of the 'spring' section, or None."""
    if data.get('spring') is None:
        return None
    spring_data = data['spring']
    check_keys(spring_data, _SPRING_KEYS, 'spring')
    return Spring(
        stiffness=_number(spring_data, 'stiffness_nm_rad', 'spring', positive=False,
                          minimum=0.0),
        theta0=math.radians(_number(spring_data, 'theta0_deg', 'spring', positive=False)))


def mechanism_from_dict(data):
    """
    Build and validate a Mechanism from a plain mapping (the YAML schema, SI units).

    Parameters
    ----------
    data : dict
        The parsed mechanism file.

    Returns
    -------
    Mechanism
        The validated mechanism.

    Raises
    ------
    MechanismError
        Naming the field: unknown keys, missing or non-positive values, a linkage that is not
        a crank-rocker.

    """
    check_keys(data, _TOP_KEYS, '')
    name = check_name(_text(data, 'name', 'mechanism', MAX_NAME_CHARS))
    source = _text(data, 'source', '', MAX_SOURCE_CHARS)
    ground = _number(data, 'ground_length_m', '')
    youngs, density = _material_from(data)
    links = _links_from(data, density)
    # a length in mm is named as such, not as a failed Grashof sum
    check_lengths(ground, [link.length for link in links])
    check_crank_rocker(ground, *(link.length for link in links))
    joint_masses = _joint_masses_from(data)
    bearing_k, bearing_joints, split = _bearings_from(data)
    shaft_k = _shaft_from(data)
    gravity = _gravity_from(data)
    zeta, elements, branch = _model_options_from(data)
    _stiffness_damping_from(data)   # checked here; read by stiffness_damping_from_file
    spring = _spring_from(data)
    rpm = _number(data, 'crank_speed_rpm', '', required=False)
    mechanism = Mechanism(
        name=name, ground_length=ground, links=links, youngs_modulus=youngs,
        density=density, joint_masses=joint_masses, bearing_stiffness=bearing_k,
        bearing_joints=bearing_joints, joint_mass_split=split, shaft_stiffness=shaft_k,
        gravity=gravity, damping_ratio=zeta,
        elements_per_link=elements, branch=branch, spring=spring,
        crank_speed=None if rpm is None else rpm * 2.0 * math.pi / 60.0,
        source=source)
    check_plausible(mechanism)      # numbers off by orders of magnitude: a slip of units
    return mechanism


def ament_share_directory(package=PACKAGE):
    """
    Return the share directory of ``package`` in the ament index, or None.

    What ``ament_index_python.get_package_share_directory`` returns, without importing ROS:
    ``<prefix>/share/<package>`` of the first ``AMENT_PREFIX_PATH`` entry whose resource
    index lists the package.

    Parameters
    ----------
    package : str
        Package name.

    """
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix and os.path.exists(prefix) and (
                pathlib.Path(prefix) / AMENT_PACKAGE_MARKERS / package).is_file():
            return pathlib.Path(prefix) / 'share' / package
    return None


def find_config(name):
    """
    Resolve a mechanism or parameter file: a path, or a bare name like 'cho1992'.

    Bare names are looked up in the installed share directory (ament index, then the
    install prefix of this Python, where ``pip install .`` puts it) and then in the source
    tree's ``config/``.

    Parameters
    ----------
    name : str
        A path or a bare name (with or without '.yaml').

    Returns
    -------
    pathlib.Path
        The file found.

    """
    path = pathlib.Path(name)
    if path.exists():
        return path
    stem = name if name.endswith('.yaml') else name + '.yaml'
    candidates = [pathlib.Path(sys.prefix) / 'share' / PACKAGE / 'config' / stem,
                  pathlib.Path(__file__).resolve().parents[2] / 'config' / stem]
    share = ament_share_directory()
    if share is not None:
        candidates.insert(0, share / 'config' / stem)
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


def read_bounded(path, limit=MAX_FILE_BYTES):
    """Read at most ``limit`` + 1 bytes of a regular file (one more tells it is too large)."""
    path = pathlib.Path(path)
    if not path.is_file():
        raise MechanismError(str(path), 'not a regular file')
    with open(path, 'rb') as stream:
        return stream.read(limit + 1)


def read_yaml_bounded(path, limit=MAX_FILE_BYTES, raw=None):
    """
    Parse a small YAML file: at most ``limit`` bytes, UTF-8, no aliases, bounded nesting.

    ``raw``: the file's bytes when the caller has them (a recording's copy; ``path`` then only
    names it). A MechanismError names the file (or ``yaml``) and the bound or parse error.

    """
    if raw is None:
        raw = read_bounded(path, limit)
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


def _read_mapping(path_or_name, raw=None):
    """Find (unless its bytes ``raw`` are given), read and parse a mechanism file's mapping."""
    path = find_config(str(path_or_name)) if raw is None else path_or_name
    data = read_yaml_bounded(path, raw=raw)
    if not isinstance(data, dict):
        raise MechanismError(str(path), 'expected a YAML mapping at the top level')
    return data


def load_mechanism(path_or_name, raw=None):
    """Load and validate a mechanism file, or its bytes ``raw`` (:func:`mechanism_from_dict`)."""
    return mechanism_from_dict(_read_mapping(path_or_name, raw))


def read_mechanism_file(path_or_name, raw=None):
    """Read a mechanism file (or its bytes ``raw``) once: Mechanism, ``stiffness_damping_s``."""
    data = _read_mapping(path_or_name, raw)
    return mechanism_from_dict(data), _stiffness_damping_from(data)


def read_mechanism_source(path_or_name):
    """
    Find a mechanism file and read its bytes once: (path, bytes), not yet checked.

    For a caller that both builds a model (:func:`read_mechanism_file` with ``raw``) and
    records the file (a recording's provenance): both then describe the same bytes, even if
    the file changes in between.
    """
    path = find_config(str(path_or_name))
    return path, read_bounded(path)


def stiffness_damping_from_file(path_or_name, raw=None):
    """Return a (validated) file's ``stiffness_damping_s`` [s] (0 if none)."""
    return read_mechanism_file(path_or_name, raw)[1]
