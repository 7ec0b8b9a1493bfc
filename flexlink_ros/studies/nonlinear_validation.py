"""
The nonlinear full order against the Exudyn peer: ``flexlink validate --nonlinear``.

Per crank speed, in the conventions of :mod:`studies.validation` (rigid crank, prescribed
constant rotation, the peer's bearings and masses, ``elements_per_link`` in both models), the
peer's last revolution against the periodic orbit of the geometrically nonlinear full order
(:func:`core.fe.nonlinear_response.nonlinear_response`), damped as the peer: Kelvin-Voigt
beta on the strain rates (the peer's beta, ``stiffness_damping`` when given) and
``beta k`` on the bearing springs, modal zeta 0 unless ``zeta`` is given. The linear full
order with the same damping is reported beside it. Measures as :mod:`studies.validation`:
per output the p2p error and relative RMS, per output point the deflection vector's relative
RMS; and the orbit's Floquet multipliers, Newton iterations per step and cost per step.

The streaming estimate (:func:`core.estimation.nonlinear_stream.estimate_nonlinear`) is
compared too: the reduced nonlinear model of the same FE model, damped by the same beta,
stepped per sample on a constant-speed crank signal sampled at :data:`STREAM_RATE_HZ` from
rest at crank angle 0 for as many revolutions as the peer marched to settle, its last
revolution interpolated periodically over crank angle onto the full order's output points.
"""

import dataclasses
import math

import numpy as np

from .peer_exudyn import compare, peak_to_peak
from .peer_linear import linear_model
from .peer_model import OUTPUT_KEYS, resolve_mechanism
from .synthetic import last_revolution, synthetic_signal
from .validation import _as_response, BEARINGS, peer_run, point_rms_errors, require_peer, \
    scene_heading, Settings
from ..core.estimation.nonlinear_stream import estimate_nonlinear
from ..core.fe.nonlinear_response import nonlinear_response
from ..core.fe.nonlinear_validity import orbit_validity, validity_record
from ..core.fe.simulate import periodic_response
from ..core.reduction.nonlinear_tables import build_nonlinear_tables

MODELS = ('linear', 'nonlinear', 'streaming')
LABELS = {'linear': 'linear', 'nonlinear': 'nonlinear', 'streaming': 'streaming'}
# The targets for the nonlinear full order against the peer.
TARGETS = {'rms': 0.05, 'p2p': 0.03}
# The streaming estimate's RMS target through the resonance.
STREAM_TARGET_RMS = 0.10
# Package time steps per revolution (a multiple of the output points).
STEPS = 720
# The streaming estimate's sample rate [Hz] (the node's rate).
STREAM_RATE_HZ = 1000.0


def streaming_run(linkage, rpm, beta, revolutions, crank_angle, jitter=0.0, tables=None):
    """
    Stream the reduced nonlinear model at one constant speed; its last turn on the points.

    ``jitter``: each sample interval is (1 + jitter U(-1, 1)) / :data:`STREAM_RATE_HZ`;
    ``tables``: the model when already built for ``linkage`` and ``beta``.

    Returns
    -------
    dict
        'outputs' (P, 4) [m] at ``crank_angle``, 'samples', 'refused', 'newton_per_sample'.

    """
    if tables is None:
        tables = build_nonlinear_tables(linkage, beta)
    seconds = revolutions * 60.0 / rpm
    stamps, angles, speeds = synthetic_signal(rpm, seconds, STREAM_RATE_HZ, jitter=jitter)
    out = estimate_nonlinear(tables, stamps, angles, speeds)
    mask = last_revolution(stamps, rpm)
    phase = np.mod(angles[mask], 2.0 * math.pi)
    values = out['outputs'][mask][:, :len(OUTPUT_KEYS)]
    outputs = np.stack([np.interp(crank_angle, phase, values[:, k], period=2.0 * math.pi)
                        for k in range(values.shape[1])], axis=1)
    return {'outputs': outputs, 'samples': int(len(stamps)), 'refused': int(out['refused']),
            'newton_per_sample': out['newton_iterations'] / max(1, len(stamps) - 1)}


