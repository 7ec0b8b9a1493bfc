"""
The package's full-order model against the nonlinear Exudyn peer: ``flexlink validate``.

Per crank speed (rigid crank, prescribed constant rotation, the peer's conventions:
:mod:`studies.peer_exudyn`) it runs the peer and the package's full-order model, and compares
over one steady revolution, per output (lever tip dX / dY, coupler mid-point dX / dY):

* ``linear``: the linear KED of Cho, Park & Lee (1992) (:func:`core.fe.simulate.periodic_response`,
  geometric stiffness on, modal zeta of the mechanism unless given);
* ``second_order``: the same plus the quasi-static second-order motion
  (:func:`core.fe.second_order_full.corrected_response`);
* ``dynamic``: the linear state plus the dynamic second-order pass
  (:func:`core.fe.second_order_dynamic.dynamic_pass`).

Each is reported as its peak-to-peak, its p2p error against the peer's and its RMS difference
relative to the peer's RMS (:func:`studies.peer_exudyn.compare`). With several speeds (a sweep)
the record also holds the validity indicator of :mod:`core.validity` (computed from the linear
response alone, as the node does) and whether the second order meets the accuracy targets, so
that the table shows where the flag turns and whether it turns where the errors grow.

Bearings: ``rigid`` are exact pins in both models; ``flexible`` are the mechanism's bearing
springs, with the peer's joint masses split as the mechanism file says (the linear model's
convention) and the crank pivot rigid. The peer damps with beta = 1e-4 s on the material strain
rates, the package with modal zeta (0.02 by default; ``zeta`` = 0.012 matches the peer's first
modes); with ``stiffness_damping`` beta both are damped with that beta. Peer runs can be kept
in a cache directory (keyed by all their settings).
"""

import dataclasses
import hashlib
import json
import math
import os

import numpy as np

from .peer_exudyn import compare, peak_to_peak, peer_response, revolution_slice
from .peer_linear import linear_model
from .peer_model import (DEFAULT_BETA_S, DEFAULT_ELEMENTS, DEFAULT_STEPS, exudyn_available,
                         EXUDYN_REQUIREMENT, OUTPUT_KEYS, resolve_mechanism)
from ..core.fe.linkage import FlexibleLinkage
from ..core.fe.second_order_dynamic import dynamic_pass
from ..core.fe.second_order_full import corrected_response
from ..core.fe.simulate import periodic_response
from ..core.fe.stiffness_damping import system_matrices
from ..core.options import ModelOptions
from ..core.reduction.cache_location import cache_file
from ..core.validity import is_valid, nonlinearity_indicator, VALIDITY_THRESHOLD
from ..errors import FlexlinkError

PEERS = ('exudyn',)
# The package's bearing names and the peer's.
BEARINGS = {'rigid': 'rigid', 'flexible': 'springs'}
MODELS = ('linear', 'second_order', 'dynamic')
MODEL_LABELS = {'linear': 'linear', 'second_order': 'linear + 2nd order',
                'dynamic': '+ dynamic pass', 'peer': 'Exudyn peer'}
# The p2p targets against the peer (lever tip, coupler mid-point), for linear + 2nd.
TARGETS = {'lever_tip': 0.10, 'coupler_mid': 0.03}
DEFAULT_POINTS = DEFAULT_STEPS
LABELS = dict(zip(OUTPUT_KEYS, ('lever tip dX', 'lever tip dY', 'coupler mid dX',
                                'coupler mid dY')))


@dataclasses.dataclass(frozen=True)
class Settings:
    """What one comparison runs (see :func:`validate_speed`)."""

    elements_per_link: int = DEFAULT_ELEMENTS
    bearings: str = 'rigid'
    gravity: bool = True
    zeta: float = None
    revolutions: int = None
    peer_steps: int = DEFAULT_STEPS
    points: int = DEFAULT_POINTS
    beta_s: float = None
    stiffness_damping: float = None
    cache: str = None

    def __post_init__(self):
        """Check the settings (ValueError names the bad one); the peer's beta as asked."""
        if self.beta_s is None:
            # the peer is damped as the package: its own default only under modal damping
            peer_beta = (DEFAULT_BETA_S if self.stiffness_damping is None
                         else self.stiffness_damping)
            object.__setattr__(self, 'beta_s', float(peer_beta))
        if self.bearings not in BEARINGS:
            raise ValueError(f'`bearings` must be one of {tuple(BEARINGS)}, '
                             f'got {self.bearings!r}')
        if self.elements_per_link < 1:
            raise ValueError('`elements_per_link` must be >= 1')
        if self.stiffness_damping is not None and not self.stiffness_damping > 0.0:
            raise ValueError('`stiffness_damping` must be a positive beta [s]')
        if self.peer_steps % self.points or DEFAULT_STEPS % self.points:
            raise ValueError(f'`points` ({self.points}) must divide {DEFAULT_STEPS} and the '
                             f'peer steps ({self.peer_steps})')


