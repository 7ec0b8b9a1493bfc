"""
``flexlink modes`` and ``flexlink simulate``: the flexible four-bar FE model of Cho 1992.

    flexlink modes --mechanism config/cho1992.yaml --crank-deg 0:360:5 --count 3
                   [--speed-rad-s 30] [--rigid-crank] [--bearings rigid|flexible]
                   [--elements-per-link N] [--no-geometric-stiffness] [--no-gravity]
                   [--centrifugal] [--shapes] [--json]
    flexlink simulate --mechanism config/cho1992.yaml --rpm 391 [--rigid-crank]
                   [--bearings rigid|flexible] [--method full|modal] [--modes N]
                   [--static-correction] [--damping-ratio Z] [--stiffness-damping BETA_S]
                   [--points-per-rev P] [--steps-per-rev S] [--check-convergence]
                   [--order 1|2] [--second-order dynamic|quasi-static] [--nonlinear] [--json]

``modes`` JSON: ``crank_deg``, ``frequencies_hz`` (per angle, per mode), ``dominant_link``,
``strain_share`` (crank, coupler, lever, springs), ``range_hz`` (min and max per mode),
optional ``shapes``. ``simulate`` JSON: ``crank_deg``, ``lever_tip`` and ``coupler_mid``
(``dx_m``, ``dy_m``: ground-frame elastic deflection over one steady revolution),
``peak_to_peak_m``, ``floquet_spectral_radius``, ``damping_ratio``, ``stiffness_damping_s``
(beta [s]), ``nonlinearity`` (``indicator_max``, ``valid``, ``threshold``: the validity
indicator of core/validity.py over the revolution of the linear response), ``wall_s``,
optional ``convergence``, ``order`` and, at order 2 (the default), ``second_order`` and
``linear_peak_to_peak_m``: the outputs are the linear response plus its second-order part,
by the dynamic pass (:func:`core.fe.second_order_dynamic.dynamic_pass`, ``--method full``) or
quasi-static (:func:`core.fe.second_order_full.corrected_response`, the estimator's; for the
modal response from its reconstructed nodal vectors); the convergence check is of the linear
response. ``--nonlinear``: the geometrically nonlinear full order instead
(:mod:`cli.simulate_nonlinear`, which documents its JSON).
"""

import dataclasses
import math
import time

import numpy as np

from .main import degree_range, emit
from .model_args import add_model_arguments, add_order_argument, \
    add_stiffness_damping_argument, stiffness_damping
from .simulate_nonlinear import simulate_nonlinear
from ..core import validity
from ..core.fe import linkage as assembly, modes, simulate
from ..core.fe.second_order_dynamic import dynamic_pass, MIN_POINTS
from ..core.fe.second_order_full import corrected_response
from ..core.mechanism_file import load_mechanism
from ..core.options import ModelOptions
from ..errors import FlexlinkError


def _model_arguments(parser):
    # The FE studies' defaults: rigid bearings, flexible crank (--elements: old spelling).
    add_model_arguments(parser, 'rigid', 'the mechanism file', elements_alias=True)
    parser.add_argument('--no-gravity', action='store_true', help='leave out gravity')
    parser.add_argument('--json', action='store_true', help='print one JSON object')


