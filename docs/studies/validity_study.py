"""
Where linear + second order can be trusted: a speed sweep against the Exudyn peer.

``python docs/studies/validity_study.py [--rpm ...] [--elements 8] [--bearings rigid]
[--chart validity.png] [--cache DIR] [--json]`` runs, per crank speed, the nonlinear peer
(:mod:`studies.peer_exudyn`: rigid crank, no gravity) and the package's full-order linear
response plus its second order (:func:`core.fe.second_order_full.corrected_response`), records the
error of the lever tip and the coupler mid-point against the peer (p2p and relative RMS; the
worse of the dX / dY channels), and computes from the linear state the candidate indicators of
:mod:`core.validity`:

* ``I``: max over a revolution of the detuning ratio (the chosen indicator,
  :func:`core.validity.nonlinearity_indicator`: the frequency shift the elastic axial force
  causes in each link's first bending mode against that mode's distance from the nearest crank
  harmonic, zeta omega as a floor);
* ``N/Pcr``: max of |N_e| / P_cr (:func:`core.validity.load_ratio_indicator`);
* ``2nd/lin``: the coupler mid-point's second-order p2p against its linear p2p (the lever
  tip's is 10-70 at every speed with rigid bearings, so it cannot separate).

A speed is ``accurate`` when linear + second order is within 10 % (lever tip) and 3 %
(coupler mid-point) of the peer's p2p (the accuracy targets). For each candidate the study
prints the largest value over accurate speeds and the smallest over inaccurate ones: a
candidate separates the sweep when the first is below the second.

Conventions: the peer damps with beta = 1e-4 s on the material strain rates (modal zeta = beta
omega / 2: 0.011 at the 34.5 Hz coupler mode, 0.013 at the 41.7 Hz lever mode), the linear
model with modal zeta (mechanism default 0.02, ``--zeta``). With ``--bearings springs`` the
peer keeps the crank pivot rigid and splits joint masses as the mechanism says
(``mass_placement='split'``), as the linear model does; the spring damping differs (c = beta k
in the peer, modal zeta in the linear model).
"""

import argparse
import json
import math
import os

from flexlink_ros.core.fe.second_order_full import corrected_response
from flexlink_ros.core.fe.simulate import periodic_response
from flexlink_ros.core.validity import load_ratios, nonlinearity_indicator, VALIDITY_THRESHOLD
from flexlink_ros.studies.peer_exudyn import compare, peer_response
from flexlink_ros.studies.peer_linear import linear_model
from flexlink_ros.studies.peer_model import (BEARINGS, DEFAULT_BETA_S, DEFAULT_ELEMENTS,
                                             OUTPUT_KEYS, resolve_mechanism)
import numpy as np

TARGETS = {'lever_tip': 0.10, 'coupler_mid': 0.03}
DEFAULT_RPM = tuple(sorted(set(range(250, 451, 10)) | set(range(385, 430, 10)) | {269, 391,
                                                                                  405}))


def _peer(mechanism, rpm, elements, bearings, cache):
    """Peer response at one speed (no gravity), from ``cache`` (a directory) if stored there."""
    name = None
    if cache:
        name = os.path.join(cache, f'peer_{bearings}_{elements}_{rpm:g}.npz')
        if os.path.exists(name):
            data = np.load(name)
            out = {key: data[key] for key in data.files if key != 'info'}
            out['info'] = json.loads(str(data['info']))
            return out
    placement = 'split' if bearings == 'springs' else 'coupler-end'
    out = peer_response(mechanism, rpm, elements_per_link=elements, bearings=bearings,
                        gravity=False, mass_placement=placement)
    if name:
        os.makedirs(cache, exist_ok=True)
        np.savez(name, **{k: v for k, v in out.items() if k != 'info'},
                 info=json.dumps(out['info']))
    return out


def _errors(table):
    """Worse of dX / dY per output point: p2p error (signed) and relative RMS."""
    out = {}
    for point in TARGETS:
        keys = [f'{point}_dx', f'{point}_dy']
        worst = max(keys, key=lambda k: abs(table[k]['p2p_error']))
        out[point] = {'p2p_error': table[worst]['p2p_error'],
                      'rms_error': max(table[k]['rms_error'] for k in keys),
                      'peer_p2p': [table[k]['peer_p2p'] for k in keys]}
    return out