def require_peer(peer='exudyn'):
    """Raise FlexlinkError, saying how to install it, when the peer cannot run."""
    if peer not in PEERS:
        raise ValueError(f'`--peer` must be one of {", ".join(PEERS)}, got {peer!r}')
    if not exudyn_available():
        raise FlexlinkError(
            'the Exudyn peer is not installed; it is an optional extra: '
            f"`pip install '.[peer]'` in the source tree (or `pip install {EXUDYN_REQUIREMENT}`)")


def _cache_name(cache, mech, rpm, settings):
    """File of a peer run in the cache directory: a hash of every setting that changes it."""
    key = repr((mech, float(rpm), settings.elements_per_link, settings.bearings,
                settings.gravity, settings.beta_s, settings.revolutions, settings.peer_steps))
    digest = hashlib.sha1(key.encode()).hexdigest()
    return str(cache_file(cache, f'peer_{mech.name}_{rpm:g}rpm', digest))


def peer_run(mech, rpm, settings):
    """Run the peer at one speed (or load it from ``settings.cache``)."""
    name = _cache_name(settings.cache, mech, rpm, settings) if settings.cache else None
    if name and os.path.exists(name):
        with np.load(name) as data:
            out = {key: data[key] for key in data.files if key != 'info'}
            out['info'] = json.loads(str(data['info']))
        return out
    bearings = BEARINGS[settings.bearings]
    out = peer_response(mech, rpm, elements_per_link=settings.elements_per_link,
                        bearings=bearings, gravity=settings.gravity, beta_s=settings.beta_s,
                        mass_placement='split' if bearings == 'springs' else 'coupler-end',
                        revolutions=settings.revolutions,
                        steps_per_revolution=settings.peer_steps)
    if name:
        os.makedirs(settings.cache, exist_ok=True)
        np.savez(name, **{k: v for k, v in out.items() if k != 'info'},
                 info=json.dumps(out['info']))
    return out


def package_runs(mech, rpm, settings):
    """
    Run the package's three models at one speed, and the validity indicator per sample.

    Returns
    -------
    dict
        'crank_angle' (P,), per :data:`MODELS` the outputs (P, 4) [m], 'indicator' (P,),
        'zeta' (the indicator's), 'damping' (text), 'wall_s' (linear and dynamic pass).

    """
    linkage = linear_model(mech, elements_per_link=settings.elements_per_link,
                           bearings=BEARINGS[settings.bearings], gravity=settings.gravity)
    speed = rpm * math.pi / 30.0
    matrices = None
    if settings.stiffness_damping is not None:
        beta = settings.stiffness_damping
        matrices = lambda angles: system_matrices(linkage, angles, speed, beta)  # noqa: E731
    linear = periodic_response(linkage, speed, method='full', points=settings.points,
                               zeta=settings.zeta, matrices=matrices)
    quasi_static = corrected_response(linkage, linear)
    dynamic = dynamic_pass(linkage, linear, matrices=matrices)
    # with beta damping the indicator's resonance floor keeps the modal zeta (given or file)
    zeta = linear.info['zeta'] if matrices is None else (
        mech.damping_ratio if settings.zeta is None else settings.zeta)
    damping = (f'modal zeta {zeta:g}' if matrices is None
               else f'beta {settings.stiffness_damping:g} s')
    indicator = nonlinearity_indicator(linkage, linear.displacement, linear.crank_angle, speed,
                                       zeta=zeta)
    return {'crank_angle': linear.crank_angle, 'linear': linear.outputs,
            'second_order': quasi_static['total'], 'dynamic': dynamic['total'],
            'indicator': indicator, 'zeta': zeta, 'damping': damping,
            'wall_s': {'linear': linear.info['wall_s'], 'dynamic': dynamic['info']['wall_s']}}


