"""
Geometrically nonlinear peer of the flexible four-bar, built with Exudyn (ANCF cables).

The linear kineto-elastodynamic (KED) model of the package (:mod:`core.fe.linkage`,
:mod:`core.fe.simulate`) follows Cho, Park & Lee (1992). This module builds an independent,
geometrically exact model of the same linkage from the same mechanism file, so that the
linear estimate (and later second-order corrections) can be checked against it.

Model (the conventions of the published peer comparison):

* coupler and lever: ``elements_per_link`` planar ANCF cable elements each
  (``ObjectANCFCable2D``: Bernoulli-Euler, exact in large rotations, axial strain
  |r'| - 1 and the material curvature), E A, E I and rho A from the mechanism file;
* crank rigid, with prescribed rotation at constant speed: theta = omega t + theta0, theta
  counter-clockwise from O2->O4 (package convention, :mod:`core.kinematics`); crank pin A
  moves exactly on its circle;
* joints: rigid bearings (``bearings='rigid'``) are exact revolute joints: the coupler's
  first node is pinned to crank pin A, coupler and lever end nodes share their position at
  B, the lever's first node is pinned at O4 (slopes free). ``bearings='springs'`` puts an
  isotropic spring k = ``bearings.stiffness_n_m`` (damping c = beta k) in place of the pin at
  each joint of ``bearings.joints`` among A, B and O4; the crank pivot O2 stays rigid (the
  crank is prescribed);
* joint masses are point masses. ``mass_placement='coupler-end'`` (the published peer's and the
  package's rigid-bearing convention): each joint's whole mass on the first modelled member
  (A and B on the coupler, O4 on the lever); ``'split'``: the fraction
  ``joint_mass_split`` on the joint's first member (crank, coupler, lever for A, B, O4) and
  the rest on the second (coupler, lever, ground). With rigid bearings the two placements are
  the same model (a point mass at a pin moves with the pin). Masses on a prescribed or fixed
  point (O2, the crank's share of A, the ground's share of O4) do nothing;
* gravity (``mechanism.gravity``) optional, on the cables and the point masses;
* damping stiffness-proportional on the material strain rates: axial damping beta E A and
  bending damping beta E I (objective: a rigid motion dissipates nothing), beta = 1e-4 s by
  default; modal damping ratio beta omega / 2 (about 0.011 at the 34 Hz coupler mode).

Outputs: elastic deflections in the ground frame, i.e. the nonlinear position minus the
rigid-body position at the same crank angle (:func:`core.kinematics.solve_kinematics`), of
the lever tip (node B of the lever) and of the coupler's material mid-point (arc length
L/2 of the undeformed coupler): the quantities of ``flexlink simulate``
(:data:`names.OUTPUT_NAMES`).

Start and steady state: the run starts with the links straight, in the rigid configuration
at theta0, with the rigid-body velocities at full speed (no ramp). The transient then decays
with the stiffness-proportional damping; :func:`default_revolutions` chooses the number of
revolutions from the slowest decay rate beta omega_1^2 / 2 of the lowest pinned-pinned
bending mode of the flexible links, and :func:`peak_to_peak` reports the last revolution with
its difference to the one before (``periodicity``), so a run that is not yet steady says so.

Integration: Exudyn's implicit generalized-alpha (index 3, spectral radius 0.9 by default),
constant step ``1 / steps_per_revolution`` of a revolution; outputs sampled at every step by
default (``samples_per_revolution``, a divisor of the steps). Where its Newton iterations
diverge (light pins on stiff bearing springs: a light plastic linkage's 0.5 g pin halves on
1e6 N/m at 720 steps) the run is repeated with 2, 4 and 8 times the steps, the samples as
asked; ``info['steps_per_revolution']`` says the steps used.

The model itself is built by :mod:`studies.peer_model`. Exudyn is optional: this module
imports without it, and the functions that need it raise :class:`errors.FlexlinkError` naming
the package to install (``exudyn==1.13.6``, requirements-test.txt).
"""

import argparse
import json
import math
import time

import numpy as np