def package_runs(mech, rpm, settings, stream_revolutions=None):
    """
    Linear and nonlinear full order and streaming estimate at one speed, damped as the peer.

    The streaming estimate runs ``stream_revolutions`` (None: the full order's plus two).

    Returns
    -------
    dict
        'crank_angle' (P,), 'linear', 'nonlinear' and 'streaming' outputs (P, 4) [m],
        'streaming_info' (:func:`streaming_run`), 'info' (the nonlinear run's info),
        'multipliers', 'beta', 'zeta', 'validity' (the nonlinear orbit's
        :class:`core.fe.nonlinear_validity.NonlinearValidity`).

    """
    linkage = linear_model(mech, elements_per_link=settings.elements_per_link,
                           bearings=BEARINGS[settings.bearings], gravity=settings.gravity)
    speed = rpm * math.pi / 30.0
    zeta = 0.0 if settings.zeta is None else settings.zeta
    beta = settings.beta_s
    linear = periodic_response(linkage, speed, steps=STEPS, points=settings.points, zeta=zeta,
                               beta=beta)
    start = np.concatenate([linear.displacement[0], linear.velocity[0]])
    nonlinear = nonlinear_response(linkage, speed, steps=STEPS, points=settings.points,
                                   zeta=zeta, beta=beta, start=start)
    if stream_revolutions is None:
        stream_revolutions = nonlinear.info['revolutions'] + 2
    streaming = streaming_run(linkage, rpm, beta, stream_revolutions, linear.crank_angle)
    return {'crank_angle': linear.crank_angle, 'linear': linear.outputs,
            'nonlinear': nonlinear.outputs, 'streaming': streaming['outputs'],
            'streaming_info': {k: v for k, v in streaming.items() if k != 'outputs'},
            'info': nonlinear.info,
            'multipliers': nonlinear.floquet_multipliers, 'beta': beta, 'zeta': zeta,
            'validity': orbit_validity(linkage, nonlinear)}


def validate_nonlinear(mechanism, rpm, settings=None):
    """
    Compare the peer with the linear and the nonlinear full order at one crank speed.

    Parameters
    ----------
    mechanism : Mechanism or str
        A Mechanism, or a mechanism file path or bare name.
    rpm : float
        Crank speed [rpm], positive.
    settings : Settings or None
        What to run (:class:`studies.validation.Settings`; the peer's beta damps both).

    Returns
    -------
    dict
        'rpm', 'mechanism', 'settings', 'peer_p2p', 'periodicity' (peer), 'peer_beta_s',
        'models' (per :data:`MODELS`: per output 'other_p2p', 'p2p_error', 'rms_error'),
        'point_rms_error' (per model and output point), 'targets_met' (nonlinear, per output
        point), 'streaming_targets_met' (per output point), 'streaming' (samples, refused,
        Newton iterations per sample), 'floquet_moduli' (the four largest),
        'spectral_radius', 'newton_mean', 'newton_max', 'step_cost_s', 'step_cpu_s',
        'revolutions', 'wall_s', 'damping',
        'nonlinear_validity' (the orbit's element rotations and fold distance) and 'series'.

    """
    settings = Settings() if settings is None else settings
    if not (math.isfinite(rpm) and rpm > 0.0):
        raise ValueError(f'`rpm` must be a positive crank speed, got {rpm!r}')
    require_peer()
    mech = resolve_mechanism(mechanism)
    peer = peer_run(mech, rpm, settings)
    runs = package_runs(mech, rpm, settings, stream_revolutions=peer['info']['revolutions'])
    models = {name: compare(peer, _as_response(runs['crank_angle'], runs[name]))
              for name in MODELS}
    span = slice(-settings.peer_steps - 1, -1)
    peer_series = {'outputs': np.stack([peer[k][span] for k in OUTPUT_KEYS], axis=1)}
    rms = {name: point_rms_errors(peer_series, {'outputs': runs[name]}) for name in MODELS}
    table = models['nonlinear']
    met = {point: (rms['nonlinear'][point] <= TARGETS['rms']
                   and all(abs(table[f'{point}_{axis}']['p2p_error']) <= TARGETS['p2p']
                           for axis in ('dx', 'dy')))
           for point in ('lever_tip', 'coupler_mid')}
    streaming_met = {point: rms['streaming'][point] <= STREAM_TARGET_RMS
                     for point in ('lever_tip', 'coupler_mid')}
    info, p2p = runs['info'], peak_to_peak(peer)
    return {'rpm': float(rpm), 'mechanism': mech.name,
            'settings': dataclasses.asdict(dataclasses.replace(settings, cache=None)),
            'peer_p2p': {k: p2p[k] for k in OUTPUT_KEYS}, 'periodicity': p2p['periodicity'],
            'peer_beta_s': peer['info']['beta_s'], 'models': models, 'point_rms_error': rms,
            'targets_met': met, 'streaming_targets_met': streaming_met,
            'streaming': runs['streaming_info'],
            'floquet_moduli': [float(x) for x in np.abs(runs['multipliers'][:4])],
            'spectral_radius': info['spectral_radius'], 'newton_mean': info['newton_mean'],
            'newton_max': info['newton_max'], 'step_cost_s': info['step_cost_s'],
            'step_cpu_s': info['step_cpu_s'],
            'revolutions': info['revolutions'], 'wall_s': info['wall_s'],
            'damping': f"beta {runs['beta']:g} s, zeta {runs['zeta']:g}",
            'nonlinear_validity': validity_record(runs['validity']),
            'series': {'crank_deg': np.degrees(runs['crank_angle']), 'peer': peer_series,
                       **{name: runs[name] for name in MODELS}}}


