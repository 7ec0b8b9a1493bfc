"""
The Exudyn model of the flexible four-bar: ANCF cables, joints, crank drive and sensors.

Builds (does not solve) the geometrically exact peer described in :mod:`studies.peer_exudyn`:
the coupler and lever as planar ANCF cables (:func:`_add_links`), the crank pin driven on its
circle (:func:`_add_crank_drive`), revolute joints or bearing springs at B and O4 and the
joint point masses (:func:`_add_joints`), and the position sensors of the lever tip and the
coupler's material mid-point (:func:`_add_sensors`). :func:`deflections` turns sensed
positions into ground-frame elastic deflections.

Exudyn is optional (``exudyn==1.13.6``, requirements-test.txt): this module imports without
it, :func:`exudyn_available` says whether it is there, and :func:`require_exudyn` raises
:class:`errors.FlexlinkError` naming the package to install.
"""

import dataclasses
import math

import numpy as np

from ..core.kinematics import solve_kinematics
from ..core.mechanism import Mechanism
from ..core.mechanism_file import load_mechanism
from ..errors import FlexlinkError

try:
    import exudyn
    import exudyn.itemInterface as exudyn_items
except ImportError as exc:   # optional: the peer is a test and study tool
    exudyn = exudyn_items = None
    EXUDYN_IMPORT_ERROR = str(exc)
else:
    EXUDYN_IMPORT_ERROR = None

BEARINGS = ('rigid', 'springs')
MASS_PLACEMENTS = ('coupler-end', 'split')
OUTPUT_KEYS = ('lever_tip_dx', 'lever_tip_dy', 'coupler_mid_dx', 'coupler_mid_dy')
EXUDYN_REQUIREMENT = 'exudyn==1.13.6'
DEFAULT_ELEMENTS = 8
DEFAULT_BETA_S = 1e-4
DEFAULT_STEPS = 720
DEFAULT_SPECTRAL_RADIUS = 0.9
# Links modelled as flexible (crank rigid): 1 coupler, 2 lever.
FLEXIBLE_LINKS = (1, 2)


def require_exudyn():
    """
    Return the exudyn module and its item interface, or raise saying how to install it.

    Returns
    -------
    tuple of (module, module)

    Raises
    ------
    FlexlinkError
        If exudyn is not installed.

    """
    if exudyn is None:
        raise FlexlinkError(
            f'the nonlinear peer needs Exudyn, which is not installed ({EXUDYN_IMPORT_ERROR}); '
            f'install it with `pip install {EXUDYN_REQUIREMENT}` (listed in '
            'requirements-test.txt)')
    return exudyn, exudyn_items


def exudyn_available():
    """Return True if exudyn can be imported (the peer can run)."""
    return exudyn is not None


def resolve_mechanism(mechanism):
    """Return a Mechanism, loading a file path or bare name."""
    if isinstance(mechanism, Mechanism):
        return mechanism
    return load_mechanism(mechanism)


def _check(mech, rpm, elements, bearings, beta_s, mass_placement):
    if not mech.is_flexible:
        raise ValueError('`mechanism` lacks the material or section data of a flexible model')
    if not (isinstance(elements, int) and not isinstance(elements, bool) and elements >= 1):
        raise ValueError(f'`elements_per_link` must be an integer >= 1, got {elements!r}')
    if bearings not in BEARINGS:
        raise ValueError(f'`bearings` must be one of {BEARINGS}, got {bearings!r}')
    if bearings == 'springs' and not mech.bearing_stiffness:
        raise ValueError("bearings='springs' needs bearings.stiffness_n_m in the mechanism")
    if mass_placement not in MASS_PLACEMENTS:
        raise ValueError(f'`mass_placement` must be one of {MASS_PLACEMENTS}, '
                         f'got {mass_placement!r}')
    if not (math.isfinite(beta_s) and beta_s >= 0.0):
        raise ValueError(f'`beta_s` must be >= 0, got {beta_s!r}')
    if not math.isfinite(rpm):
        raise ValueError(f'`rpm` must be finite, got {rpm!r}')


@dataclasses.dataclass
class PeerModel:
    """
    An assembled Exudyn model of the linkage and what is needed to read it.

    Attributes
    ----------
    system_container, mbs :
        Exudyn SystemContainer and MainSystem.
    mechanism : Mechanism
    omega : float
        Crank speed [rad/s].
    start_angle : float
        Crank angle at t = 0 [rad].
    nodes : dict of int to list of int
        Node numbers of the coupler (1) and lever (2), first joint to second.
    elements : dict of int to list of int
        Cable object numbers per link.
    sensors : dict of str to int
        'lever_tip' (lever node at B) and 'coupler_mid' (material mid-point), positions.
    options : dict
        The modelling choices.

    """

    system_container: object
    mbs: object
    mechanism: Mechanism
    omega: float
    start_angle: float
    nodes: dict
    elements: dict
    sensors: dict
    options: dict