def register(subparsers):
    """Add the `modes` and `simulate` subcommands."""
    parser = subparsers.add_parser('modes', help='frozen natural frequencies and modes over '
                                                 'crank angles (Cho 1992 FE model)')
    _model_arguments(parser)
    parser.add_argument('--crank-deg', type=degree_range, default=degree_range('0:360:5'),
                        help='crank angles, START:STOP:STEP or a comma list (default 0:360:5)')
    parser.add_argument('--count', default='3', help='number of modes (default 3)')
    parser.add_argument('--speed-rad-s', default='0',
                        help='crank speed of the axial forces in K_G [rad/s] (default 0)')
    parser.add_argument('--accel-rad-s2', default='0',
                        help='crank acceleration of the axial forces [rad/s^2] (default 0)')
    parser.add_argument('--centrifugal', action='store_true',
                        help='add the symmetric part of K_c (off in the paper)')
    parser.add_argument('--shapes', action='store_true',
                        help='include ground-frame mode shapes (8 points per element)')
    parser.set_defaults(func=modes_command)

    parser = subparsers.add_parser('simulate', help='periodic elastic response at constant '
                                                    'crank speed (full order or modal)')
    _model_arguments(parser)
    parser.add_argument('--rpm', default='391', help='crank speed [rpm] (default 391)')
    parser.add_argument('--method', default='full', help='full (default) or modal')
    parser.add_argument('--modes', default=None, help='modes kept by the modal method')
    parser.add_argument('--static-correction', action='store_true',
                        help='add the residual flexibility of the discarded modes (modal)')
    parser.add_argument('--damping-ratio', default=None,
                        help='modal damping ratio (default: the mechanism file)')
    add_stiffness_damping_argument(parser)
    parser.add_argument('--points-per-rev', default=str(simulate.DEFAULT_POINTS),
                        help=f'output points per revolution (default {simulate.DEFAULT_POINTS})')
    parser.add_argument('--steps-per-rev', default=str(simulate.DEFAULT_STEPS),
                        help='time steps per revolution, a multiple of the points '
                             f'(default {simulate.DEFAULT_STEPS})')
    parser.add_argument('--stages', default=str(simulate.DEFAULT_STAGES),
                        help='Radau IIA stages: 2 (order 3, default) or 3 (order 5)')
    parser.add_argument('--check-convergence', action='store_true',
                        help='also report the error at 1/4, 1/2 and 1x the steps against 4x')
    add_order_argument(parser)
    parser.add_argument('--second-order', choices=SECOND_ORDER_KINDS, default=None,
                        help='how order 2 is computed: dynamic (one more solve loaded by the '
                        'second-order terms, so their motion carries its inertia; --method '
                        'full, at least 24 points per revolution) or quasi-static (the '
                        "estimator's correction) (default: dynamic where it applies)")
    parser.add_argument('--nonlinear', action='store_true',
                        help='the geometrically nonlinear full order (von Karman element '
                        'strain, damping on its rate): periodic orbit by shooting, with its '
                        'Floquet multipliers')
    parser.set_defaults(func=simulate_command)


def _number(text, name, integer=False, positive=True, allow_zero=False):
    try:
        value = int(text) if integer else float(text)
    except (TypeError, ValueError):
        kind = 'an integer' if integer else 'a number'
        raise ValueError(f'`--{name}` must be {kind}, got {text!r}') from None
    if not math.isfinite(value) or (positive and (value < 0 or (value == 0 and not allow_zero))):
        raise ValueError(f'`--{name}` must be {"positive" if not allow_zero else ">= 0"}, '
                         f'got {text!r}')
    return value


def build_model(args):
    """
    Build the mechanism and its FlexibleLinkage from the common arguments.

    Parameters
    ----------
    args : argparse.Namespace
        The model flags (:func:`cli.model_args.add_model_arguments`) and ``no_gravity``.

    Returns
    -------
    mech : Mechanism
    model : FlexibleLinkage

    """
    mech = load_mechanism(args.mechanism)
    if args.elements_per_link is not None:
        mech = dataclasses.replace(mech, elements_per_link=_number(
            args.elements_per_link, 'elements-per-link', integer=True))
    if args.bearings not in assembly.BEARING_MODELS:
        raise ValueError(f'`--bearings` must be one of {", ".join(assembly.BEARING_MODELS)}, '
                         f'got {args.bearings!r}')
    options = ModelOptions.full_model(rigid_crank=args.rigid_crank, bearings=args.bearings,
                                      geometric_stiffness=not args.no_geometric_stiffness,
                                      gravity=not args.no_gravity,
                                      stiffness_damping=stiffness_damping(args))
    return mech, assembly.FlexibleLinkage(mech, options)


def _options_record(model):
    opts = model.options
    return {'rigid_crank': opts.rigid_crank, 'bearings': opts.bearings,
            'geometric_stiffness': opts.geometric_stiffness, 'gravity': opts.gravity,
            'elements_per_link': model.mechanism.elements_per_link, 'dofs': model.size}