def format_nonlinear(record):
    """Text table of one speed: p2p, p2p error and relative RMS of both models, Floquet."""
    lines = scene_heading(record, f"both damped {record['damping']}", record['peer_beta_s'],
                          26)
    for name in MODELS:
        table = record['models'][name]
        lines.append(f"{LABELS[name] + ' p2p [um]':26s}" + ''.join(
            f"{table[k]['other_p2p'] * 1e6:16.1f}" for k in OUTPUT_KEYS))
        lines.append(f"{LABELS[name] + ' p2p error':26s}" + ''.join(
            f"{100 * table[k]['p2p_error']:15.1f}%" for k in OUTPUT_KEYS))
    for name in MODELS:
        rms = record['point_rms_error'][name]
        lines.append(f"{LABELS[name] + ' vector rel RMS':26s}lever tip "
                     f"{100 * rms['lever_tip']:.1f} %, coupler mid "
                     f"{100 * rms['coupler_mid']:.1f} %")
    met = record['targets_met']
    lines.append(f"nonlinear within {100 * TARGETS['rms']:g} % RMS and {100 * TARGETS['p2p']:g} "
                 f"% p2p: lever tip {'yes' if met['lever_tip'] else 'NO'}, coupler mid "
                 f"{'yes' if met['coupler_mid'] else 'NO'}")
    met = record['streaming_targets_met']
    lines.append(f'streaming within {100 * STREAM_TARGET_RMS:g} % RMS: lever tip '
                 f"{'yes' if met['lever_tip'] else 'NO'}, coupler mid "
                 f"{'yes' if met['coupler_mid'] else 'NO'} ({record['streaming']['samples']} "
                 f'samples at {STREAM_RATE_HZ:g} Hz, '
                 f"{record['streaming']['newton_per_sample']:.2f} Newton per sample, "
                 f"{record['streaming']['refused']} refused)")
    moduli = ', '.join(f'{x:.3f}' for x in record['floquet_moduli'])
    lines.append(f"Floquet multipliers |mu| {moduli}; Newton {record['newton_mean']:.2f} "
                 f"iterations per step (max {record['newton_max']}), "
                 f"{1e3 * record['step_cost_s']:.1f} ms per step "
                 f"({1e3 * record['step_cpu_s']:.1f} ms CPU), "
                 f"{record['revolutions']} revolutions, {record['wall_s']:.0f} s")
    validity = record['nonlinear_validity']
    lines.append('nonlinear validity: largest element rotation '
                 f"{validity['max_element_rotation_rad']:.3f} rad, nearest multiplier "
                 f"{validity['fold_distance']:.3f} from +1: "
                 + ('valid' if validity['valid'] else f"NOT valid ({validity['reason']})"))
    return '\n'.join(lines)


def without_series(record):
    """Return the record as ``--json`` prints it (no sample series)."""
    return {key: value for key, value in record.items() if key != 'series'}


__all__ = ['MODELS', 'TARGETS', 'STEPS', 'STREAM_RATE_HZ', 'STREAM_TARGET_RMS',
           'streaming_run', 'package_runs', 'validate_nonlinear',
           'format_nonlinear', 'without_series']