def _crank_offset(fun, crank, angle_at, theta0):
    """Offset user function: displacement a fun(theta(t)) - a fun(theta0) of pin A."""
    start = crank * fun(theta0)

    def offset(mbs, t, itemNumber, lOffset):
        return crank * fun(angle_at(t)) - start
    return offset


def _joint_masses(mech, placement):
    """
    Place the joints' point masses per (link, end).

    {(1, 0): coupler at A, (1, 1): coupler at B, (2, 0): lever at O4, (2, 1): lever at B,
    ('pin', 'A'): crank pin}.
    """
    m = mech.joint_masses
    s = mech.joint_mass_split
    if placement == 'coupler-end':
        return {(1, 0): m['A'], (1, 1): m['B'], (2, 0): m['O4'], (2, 1): 0.0,
                ('pin', 'A'): 0.0}
    return {(1, 0): (1.0 - s) * m['A'], (1, 1): s * m['B'], (2, 0): s * m['O4'],
            (2, 1): (1.0 - s) * m['B'], ('pin', 'A'): s * m['A']}


def build_peer(mechanism, rpm, *, elements_per_link=DEFAULT_ELEMENTS, bearings='rigid',
               gravity=True, beta_s=DEFAULT_BETA_S, mass_placement='coupler-end',
               start_angle=0.0, crank_angle=None):
    """
    Build (not solve) the Exudyn model of the linkage at constant crank speed (or a profile).

    Parameters
    ----------
    mechanism : Mechanism or str
        A Mechanism, or a mechanism file path or bare name ('cho1992').
    rpm : float
        Crank speed [rpm] (0 for a static model; negative turns clockwise).
    elements_per_link : int
        ANCF cable elements of the coupler and of the lever.
    bearings : str
        'rigid' (revolute joints) or 'springs' (bearing springs at ``mechanism.bearing_joints``
        among A, B, O4; rigid crank pivot).
    gravity : bool
        Apply ``mechanism.gravity`` to the cables and the joint masses.
    beta_s : float
        Stiffness-proportional damping beta [s] on the material strain rates (and c = beta k
        on the bearing springs).
    mass_placement : str
        'coupler-end' or 'split' (see the module notes of :mod:`studies.peer_exudyn`).
    start_angle : float
        Crank angle theta0 at t = 0 [rad].
    crank_angle : callable or None
        theta(t) [rad] of a varying crank speed (a speed ramp), with theta(0) = ``start_angle``
        and theta'(0) the speed of ``rpm``; None for omega t + theta0.

    Returns
    -------
    PeerModel

    Raises
    ------
    FlexlinkError
        If exudyn is not installed.

    """
    exu, items = require_exudyn()
    mech = resolve_mechanism(mechanism)
    _check(mech, rpm, elements_per_link, bearings, beta_s, mass_placement)
    omega = rpm * 2.0 * math.pi / 60.0
    theta0 = float(start_angle)
    state = solve_kinematics(mech, np.array([theta0]), omega)
    container = exu.SystemContainer()
    builder = _Builder(container.AddSystem(), items, mech,
                       list(mech.gravity) + [0.0] if gravity else [0.0, 0.0, 0.0], beta_s)
    nodes, elements = _add_links(builder, state, elements_per_link)
    springs = set(mech.bearing_joints) if bearings == 'springs' else set()
    masses = _joint_masses(mech, mass_placement)
    if crank_angle is None:
        crank_angle = lambda t: omega * t + theta0  # noqa: E731
    _add_crank_drive(builder, nodes[1][0], 'A' in springs, masses[('pin', 'A')], state,
                     crank_angle, theta0)
    _add_joints(builder, nodes, springs, masses)
    sensors = _add_sensors(builder, exu, nodes[2][-1], elements[1], elements_per_link)
    builder.mbs.Assemble()
    options = {'elements_per_link': elements_per_link, 'bearings': bearings,
               'gravity': bool(gravity), 'beta_s': beta_s, 'mass_placement': mass_placement,
               'start_angle_rad': theta0, 'rpm': float(rpm),
               'springs_at': sorted(springs)}
    return PeerModel(system_container=container, mbs=builder.mbs, mechanism=mech, omega=omega,
                     start_angle=theta0, nodes=nodes, elements=elements, sensors=sensors,
                     options=options)