def flexible_crank_check(mechanism, rpm, settings, rigid_outputs):
    """
    Compare the node's crank model (a flexible beam) with this comparison's rigid crank.

    The peer's crank is rigid, the node's and ``flexlink estimate``'s is not: a long or slender
    crank's bending then moves every output and the peer cannot check it. The package's linear
    full order with the flexible crank, the comparison's other settings, says by how much.

    Parameters
    ----------
    mechanism : Mechanism or str
        The linkage, or a mechanism file path or bare name.
    rpm : float
        Crank speed [rpm].
    settings : Settings
        The comparison's elements, bearings, gravity, damping and output points.
    rigid_outputs : ndarray, shape (P, 4)
        The rigid-crank linear outputs of :func:`package_runs` [m].

    Returns
    -------
    dict
        'p2p' and 'ratio' (flexible over rigid crank) per output, 'differs' (a ratio off 1 by
        more than the lever tip's target of :data:`TARGETS`).

    """
    mech = dataclasses.replace(resolve_mechanism(mechanism),
                               elements_per_link=settings.elements_per_link)
    options = ModelOptions.full_model(rigid_crank=False, bearings=settings.bearings,
                                      geometric_stiffness=True, gravity=settings.gravity)
    response = periodic_response(FlexibleLinkage(mech, options), rpm * math.pi / 30.0,
                                 method='full', points=settings.points, zeta=settings.zeta)
    flexible = np.ptp(response.outputs, axis=0)
    rigid = np.maximum(np.ptp(np.asarray(rigid_outputs), axis=0), 1e-300)
    ratio = dict(zip(OUTPUT_KEYS, (flexible / rigid).tolist()))
    return {'p2p': dict(zip(OUTPUT_KEYS, flexible.tolist())), 'ratio': ratio,
            'differs': any(abs(r - 1.0) > TARGETS['lever_tip'] for r in ratio.values())}


def format_crank(check):
    """One line where the node's flexible crank differs from the peer's rigid one, else ''."""
    if not check['differs']:
        return ''
    p2p = ' / '.join(f"{check['p2p'][k] * 1e6:.3g}" for k in OUTPUT_KEYS)
    worst = max(check['ratio'].values(), key=lambda r: abs(math.log(max(r, 1e-300))))
    return (f"crank: the peer's is rigid, the node's and estimate's bend (flexible crank, "
            f'their default): with it the package gives p2p {p2p} um ({worst:.3g} times the '
            "rigid crank's at worst); the crank's bending is not checked here")


def _as_response(angles, values):
    out = {'crank_angle': angles}
    out.update(zip(OUTPUT_KEYS, np.asarray(values).T))
    return out


def point_rms_errors(peer, other):
    """
    RMS of the deflection-vector difference per output point, relative to the peer's RMS.

    ``sqrt(mean(|d - d_peer|^2) / mean(|d_peer|^2))`` with d = (dX, dY) of the lever tip and
    of the coupler mid-point, the peer taken on the other's grid (series of
    :func:`validate_speed`: the other's samples are a subset of the peer's).
    """
    stride = peer['outputs'].shape[0] // other['outputs'].shape[0]
    mine = peer['outputs'][::stride]
    out = {}
    for index, point in enumerate(TARGETS):
        cols = slice(2 * index, 2 * index + 2)
        out[point] = float(np.sqrt(np.sum((other['outputs'][:, cols] - mine[:, cols]) ** 2)
                                   / np.sum(mine[:, cols] ** 2)))
    return out


def meets_targets(table):
    """Whether a :func:`compare` table is within :data:`TARGETS` (p2p), per output point."""
    return {point: all(abs(table[f'{point}_{axis}']['p2p_error']) <= limit
                       for axis in ('dx', 'dy')) for point, limit in TARGETS.items()}