def run_speed(mechanism, rpm, elements=DEFAULT_ELEMENTS, bearings='rigid', zeta=None,
              points=120, cache=None):
    """
    Peer, linear + second order and the candidate indicators at one crank speed.

    Returns
    -------
    dict
        'rpm', 'errors' (per output point: 'p2p_error', 'rms_error', 'peer_p2p' [m] dX, dY),
        'accurate', 'indicator' (max of the detuning ratio I), 'load_ratio' (max |N_e| /
        P_cr), 'second_ratio', 'indicator_samples' (I over the revolution), 'links' (max
        |N_e| / P_cr per link), 'peer_cpu_s'.

    """
    response = _peer(mechanism, rpm, elements, bearings, cache)
    linkage = linear_model(mechanism, elements_per_link=elements, bearings=bearings,
                           gravity=False)
    speed = rpm * math.pi / 30.0
    linear = periodic_response(linkage, speed, method='full', points=points, zeta=zeta)
    corrected = corrected_response(linkage, linear)
    total = {'crank_angle': linear.crank_angle}
    total.update(zip(OUTPUT_KEYS, corrected['total'].T))
    errors = _errors(compare(response, total))
    used_zeta = linear.info['zeta']
    samples = nonlinearity_indicator(linkage, linear.displacement,
                                     linear.crank_angle, speed, zeta=used_zeta)
    ratios = load_ratios(linkage, linear.displacement, linear.crank_angle, speed)
    load_ratio = np.max(np.abs(np.stack(list(ratios.values()))))
    p2p = lambda x: x.max(axis=0) - x.min(axis=0)  # noqa: E731
    second_ratio = float(np.max(p2p(corrected['second'][:, 2:])
                                / p2p(corrected['linear'][:, 2:])))
    accurate = all(abs(errors[k]['p2p_error']) <= TARGETS[k] for k in TARGETS)
    return {'rpm': float(rpm), 'bearings': bearings, 'elements': elements, 'zeta': used_zeta,
            'errors': errors, 'accurate': accurate, 'indicator': float(samples.max()),
            'indicator_samples': samples, 'load_ratio': float(load_ratio),
            'second_ratio': second_ratio,
            'links': {int(k): float(np.abs(v).max()) for k, v in ratios.items()},
            'peer_cpu_s': response['info']['cpu_s']}


def separation(records, key):
    """
    Find the largest ``key`` over accurate speeds and the smallest over inaccurate ones.

    And whether the first is below the second (the candidate separates the sweep).
    """
    good = [r[key] for r in records if r['accurate']]
    bad = [r[key] for r in records if not r['accurate']]
    top, bottom = (max(good) if good else None), (min(bad) if bad else None)
    return {'accurate_max': top, 'inaccurate_min': bottom,
            'separates': top is not None and bottom is not None and top < bottom}


def format_table(records, threshold=VALIDITY_THRESHOLD):
    """Format the sweep table (text)."""
    head = (f"{'rpm':>5s} {'peer tip p2p um':>16s} {'peer mid p2p um':>16s} "
            f"{'tip err':>8s} {'mid err':>8s} {'tip rms':>8s} {'mid rms':>8s} "
            f"{'I max':>7s} {'N/Pcr':>7s} {'2nd/lin':>7s} {'acc':>4s} {'valid':>5s}")
    lines = [head]
    for r in records:
        e = r['errors']
        tip, mid = (e[k]['peer_p2p'] for k in ('lever_tip', 'coupler_mid'))
        lines.append(
            f"{r['rpm']:5.0f} {tip[0] * 1e6:7.1f}/{tip[1] * 1e6:<8.1f} "
            f'{mid[0] * 1e6:7.0f}/{mid[1] * 1e6:<8.0f} '
            + ''.join(f'{100 * e[point][kind]:7.1f}% ' for kind in ('p2p_error', 'rms_error')
                      for point in ('lever_tip', 'coupler_mid'))
            + f"{r['indicator']:7.3f} {r['load_ratio']:7.4f} {r['second_ratio']:7.3f} "
            f"{'yes' if r['accurate'] else 'NO':>4s} "
            f"{'yes' if r['indicator'] <= threshold else 'NO':>5s}")
    for key in ('indicator', 'load_ratio', 'second_ratio'):
        s = separation(records, key)
        fmt = lambda v: 'n/a' if v is None else f'{v:.4f}'  # noqa: E731
        lines.append(f"{key}: max over accurate speeds {fmt(s['accurate_max'])}, min over "
                     f"inaccurate {fmt(s['inaccurate_min'])}: "
                     + ('n/a' if None in (s['accurate_max'], s['inaccurate_min'])
                        else 'separates' if s['separates'] else 'does not separate'))
    return '\n'.join(lines)