from .peer_linear import linear_model, linear_response, linear_static
from .peer_model import BEARINGS, build_peer, DEFAULT_BETA_S, DEFAULT_ELEMENTS
from .peer_model import DEFAULT_SPECTRAL_RADIUS, DEFAULT_STEPS, deflections
from .peer_model import exudyn_available, EXUDYN_REQUIREMENT, FLEXIBLE_LINKS, MASS_PLACEMENTS
from .peer_model import OUTPUT_KEYS, PeerModel, require_exudyn, resolve_mechanism
from .peer_model import solver_settings
from .peer_solver import solve_or_explain
from ..errors import FlexlinkError

# The transient is let decay to this fraction of its start (ln(1/1e-3) = 6.9 time constants).
SETTLE_FRACTION = 1e-3
# Step refinements tried in turn when the solver fails (light pins on stiff bearing springs).
STEP_REFINEMENTS = (1, 2, 4, 8)


def lowest_bending_frequency(mechanism):
    """
    Lowest pinned-pinned bending frequency of the flexible links [rad/s] (joint masses left out).

    (pi / L)^2 sqrt(E I / (rho A)) per link; about 217 rad/s (34.5 Hz) for the cho1992
    coupler. Used to size the settling run; the linkage's own lowest mode is somewhat lower.
    """
    mech = resolve_mechanism(mechanism)
    return min((math.pi / mech.links[k].length) ** 2
               * math.sqrt(mech.youngs_modulus * mech.links[k].second_moment
                           / (mech.density * mech.links[k].area)) for k in FLEXIBLE_LINKS)


def default_revolutions(mechanism, rpm, beta_s=DEFAULT_BETA_S, extra=2):
    """
    Revolutions for the start transient to decay to :data:`SETTLE_FRACTION`, plus ``extra``.

    The decay rate of a mode with stiffness-proportional damping is beta omega^2 / 2; the
    slowest is the lowest mode, estimated by :func:`lowest_bending_frequency` lowered by 15 %
    (the joint mass at B and the lever's compliance lower it), so the settling time is
    ``ln(1 / SETTLE_FRACTION) / (beta (0.85 omega_1)^2 / 2)``: 4.1 s with beta = 1e-4 s for
    cho1992: 19 revolutions at 269 rpm, 27 at 391 rpm (plus ``extra``).
    """
    if beta_s <= 0.0:
        raise ValueError('without damping the transient does not decay: give `revolutions`')
    rate = 0.5 * beta_s * (0.85 * lowest_bending_frequency(mechanism)) ** 2
    settle = math.log(1.0 / SETTLE_FRACTION) / rate
    return int(math.ceil(settle * abs(rpm) / 60.0)) + int(extra)


