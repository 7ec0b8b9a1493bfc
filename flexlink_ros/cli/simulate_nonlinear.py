"""
``flexlink simulate --nonlinear``: the geometrically nonlinear full order's periodic orbit.

The model of :mod:`core.fe.nonlinear_response` (co-rotational element strain, Kelvin-Voigt
damping on its rate, the rigid-body K_G dropped) with the same model flags as ``simulate``
(crank, bearings, elements, gravity, ``--damping-ratio``, ``--stiffness-damping``, steps,
points, stages). Full order only: ``--method modal`` and ``--second-order`` are refused (the
nonlinear orbit carries the chord shortening itself). JSON: as ``simulate`` (``crank_deg``,
``lever_tip``, ``coupler_mid``, ``peak_to_peak_m``), plus ``linear_peak_to_peak_m`` (the
linear full order with the same damping, the shooting's start), ``floquet_multipliers``
(the 8 largest as [re, im]), ``floquet_spectral_radius``, ``newton_iterations_per_step``
(mean and max over the periodic revolution), ``step_cost_s`` and ``step_cpu_s`` (wall and
CPU time per step), ``revolutions`` marched,
``shooting_updates`` and ``periodicity`` (the last revolution-to-revolution change),
``strain`` (the element strain: corotational), and
``nonlinear_validity`` (:mod:`core.fe.nonlinear_validity`: the orbit's largest element
rotation and its nearest multiplier to +1, whether the model can carry them).
"""

import math
import time

import numpy as np

from .main import emit
from ..core.fe.nonlinear_response import nonlinear_response
from ..core.fe.nonlinear_validity import orbit_validity, validity_record
from ..core.fe.simulate import periodic_response

# Floquet multipliers printed in the JSON (largest modulus first).
MULTIPLIERS_SHOWN = 8


def check_arguments(args):
    """Refuse the flags that have no meaning for the nonlinear full order (ValueError)."""
    if args.method != 'full':
        raise ValueError('--nonlinear is the full order: `--method` must be full')
    if args.second_order is not None or args.check_convergence:
        raise ValueError('--nonlinear takes neither --second-order nor --check-convergence '
                         '(its orbit carries the second-order motion)')


def simulate_nonlinear(args, mech, model, rpm, numbers):
    """
    Run ``simulate --nonlinear``; returns the exit code.

    ``numbers``: 'zeta' (or None), 'points', 'steps', 'stages' as parsed by ``simulate``.
    """
    check_arguments(args)
    started = time.perf_counter()
    speed = rpm * 2.0 * math.pi / 60.0
    kwargs = {'steps': numbers['steps'], 'points': numbers['points'],
              'stages': numbers['stages'], 'zeta': numbers['zeta']}
    linear = periodic_response(model, speed, **kwargs)
    start = np.concatenate([linear.displacement[0], linear.velocity[0]])
    response = nonlinear_response(model, speed, start=start, **kwargs)
    out, info = response.outputs, response.info
    p2p, lin = response.peak_to_peak, linear.peak_to_peak
    shown = response.floquet_multipliers[:MULTIPLIERS_SHOWN]
    result = {'crank_deg': np.mod(np.degrees(response.crank_angle), 360.0),
              'lever_tip': {'dx_m': out[:, 0], 'dy_m': out[:, 1]},
              'coupler_mid': {'dx_m': out[:, 2], 'dy_m': out[:, 3]},
              'peak_to_peak_m': {'lever_tip': p2p[:2], 'coupler_mid': p2p[2:]},
              'linear_peak_to_peak_m': {'lever_tip': lin[:2], 'coupler_mid': lin[2:]},
              'floquet_multipliers': np.stack([shown.real, shown.imag], axis=1),
              'floquet_spectral_radius': info['spectral_radius'],
              'newton_iterations_per_step': {'mean': info['newton_mean'],
                                             'max': info['newton_max']},
              'step_cost_s': info['step_cost_s'], 'step_cpu_s': info['step_cpu_s'],
              'revolutions': info['revolutions'],
              'shooting_updates': info['shooting_updates'],
              'periodicity': info['periodicity'],
              'nonlinear_validity': validity_record(orbit_validity(model, response)),
              'rpm': rpm, 'method': 'full',
              'model': 'nonlinear', 'strain': info['strain'], 'damping_ratio': info['zeta'],
              'stiffness_damping_s': info['stiffness_damping_s'],
              'steps_per_rev': numbers['steps'], 'stages': numbers['stages'],
              'options': numbers['options'], 'mechanism': mech.name,
              'solve_s': info['wall_s'], 'wall_s': time.perf_counter() - started}
    return emit(result, _text(mech, model, args, result), args.json)


def _text(mech, model, args, result):
    """Return the plain-text report (the JSON's figures, in mm)."""
    p2p, lin = result['peak_to_peak_m'], result['linear_peak_to_peak_m']
    p2p = (*p2p['lever_tip'], *p2p['coupler_mid'])
    lin = (*lin['lever_tip'], *lin['coupler_mid'])
    names = ('lever tip dX', 'dY', 'coupler mid dX', 'dY')
    moduli = np.hypot(*np.asarray(result['floquet_multipliers'][:4]).T)
    newton = result['newton_iterations_per_step']
    return (f'{mech.name} at {result["rpm"]:g} rpm, nonlinear full order ({result["strain"]} '
            f'strain), {model.size} DOFs, '
            f'bearings {args.bearings}, rigid crank {args.rigid_crank}, damping zeta '
            f'{result["damping_ratio"]:g} and beta {result["stiffness_damping_s"]:g} s\n'
            'peak-to-peak [mm]: ' + ', '.join(
                f'{name} {1e3 * value:.4f}' for name, value in zip(names, p2p)) + '\n'
            '  linear full order: ' + ', '.join(
                f'{name} {1e3 * value:.4f}' for name, value in zip(names, lin)) + '\n'
            f'Floquet multipliers |mu| {", ".join(f"{m:.4f}" for m in moduli)} (spectral '
            f'radius {result["floquet_spectral_radius"]:.4f}: '
            f'{"stable" if result["floquet_spectral_radius"] < 1.0 else "NOT stable"})\n'
            f'Newton {newton["mean"]:.2f} iterations per step (max {newton["max"]}), '
            f'{1e3 * result["step_cost_s"]:.2f} ms per step ({1e3 * result["step_cpu_s"]:.2f} '
            f'ms CPU), {result["revolutions"]} '
            f'revolutions ({result["shooting_updates"]} shooting updates), periodic to '
            f'{result["periodicity"]:.1e}, wall {result["wall_s"]:.1f} s\n'
            + _validity_line(result['nonlinear_validity']))


def _validity_line(validity):
    """One line: the nonlinear model's validity on this orbit."""
    verdict = 'valid' if validity['valid'] else f"NOT valid: {validity['reason']}"
    return (f"nonlinear validity indicator {validity['indicator']:.2f} (threshold 1; largest "
            f"element rotation {validity['max_element_rotation_rad']:.3f} rad against its "
            f"{validity['rotation_frame']}, nearest "
            f"multiplier {validity['fold_distance']:.3f} from +1): {verdict}")


__all__ = ['check_arguments', 'simulate_nonlinear']