def plot_sweep(records, path, threshold=VALIDITY_THRESHOLD):
    """Chart of the errors and the indicator against crank speed, written to ``path``."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    rpm = np.array([r['rpm'] for r in records])
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(8, 6.5))
    for key, style, label in (('lever_tip', 'o-', 'lever tip'),
                              ('coupler_mid', 's-', 'coupler mid-point')):
        err = np.array([abs(r['errors'][key]['p2p_error']) for r in records]) * 100
        top.semilogy(rpm, np.maximum(err, 1e-2), style, ms=4,
                     label=f'{label} |p2p error| (target {TARGETS[key]:.0%})')
        top.axhline(100 * TARGETS[key], ls=':', color=top.lines[-1].get_color())
    top.set_ylabel('linear + 2nd order vs peer [%]')
    top.legend(fontsize=8)
    bottom.semilogy(rpm, [r['indicator'] for r in records], 'k.-',
                    label='I: detuning ratio (frequency shift / distance to resonance)')
    bottom.semilogy(rpm, [r['load_ratio'] for r in records], '.:', color='0.4',
                    label='candidate: max |N_e| / P_cr')
    bottom.axhline(threshold, color='r', ls='--', label=f'threshold {threshold:g}')
    bad = rpm[[not r['accurate'] for r in records]]
    for ax in (top, bottom):
        for value in bad:
            ax.axvspan(value - 2.5, value + 2.5, color='0.85', lw=0)
    bottom.set_xlabel('crank speed [rpm]  (grey: outside the 10 % / 3 % targets)')
    bottom.set_ylabel('nonlinearity indicator')
    bottom.legend(fontsize=8)
    info = records[0]
    fig.suptitle(f"Validity sweep: {info['bearings']} bearings, rigid crank, "
                 f"{info['elements']} elements per link, modal zeta {info['zeta']:g}",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv=None):
    """Run the sweep, print the table, optionally write the chart (see the module notes)."""
    parser = argparse.ArgumentParser(prog='python docs/studies/validity_study.py',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--mechanism', default='cho1992')
    parser.add_argument('--rpm', type=float, nargs='+', default=list(DEFAULT_RPM))
    parser.add_argument('--elements', type=int, default=DEFAULT_ELEMENTS)
    parser.add_argument('--bearings', choices=BEARINGS, default='rigid')
    parser.add_argument('--zeta', type=float, default=None,
                        help='modal damping ratio of the linear model (default: mechanism)')
    parser.add_argument('--cache', default=None, help='directory to keep peer runs in')
    parser.add_argument('--chart', default=None, help='write the chart to this path (PNG)')
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args(argv)
    mech = resolve_mechanism(args.mechanism)
    records = [run_speed(mech, rpm, args.elements, args.bearings, args.zeta, cache=args.cache)
               for rpm in args.rpm]
    if args.chart:
        plot_sweep(records, args.chart)
    if args.json:
        slim = [{k: v for k, v in r.items() if k != 'indicator_samples'} for r in records]
        print(json.dumps(slim, indent=1, default=float))
        return 0
    print(f'{args.bearings} bearings, rigid crank, no gravity, {args.elements} elements per '
          f"link, linear modal zeta {records[0]['zeta']:g}, peer beta {DEFAULT_BETA_S:g} s; "
          f'threshold {VALIDITY_THRESHOLD:g}')
    print(format_table(records))
    return 0


__all__ = ['TARGETS', 'DEFAULT_RPM', 'run_speed', 'separation', 'format_table', 'plot_sweep',
           'main']


if __name__ == '__main__':
    raise SystemExit(main())