class _Builder:
    """The Exudyn MainSystem being built, with the small items every step adds."""

    def __init__(self, mbs, items, mech, gvec, beta_s):
        self.mbs, self.items, self.mech, self.gvec, self.beta_s = mbs, items, mech, gvec, beta_s
        ground = mbs.AddNode(items.NodePointGround(referenceCoordinates=[0.0, 0.0, 0.0]))
        self.ground_coord = mbs.AddMarker(items.MarkerNodeCoordinate(nodeNumber=ground,
                                                                     coordinate=0))

    def coordinate_marker(self, node, index):
        """Add a marker on one coordinate of a node."""
        return self.mbs.AddMarker(self.items.MarkerNodeCoordinate(nodeNumber=node,
                                                                  coordinate=index))

    def position_marker(self, node):
        """Add a marker on the position of a node."""
        return self.mbs.AddMarker(self.items.MarkerNodePosition(nodeNumber=node))

    def gravity_load(self, body):
        """Add gravity to a body (nothing without gravity)."""
        if any(self.gvec):
            marker = self.mbs.AddMarker(self.items.MarkerBodyMass(bodyNumber=body))
            self.mbs.AddLoad(self.items.LoadMassProportional(markerNumber=marker,
                                                             loadVector=self.gvec))

    def point_mass(self, node, mass):
        """Add a point mass at a node (nothing for a zero mass)."""
        if mass <= 0.0:
            return
        self.gravity_load(self.mbs.AddObject(self.items.ObjectMassPoint2D(mass=mass,
                                                                          nodeNumber=node)))

    def pin(self, node_a, node_b):
        """Equal displacements of two nodes (same reference position): a rigid revolute."""
        for index in (0, 1):
            first = self.ground_coord if node_a is None else self.coordinate_marker(node_a, index)
            self.mbs.AddObject(self.items.ObjectConnectorCoordinate(
                markerNumbers=[first, self.coordinate_marker(node_b, index)]))

    def spring(self, marker_a, marker_b):
        """Add an isotropic bearing spring with damping beta k between two markers."""
        k = self.mech.bearing_stiffness
        self.mbs.AddObject(self.items.ObjectConnectorCartesianSpringDamper(
            markerNumbers=[marker_a, marker_b], stiffness=[k, k, 0.0],
            damping=[self.beta_s * k, self.beta_s * k, 0.0]))


def _add_links(builder, state, elements_per_link):
    """Add the coupler and lever: nodes on the rigid configuration, then ANCF cables."""
    mbs, items, mech = builder.mbs, builder.items, builder.mech
    nodes, elements = {}, {}
    for link in FLEXIBLE_LINKS:
        spec = mech.links[link]
        le = spec.length / elements_per_link
        tangent = complex(math.cos(float(state.angle[link][0])),
                          math.sin(float(state.angle[link][0])))
        slope_rate = 1j * float(state.omega[link][0]) * tangent
        nodes[link] = []
        for k in range(elements_per_link + 1):
            position, velocity = (p[0] for p in state.point(link, k * le)[:2])
            nodes[link].append(mbs.AddNode(items.NodePoint2DSlope1(
                referenceCoordinates=[position.real, position.imag, tangent.real, tangent.imag],
                initialVelocities=[velocity.real, velocity.imag, slope_rate.real,
                                   slope_rate.imag])))
        EA, EI = mech.youngs_modulus * spec.area, mech.youngs_modulus * spec.second_moment
        elements[link] = []
        for k in range(elements_per_link):
            body = mbs.AddObject(items.ObjectANCFCable2D(
                length=le, massPerLength=mech.density * spec.area, bendingStiffness=EI,
                axialStiffness=EA, bendingDamping=builder.beta_s * EI,
                axialDamping=builder.beta_s * EA,
                nodeNumbers=[nodes[link][k], nodes[link][k + 1]]))
            elements[link].append(body)
            builder.gravity_load(body)
    return nodes, elements