def _guard_geometric(function, *args, **kwargs):
    try:
        return function(*args, **kwargs)
    except ImportError as exc:
        raise FlexlinkError(f'the geometric stiffness needs the rigid-body analysis '
                            f'(core/dynamics.py), which is not available ({exc}); '
                            'use --no-geometric-stiffness') from exc


def modes_command(args):
    """Frozen eigen-analysis over crank angles; returns the exit code."""
    started = time.perf_counter()
    mech, model = build_model(args)
    count = _number(args.count, 'count', integer=True)
    speed = _number(args.speed_rad_s, 'speed-rad-s', positive=False)
    accel = _number(args.accel_rad_s2, 'accel-rad-s2', positive=False)
    angles = np.radians(np.asarray(args.crank_deg, dtype=float))
    system = _guard_geometric(model.assemble, angles)
    result_modes = modes.solve_frozen_modes(system, count, speed, accel, args.centrifugal)
    freqs = result_modes.frequencies_hz
    result = {'crank_deg': list(args.crank_deg), 'frequencies_hz': freqs,
              'dominant_link': result_modes.dominant_link_names,
              'strain_share': result_modes.strain_share,
              'range_hz': {'min': freqs.min(axis=0), 'max': freqs.max(axis=0)},
              'speed_rad_s': speed, 'accel_rad_s2': accel, 'centrifugal': args.centrifugal,
              'options': _options_record(model), 'mechanism': mech.name}
    if args.shapes:
        positions, operator = model.shape_operator(angles)
        deflection = np.einsum('klpcn,knm->kmlpc', operator, result_modes.shapes)
        result['shapes'] = {'positions_m': positions, 'deflection_per_unit_modal_m': deflection,
                            'layout': 'angle, [mode,] link, point, (x, y)'}
    result['wall_s'] = time.perf_counter() - started
    lines = [f'{mech.name}: frozen modes, {model.size} DOFs, bearings {args.bearings}, '
             f'rigid crank {args.rigid_crank}, K_G {not args.no_geometric_stiffness}, '
             f'speed {speed:g} rad/s']
    lines.append('crank deg  ' + '  '.join(f'f{i + 1} [Hz] (link)' for i in range(count)))
    for deg, row, names in zip(args.crank_deg, freqs, result_modes.dominant_link_names):
        lines.append(f'{deg:9.2f}  ' + '  '.join(f'{f:9.3f} ({name})'
                                                 for f, name in zip(row, names)))
    return emit(result, '\n'.join(lines), args.json)


def nonlinearity_line(summary):
    """Say the validity indicator's verdict in one line of text."""
    if summary['valid'] is None:
        return 'nonlinearity indicator: not available for this model'
    verdict = 'valid' if summary['valid'] else 'NOT valid (amplitude-dependent detuning)'
    return (f'nonlinearity indicator max {summary["indicator_max"]:.3g} (threshold '
            f'{summary["threshold"]:g}): linear estimate {verdict}')


SECOND_ORDER_KINDS = ('dynamic', 'quasi-static')


def _ordered_outputs(model, response, args, steps, stages):
    """Return the outputs of ``args.order`` (2: plus the second order) and their JSON entries."""
    if args.order == 1:
        return response.outputs, {'order': 1}
    kind = args.second_order
    if kind is None:
        full = response.info['method'] == 'full' and len(response.crank_angle) >= MIN_POINTS
        kind = 'dynamic' if full else 'quasi-static'
    if kind == 'dynamic':
        total = dynamic_pass(model, response, steps=steps, stages=stages)['total']
    else:
        total = corrected_response(model, response)['total']
    linear = response.peak_to_peak
    return total, {'order': 2, 'second_order': kind,
                   'linear_peak_to_peak_m': {'lever_tip': linear[:2], 'coupler_mid': linear[2:]}}