def peer_response(mechanism, rpm, *, elements_per_link=DEFAULT_ELEMENTS, bearings='rigid',
                  gravity=True, beta_s=DEFAULT_BETA_S, mass_placement='coupler-end',
                  revolutions=None, steps_per_revolution=DEFAULT_STEPS,
                  samples_per_revolution=None, start_angle=0.0,
                  spectral_radius=DEFAULT_SPECTRAL_RADIUS):
    """
    Run the nonlinear peer at constant crank speed and return the elastic deflections.

    Parameters
    ----------
    mechanism : Mechanism or str
        A Mechanism, or a mechanism file path or bare name ('cho1992').
    rpm : float
        Crank speed [rpm], non-zero.
    elements_per_link, bearings, gravity, beta_s, mass_placement, start_angle :
        See :func:`build_peer`.
    revolutions : int or None
        Crank revolutions simulated from the start; None for :func:`default_revolutions`.
    steps_per_revolution : int
        Constant time steps per revolution (a multiple of ``samples_per_revolution``).
    samples_per_revolution : int or None
        Output samples per revolution, a divisor of ``steps_per_revolution``; None for every
        step (peak-to-peak of the 6th-8th crank harmonics on a 3 degree grid is up to 0.3 %
        low at 391 rpm).
    spectral_radius : float
        Generalized-alpha spectral radius at infinity (< 1 for index-3 constraints).

    Returns
    -------
    dict
        'time' [s], 'crank_angle' [rad] (omega t + theta0, unwrapped), 'revolution' (index of
        each sample's revolution, 0 first), the four :data:`OUTPUT_KEYS` [m] (ground-frame
        elastic deflections), all arrays of shape (revolutions * samples + 1,); 'info'
        (settings, wall and CPU time [s], revolutions, steps).

    Raises
    ------
    FlexlinkError
        If exudyn is missing or the solver fails.

    """
    exu, _ = require_exudyn()
    mech = resolve_mechanism(mechanism)
    if rpm == 0.0:
        raise ValueError('`rpm` must be non-zero (see peer_static for the static case)')
    revolutions, samples_per_revolution = _run_length(
        mech, rpm, beta_s, revolutions, steps_per_revolution, samples_per_revolution)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for refinement in STEP_REFINEMENTS:
        # light pins on stiff bearing springs: Newton diverges on too long a step
        model = build_peer(mech, rpm, elements_per_link=elements_per_link, bearings=bearings,
                           gravity=gravity, beta_s=beta_s, mass_placement=mass_placement,
                           start_angle=start_angle)
        period = 2.0 * math.pi / abs(model.omega)
        h = period / (refinement * steps_per_revolution)
        settings = solver_settings(exu, revolutions * period,
                                   revolutions * refinement * steps_per_revolution,
                                   spectral_radius, 0.5 * h)
        case = (f'{rpm:g} rpm ({elements_per_link} elements per link, {bearings} bearings, '
                f'{refinement * steps_per_revolution} steps a revolution)')
        try:
            solve_or_explain(exu, model.mbs, settings, case, bearings)
            break
        except FlexlinkError:
            if refinement == STEP_REFINEMENTS[-1]:
                raise
    steps_per_revolution *= refinement     # the samples stay as asked
    data, index, wanted = _stored_samples(model, revolutions * samples_per_revolution + 1,
                                          steps_per_revolution // samples_per_revolution, h)
    t = data['lever_tip'][:, 0][index]
    theta = model.omega * wanted + model.start_angle
    out = deflections(mech, theta, data['lever_tip'][index, 1:3],
                      data['coupler_mid'][index, 1:3])
    info = dict(model.options)
    info.update({'revolutions': revolutions, 'steps_per_revolution': steps_per_revolution,
                 'samples_per_revolution': samples_per_revolution,
                 'spectral_radius': spectral_radius, 'time_step_s': h,
                 'wall_s': time.perf_counter() - wall0,
                 'cpu_s': time.process_time() - cpu0, 'exudyn': exu.__version__})
    result = {'time': t, 'crank_angle': theta,
              'revolution': np.minimum(np.arange(t.shape[0]) // samples_per_revolution,
                                       revolutions - 1)}
    result.update(out)
    result['info'] = info
    return result


def _run_length(mech, rpm, beta_s, revolutions, steps_per_revolution, samples_per_revolution):
    """Check the revolutions and the sampling of a run, filling in their defaults."""
    if revolutions is None:
        revolutions = default_revolutions(mech, rpm, beta_s)
    if not (isinstance(revolutions, int) and revolutions >= 1):
        raise ValueError(f'`revolutions` must be an integer >= 1, got {revolutions!r}')
    if samples_per_revolution is None:
        samples_per_revolution = steps_per_revolution
    if (samples_per_revolution < 1 or steps_per_revolution < 1
            or steps_per_revolution % samples_per_revolution):
        raise ValueError(f'`steps_per_revolution` ({steps_per_revolution}) must be a positive '
                         f'multiple of `samples_per_revolution` ({samples_per_revolution})')
    return revolutions, samples_per_revolution


def _stored_samples(model, count, stride, h):
    """
    Pick every ``stride``-th step of the sensors' stored data, ``count`` samples from t = 0.

    Returns the stored data per sensor, the indices picked and their wanted times [s].
    """
    data = {name: np.asarray(model.mbs.GetSensorStoredData(sensor))
            for name, sensor in model.sensors.items()}
    t_all = data['lever_tip'][:, 0]
    wanted = np.arange(count) * stride * h
    index = np.searchsorted(t_all, wanted - 0.25 * h)
    if index.max() >= len(t_all) or np.abs(t_all[index] - wanted).max() > 0.25 * h:
        raise FlexlinkError('the Exudyn sensors did not store every step')
    return data, index, wanted


def revolution_slice(response, revolution=-1):
    """
    Index slice of one whole revolution of a :func:`peer_response` result.

    ``revolution=-1`` is the last one. The slice holds ``samples_per_revolution`` samples
    (start included, the end - which is the next revolution's start - excluded).
    """
    info = response['info']
    count, samples = info['revolutions'], info['samples_per_revolution']
    rev = revolution % count
    return slice(rev * samples, (rev + 1) * samples)


def peak_to_peak(response, revolution=-1):
    """
    Peak-to-peak of each output over one revolution (the last by default) [m].

    Returns
    -------
    dict
        The four :data:`OUTPUT_KEYS` [m]; 'periodicity': per output, the largest difference
        between this revolution and the one before, relative to this revolution's
        peak-to-peak (the transient left; None with a single revolution); 'crank_deg' of the
        revolution's start.

    """
    span = revolution_slice(response, revolution)
    out = {}
    for key in OUTPUT_KEYS:
        values = response[key][span]
        out[key] = float(values.max() - values.min())
    samples = response['info']['samples_per_revolution']
    if span.start >= samples:
        previous = slice(span.start - samples, span.stop - samples)
        out['periodicity'] = {
            key: float(np.abs(response[key][span] - response[key][previous]).max()
                       / max(out[key], 1e-300)) for key in OUTPUT_KEYS}
    else:
        out['periodicity'] = None
    out['crank_deg'] = float(np.degrees(response['crank_angle'][span.start]))
    return out


def peer_static(mechanism, crank_angle=0.0, *, elements_per_link=DEFAULT_ELEMENTS,
                bearings='rigid', mass_placement='coupler-end'):
    """
    Solve the nonlinear static deflection under gravity at a fixed crank angle (zero speed).

    Returns
    -------
    dict
        The four :data:`OUTPUT_KEYS` [m].

    """
    exu, _ = require_exudyn()
    mech = resolve_mechanism(mechanism)
    model = build_peer(mech, 0.0, elements_per_link=elements_per_link, bearings=bearings,
                       gravity=True, beta_s=0.0, mass_placement=mass_placement,
                       start_angle=crank_angle)
    settings = solver_settings(exu, 1.0, 1, DEFAULT_SPECTRAL_RADIUS, 1.0)
    settings.staticSolver.verboseMode = 0
    settings.staticSolver.numberOfLoadSteps = 4
    # loads are about 1 N and axial forces round off near 1e-9 N (E A = 3e6 N)
    settings.staticSolver.newton.absoluteTolerance = 1e-7
    if not exu.SolveStatic(model.mbs, settings):
        raise FlexlinkError('the Exudyn peer did not find the static equilibrium')
    mbs = model.mbs
    config = exu.ConfigurationType.Current
    tip = np.asarray(mbs.GetNodeOutput(model.nodes[2][-1], exu.OutputVariableType.Position,
                                       configuration=config))[None, :2]
    sensor = mbs.GetSensorValues(model.sensors['coupler_mid'], configuration=config)
    mid = np.asarray(sensor)[None, :2]
    out = deflections(mech, np.array([float(crank_angle)]), tip, mid)
    return {key: float(value[0]) for key, value in out.items()}


def compare(peer, linear):
    """
    Linear (or any other) response against the peer over the peer's last revolution.

    Parameters
    ----------
    peer : dict
        From :func:`peer_response`.
    linear : dict
        'crank_angle' [rad] over one revolution on a uniform grid and the
        :data:`OUTPUT_KEYS` [m], e.g. from :func:`linear_response`; its grid must be a
        subset of the peer's samples (same start angle modulo 2 pi, a divisor of the
        peer's samples per revolution).

    Returns
    -------
    dict
        Per output key: 'peer_p2p' [m] (peer on its full grid), 'other_p2p' [m],
        'p2p_error' (other / peer - 1), 'rms_error' (RMS of other - peer over the other's
        grid, relative to the RMS of the peer there, means included).

    """
    span = revolution_slice(peer)
    samples = span.stop - span.start
    points = len(linear['crank_angle'])
    if samples % points:
        raise ValueError(f'the linear grid ({points} points) is not a subset of the peer '
                         f'grid ({samples} samples per revolution)')
    offset = np.angle(np.exp(1j * (linear['crank_angle'][0] - peer['crank_angle'][span.start])))
    if abs(offset) > 1e-9:
        raise ValueError('the linear and peer revolutions start at different crank angles')
    stride = samples // points
    out = {}
    for key in OUTPUT_KEYS:
        full = peer[key][span]
        mine = full[::stride]
        other = np.asarray(linear[key])
        peer_p2p = float(full.max() - full.min())
        other_p2p = float(other.max() - other.min())
        out[key] = {'peer_p2p': peer_p2p, 'other_p2p': other_p2p,
                    'p2p_error': other_p2p / peer_p2p - 1.0,
                    'rms_error': float(np.sqrt(np.mean((other - mine) ** 2)
                                               / np.mean(mine ** 2)))}
    return out


def main(argv=None):
    """
    Print peer and linear peak-to-peak side by side (the published peer table).

    ``python -m flexlink_ros.studies.peer_exudyn --rpm 269 391 [--gravity] [--json]``.
    """
    parser = argparse.ArgumentParser(prog='python -m flexlink_ros.studies.peer_exudyn',
                                     description=main.__doc__)
    parser.add_argument('--mechanism', default='cho1992')
    parser.add_argument('--rpm', type=float, nargs='+', default=[269.0, 391.0])
    parser.add_argument('--elements', type=int, default=DEFAULT_ELEMENTS)
    parser.add_argument('--bearings', choices=BEARINGS, default='rigid')
    parser.add_argument('--mass-placement', choices=MASS_PLACEMENTS, default='coupler-end')
    parser.add_argument('--gravity', action='store_true', help='apply gravity (default off, '
                        'as in the published peer table)')
    parser.add_argument('--beta', type=float, default=DEFAULT_BETA_S)
    parser.add_argument('--steps', type=int, default=DEFAULT_STEPS)
    parser.add_argument('--revolutions', type=int, default=None)
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args(argv)
    records = []
    for rpm in args.rpm:
        response = peer_response(args.mechanism, rpm, elements_per_link=args.elements,
                                 bearings=args.bearings, gravity=args.gravity,
                                 beta_s=args.beta, mass_placement=args.mass_placement,
                                 revolutions=args.revolutions, steps_per_revolution=args.steps)
        linear = linear_response(args.mechanism, rpm, elements_per_link=args.elements,
                                 bearings=args.bearings, gravity=args.gravity)
        p2p = peak_to_peak(response)
        records.append({'rpm': rpm, 'peer_p2p_m': {k: p2p[k] for k in OUTPUT_KEYS},
                        'periodicity': p2p['periodicity'], 'info': response['info'],
                        'linear_vs_peer': compare(response, linear)})
    if args.json:
        print(json.dumps(records, indent=1, default=float))
        return 0
    for rec in records:
        table = rec['linear_vs_peer']
        info = rec['info']
        print(f"{rec['rpm']:g} rpm, {info['bearings']} bearings, gravity {info['gravity']}, "
              f"{info['elements_per_link']} elements per link, {info['revolutions']} "
              f"revolutions, {info['cpu_s']:.1f} CPU s")
        print('  ' + ' '.join(f'{k:>15s}' for k in OUTPUT_KEYS))
        print('  peer p2p [um]  ' + ' '.join(f"{table[k]['peer_p2p'] * 1e6:15.2f}"
                                             for k in OUTPUT_KEYS))
        print('  linear p2p [um]' + ' '.join(f"{table[k]['other_p2p'] * 1e6:15.2f}"
                                             for k in OUTPUT_KEYS))
        print('  linear p2p err ' + ' '.join(f"{100 * table[k]['p2p_error']:14.1f}%"
                                             for k in OUTPUT_KEYS))
        print('  linear rel RMS ' + ' '.join(f"{100 * table[k]['rms_error']:14.1f}%"
                                             for k in OUTPUT_KEYS))
    return 0


__all__ = ['BEARINGS', 'MASS_PLACEMENTS', 'OUTPUT_KEYS', 'EXUDYN_REQUIREMENT', 'PeerModel',
           'exudyn_available', 'lowest_bending_frequency', 'default_revolutions', 'build_peer',
           'peer_response', 'revolution_slice', 'peak_to_peak', 'peer_static', 'linear_model',
           'linear_static', 'linear_response', 'compare', 'main']


if __name__ == '__main__':
    raise SystemExit(main())