def validate_speed(mechanism, rpm, settings=None):
    """
    Peer against linear, linear + second order and the dynamic pass at one crank speed.

    Parameters
    ----------
    mechanism : Mechanism or str
        A Mechanism, or a mechanism file path or bare name.
    rpm : float
        Crank speed [rpm], positive.
    settings : Settings or None
        What to run (default :class:`Settings`).

    Returns
    -------
    dict
        'rpm', 'settings', 'peer_p2p' (per output [m]), 'periodicity' (peer), 'models' (per
        :data:`MODELS`: per output 'other_p2p' [m], 'p2p_error', 'rms_error'), 'targets_met'
        (per model and output point), 'point_rms_error' (per model and output point: the
        deflection vector's relative RMS), 'nonlinearity' ({'indicator_max', 'valid'}),
        'threshold', 'zeta', 'damping', 'peer_beta_s' (the peer's beta [s]), 'peer_cpu_s',
        'crank' (:func:`flexible_crank_check`: the node's flexible crank against the rigid one
        compared here), 'wall_s', and 'series' (for charts: crank angle [deg] and outputs [m]
        of the peer's last revolution and of every model).

    """
    settings = Settings() if settings is None else settings
    if not (math.isfinite(rpm) and rpm > 0.0):
        raise ValueError(f'`rpm` must be a positive crank speed, got {rpm!r}')
    require_peer()
    mech = resolve_mechanism(mechanism)
    peer = peer_run(mech, rpm, settings)
    runs = package_runs(mech, rpm, settings)
    models = {name: compare(peer, _as_response(runs['crank_angle'], runs[name]))
              for name in MODELS}
    p2p = peak_to_peak(peer)
    span = revolution_slice(peer)
    # whole revolutions from the package's revolution to the peer's last one
    turns = 2.0 * math.pi * np.round((peer['crank_angle'][span.start]
                                      - runs['crank_angle'][0]) / (2.0 * math.pi))
    series = {'peer': {'crank_deg': np.degrees(peer['crank_angle'][span] - turns),
                       'outputs': np.stack([peer[k][span] for k in OUTPUT_KEYS], axis=1)}}
    series.update({name: {'crank_deg': np.degrees(runs['crank_angle']),
                          'outputs': runs[name]} for name in MODELS})
    return {'rpm': float(rpm), 'mechanism': mech.name,
            'settings': dataclasses.asdict(dataclasses.replace(settings, cache=None)),
            'peer_p2p': {k: p2p[k] for k in OUTPUT_KEYS}, 'periodicity': p2p['periodicity'],
            'models': models,
            'point_rms_error': {name: point_rms_errors(series['peer'], series[name])
                                for name in MODELS},
            'targets_met': {name: meets_targets(table) for name, table in models.items()},
            'nonlinearity': is_valid(runs['indicator']), 'threshold': VALIDITY_THRESHOLD,
            'zeta': runs['zeta'], 'damping': runs['damping'],
            'peer_beta_s': peer['info']['beta_s'], 'peer_cpu_s': peer['info']['cpu_s'],
            'crank': flexible_crank_check(mech, rpm, settings, runs['linear']),
            'wall_s': runs['wall_s'], 'series': series}


def flag_turns(records):
    """
    Where the validity flag changes between consecutive speeds of a sweep.

    Returns
    -------
    list of dict
        'from_rpm', 'to_rpm', 'valid' (the flag at ``to_rpm``).

    """
    out = []
    ordered = sorted(records, key=lambda r: r['rpm'])
    for before, after in zip(ordered, ordered[1:]):
        if before['nonlinearity']['valid'] != after['nonlinearity']['valid']:
            out.append({'from_rpm': before['rpm'], 'to_rpm': after['rpm'],
                        'valid': after['nonlinearity']['valid']})
    return out


def sweep_speeds(text):
    """
    Parse a sweep 'START:STOP:STEP' [rpm] (STOP included when it lies on the grid).

    Returns
    -------
    list of float

    """
    try:
        start, stop, step = (float(part) for part in text.split(':'))
    except ValueError:
        raise ValueError(f'`--sweep` must be START:STOP:STEP in rpm, got {text!r}') from None
    if not (step > 0.0 and 0.0 < start <= stop):
        raise ValueError(f'`--sweep` needs 0 < START <= STOP and STEP > 0, got {text!r}')
    count = int(math.floor((stop - start) / step + 1e-9)) + 1
    return [start + k * step for k in range(count)]


def without_series(record):
    """Return the record as ``--json`` prints it (no sample series)."""
    return {key: value for key, value in record.items() if key != 'series'}


def _worst(table, point, kind='p2p_error'):
    """Return the worse (by magnitude) of an output point's dX / dY entries."""
    return max((table[f'{point}_{axis}'][kind] for axis in ('dx', 'dy')), key=abs)