def _add_crank_drive(builder, coupler_start, spring_at_a, pin_mass, state, angle_at, theta0):
    """Joint A: the coupler's first node on crank pin A, a (cos, sin)(theta(t))."""
    mbs, items = builder.mbs, builder.items
    crank = builder.mech.links[0].length

    def prescribe_crank_pin(node):
        for index, fun in ((0, math.cos), (1, math.sin)):
            mbs.AddObject(items.ObjectConnectorCoordinate(
                markerNumbers=[builder.ground_coord, builder.coordinate_marker(node, index)],
                offsetUserFunction=_crank_offset(fun, crank, angle_at, theta0)))

    if not spring_at_a:
        prescribe_crank_pin(coupler_start)
        return
    a0 = state.joints['A'][0]
    crank_pin = mbs.AddNode(items.NodePoint2D(referenceCoordinates=[a0.real, a0.imag]))
    # the pin is prescribed; give it a mass so its rows are regular (the value is inert)
    mbs.AddObject(items.ObjectMassPoint2D(mass=max(pin_mass, 1e-3), nodeNumber=crank_pin))
    prescribe_crank_pin(crank_pin)
    builder.spring(builder.position_marker(crank_pin), builder.position_marker(coupler_start))


def _add_joints(builder, nodes, springs, masses):
    """Joints B (coupler and lever ends) and O4 (lever on the ground), then the joint masses."""
    coupler, lever = nodes[1], nodes[2]
    if 'B' in springs:
        builder.spring(builder.position_marker(coupler[-1]), builder.position_marker(lever[-1]))
    else:
        builder.pin(coupler[-1], lever[-1])
    if 'O4' in springs:
        o4 = builder.mbs.AddNode(builder.items.NodePointGround(
            referenceCoordinates=[builder.mech.ground_length, 0.0, 0.0]))
        builder.spring(builder.position_marker(o4), builder.position_marker(lever[0]))
    else:
        builder.pin(None, lever[0])
    builder.point_mass(coupler[0], masses[(1, 0)])
    builder.point_mass(coupler[-1], masses[(1, 1)])
    builder.point_mass(lever[0], masses[(2, 0)])
    builder.point_mass(lever[-1], masses[(2, 1)])


def _add_sensors(builder, exu, lever_tip, coupler_elements, elements_per_link):
    """Absolute positions of the lever tip and the coupler's material mid-point."""
    mbs, items = builder.mbs, builder.items
    position = exu.OutputVariableType.Position
    half = 0.5 * builder.mech.links[1].length
    le = builder.mech.links[1].length / elements_per_link
    which = min(int(half // le), elements_per_link - 1)
    return {
        'lever_tip': mbs.AddSensor(items.SensorNode(
            nodeNumber=lever_tip, storeInternal=True, writeToFile=False,
            outputVariableType=position)),
        'coupler_mid': mbs.AddSensor(items.SensorBody(
            bodyNumber=coupler_elements[which], localPosition=[half - which * le, 0.0, 0.0],
            storeInternal=True, writeToFile=False, outputVariableType=position)),
    }


def solver_settings(exu, end_time, steps, spectral_radius, write_period):
    settings = exu.SimulationSettings()
    settings.timeIntegration.endTime = end_time
    settings.timeIntegration.numberOfSteps = steps
    settings.timeIntegration.verboseMode = 0
    settings.timeIntegration.generalizedAlpha.spectralRadius = spectral_radius
    settings.timeIntegration.adaptiveStep = False
    settings.solution.file.write = False
    settings.solution.sensors.writePeriod = write_period
    settings.show.statistics = False
    settings.show.computationTime = False
    return settings


def _rigid_outputs(mech, theta):
    """Rigid positions of the lever tip (B) and the coupler mid-point, complex (n,) each."""
    state = solve_kinematics(mech, theta)
    return state.joints['B'], state.point(1, 0.5 * mech.links[1].length)[0]


def deflections(mech, theta, tip, mid):
    rigid_tip, rigid_mid = _rigid_outputs(mech, theta)
    d_tip = tip[:, 0] + 1j * tip[:, 1] - rigid_tip
    d_mid = mid[:, 0] + 1j * mid[:, 1] - rigid_mid
    return {'lever_tip_dx': d_tip.real, 'lever_tip_dy': d_tip.imag,
            'coupler_mid_dx': d_mid.real, 'coupler_mid_dy': d_mid.imag}


__all__ = ['BEARINGS', 'MASS_PLACEMENTS', 'OUTPUT_KEYS', 'EXUDYN_REQUIREMENT', 'DEFAULT_ELEMENTS',
           'DEFAULT_BETA_S', 'DEFAULT_STEPS', 'DEFAULT_SPECTRAL_RADIUS', 'FLEXIBLE_LINKS',
           'PeerModel', 'require_exudyn', 'exudyn_available', 'resolve_mechanism', 'build_peer',
           'solver_settings', 'deflections']