def simulate_command(args):
    """Periodic steady-state response at constant speed; returns the exit code."""
    started = time.perf_counter()
    mech, model = build_model(args)
    rpm = _number(args.rpm, 'rpm')
    method = args.method
    if method not in simulate.METHODS:
        raise ValueError(f'`--method` must be one of {", ".join(simulate.METHODS)}, '
                         f'got {method!r}')
    count = None if args.modes is None else _number(args.modes, 'modes', integer=True)
    if method == 'modal' and count is None:
        raise ValueError('`--modes` is required with --method modal')
    zeta = (None if args.damping_ratio is None
            else _number(args.damping_ratio, 'damping-ratio', allow_zero=True))
    points = _number(args.points_per_rev, 'points-per-rev', integer=True)
    steps = _number(args.steps_per_rev, 'steps-per-rev', integer=True)
    stages = _number(args.stages, 'stages', integer=True)
    if args.nonlinear:
        return simulate_nonlinear(args, mech, model, rpm, {
            'zeta': zeta, 'points': points, 'steps': steps, 'stages': stages,
            'options': _options_record(model)})
    speed = rpm * 2.0 * math.pi / 60.0
    kwargs = {'method': method, 'modes': count, 'static_correction': args.static_correction,
              'stages': stages, 'zeta': zeta}
    response = _guard_geometric(simulate.periodic_response, model, speed, steps=steps,
                                points=points, **kwargs)
    out, extra = _ordered_outputs(model, response, args, steps, stages)
    p2p = out.max(axis=0) - out.min(axis=0)
    result = {'crank_deg': np.mod(np.degrees(response.crank_angle), 360.0),
              'lever_tip': {'dx_m': out[:, 0], 'dy_m': out[:, 1]},
              'coupler_mid': {'dx_m': out[:, 2], 'dy_m': out[:, 3]},
              'peak_to_peak_m': {'lever_tip': p2p[:2], 'coupler_mid': p2p[2:]},
              'floquet_spectral_radius': response.info['spectral_radius'],
              'rpm': rpm, 'method': method, 'modes': count,
              'static_correction': args.static_correction,
              'damping_ratio': response.info['zeta'],
              'stiffness_damping_s': response.info['stiffness_damping_s'], 'steps_per_rev': steps,
              'stages': stages, 'options': _options_record(model), 'mechanism': mech.name,
              'solve_s': response.info['wall_s'],
              'nonlinearity': validity.is_valid(validity.nonlinearity_indicator(
                  model, response.displacement, response.crank_angle, speed,
                  zeta=response.info['zeta'])), **extra}
    if args.check_convergence:
        if steps % 4:
            raise ValueError('--check-convergence needs steps-per-rev divisible by 4')
        # compared at the output points common to every run
        result['convergence'] = simulate.step_convergence(
            model, speed, steps=(steps // 4, steps // 2, steps), reference_steps=4 * steps,
            points=math.gcd(steps // 4, points), **kwargs)
    result['wall_s'] = time.perf_counter() - started
    return emit(result, _simulate_text(mech, model, args, result), args.json)


def _simulate_text(mech, model, args, result):
    """Return the plain-text report of ``simulate`` (the JSON's figures, in mm)."""
    p2p, count = result['peak_to_peak_m'], result['modes']
    p2p = (*p2p['lever_tip'], *p2p['coupler_mid'])
    text = (f'{mech.name} at {result["rpm"]:g} rpm, {result["method"]}'
            + (f' ({count} modes{", static correction" if args.static_correction else ""})'
               if result['method'] == 'modal' else '')
            + f', {model.size} DOFs, bearings {args.bearings}, rigid crank {args.rigid_crank}'
            + (f', stiffness damping {model.options.stiffness_damping:g} s'
               if model.options.stiffness_damping else '')
            + f', order {args.order}' + (f' ({result["second_order"]})' if args.order == 2 else '')
            + '\n'
            f'peak-to-peak [mm]: lever tip dX {1e3 * p2p[0]:.4f} dY {1e3 * p2p[1]:.4f}, '
            f'coupler mid dX {1e3 * p2p[2]:.4f} dY {1e3 * p2p[3]:.4f}\n'
            f'Floquet spectral radius {result["floquet_spectral_radius"]:.4f}, '
            f'wall {result["wall_s"]:.2f} s\n' + nonlinearity_line(result['nonlinearity']))
    if 'convergence' in result:
        conv = result['convergence']
        text += ('\nstep check: max error [m] ' + ', '.join(
            f'{s}: {e:.3g}' for s, e in zip(conv['steps'], conv['max_error_m']))
            + ' (observed order ' + ', '.join(f'{o:.2f}' for o in conv['observed_order']) + ')')
    return text