def scene_heading(record, damping, peer_beta_s, width):
    """Return the first lines of one speed's table: the scene, the outputs, the peer's p2p."""
    s = record['settings']
    return [f"{record['rpm']:g} rpm, {s['bearings']} bearings, gravity "
            f"{'on' if s['gravity'] else 'off'}, {s['elements_per_link']} elements per link, "
            f"rigid crank ({record['mechanism']}; {damping}, peer beta {peer_beta_s:g} s)",
            f"{'':{width}s}" + ''.join(f'{LABELS[k]:>16s}' for k in OUTPUT_KEYS),
            f"{'Exudyn peer p2p [um]':{width}s}" + ''.join(
                f"{record['peer_p2p'][k] * 1e6:16.1f}" for k in OUTPUT_KEYS)]


def format_speed(record):
    """Text table of one speed: the peer's p2p and each model's p2p, p2p error and rel RMS."""
    info = record['nonlinearity']
    lines = scene_heading(record, f"package {record['damping']}",
                          record['settings']['beta_s'], 30)
    for name in MODELS:
        table = record['models'][name]
        rows = (('other_p2p', ' p2p [um]', 1e6), ('p2p_error', ' p2p error', 100.0),
                ('rms_error', ' rel RMS', 100.0))
        for kind, unit, scale in rows:
            cells = ''.join(f'{table[k][kind] * scale:16.1f}' if scale == 1e6
                            else f'{table[k][kind] * scale:15.1f}%' for k in OUTPUT_KEYS)
            lines.append(f'{MODEL_LABELS[name] + unit:30s}' + cells)
    lines.append(f"{'vector rel RMS (tip ; mid)':30s}" + '   '.join(
        f"{MODEL_LABELS[name]} {100 * record['point_rms_error'][name]['lever_tip']:.1f}"
        f" ; {100 * record['point_rms_error'][name]['coupler_mid']:.1f} %" for name in MODELS))
    lines.append(f"validity indicator {info['indicator_max']:.3f} (threshold "
                 f"{record['threshold']:g}): {'valid' if info['valid'] else 'NOT valid'}")
    crank = format_crank(record['crank']) if 'crank' in record else ''
    return '\n'.join(lines + ([crank] if crank else []))


def format_sweep(records):
    """Text table of a sweep: worst p2p error per point and model, the indicator and flag."""
    short = {'linear': 'lin', 'second_order': '2nd', 'dynamic': 'dyn'}
    head = (f"{'rpm':>6s}  " + ''.join(f"{'tip ' + short[m]:>9s}" for m in MODELS)
            + ''.join(f"{'mid ' + short[m]:>9s}" for m in MODELS)
            + f"{'mid RMS 2nd':>12s}{'mid RMS dyn':>12s}"
            + f"{'I max':>8s} {'valid':>5s} {'2nd in targets':>14s}")
    lines = ["p2p error against the peer (worse of dX / dY), the coupler mid-point's vector "
             'relative RMS, validity indicator', head]
    for r in sorted(records, key=lambda item: item['rpm']):
        met = r['targets_met']['second_order']
        lines.append(f"{r['rpm']:6g}  " + ''.join(
            f"{100 * _worst(r['models'][m], point):8.1f}%" for point in TARGETS
            for m in MODELS)
            + ''.join(f"{100 * r['point_rms_error'][m]['coupler_mid']:11.1f}%"
                      for m in ('second_order', 'dynamic'))
            + f"{r['nonlinearity']['indicator_max']:8.3f} "
            f"{'yes' if r['nonlinearity']['valid'] else 'NO':>5s} "
            f"{'yes' if all(met.values()) else 'NO':>14s}")
    turns = flag_turns(records)
    lines.append('flag turns: ' + ('; '.join(
        f"{'valid' if t['valid'] else 'NOT valid'} from {t['to_rpm']:g} rpm "
        f"(after {t['from_rpm']:g})" for t in turns) if turns else 'nowhere in the sweep'))
    return '\n'.join(lines)


__all__ = ['PEERS', 'BEARINGS', 'MODELS', 'MODEL_LABELS', 'TARGETS', 'Settings',
           'require_peer', 'peer_run', 'package_runs', 'point_rms_errors', 'meets_targets',
           'validate_speed', 'flag_turns', 'sweep_speeds', 'without_series', 'format_speed',
           'format_sweep']
