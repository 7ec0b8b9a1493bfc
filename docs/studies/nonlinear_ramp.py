"""
A crank speed ramp up and down through 360-440 rpm in the Exudyn peer and the streaming estimate.

    python docs/studies/nonlinear_ramp.py [--from 360] [--to 440] [--ramp-s 80] [--settle 30]
        [--hold 10] [--elements 8] [--peer-steps 720] [--bearings flexible|rigid]
        [--rate 1000] [--jitter 0.3] [--peer PATH.npz] [--chart PATH] [--json PATH]

The same ramp (:class:`ramp_sweep.RampProfile`: settle at the low speed,
ramp up, hold, ramp down, hold) drives the peer (8 ANCF elements per link, beta = 1e-4 s,
bearing springs, gravity; kept in ``--peer`` so a second run only streams) and the streaming
estimate (the reduced nonlinear model at 1 kHz, once evenly sampled and once with +-30 %
jitter of the interval). Prints per model the largest gap between the ramp-up and ramp-down
peak-to-peak at one speed (a branching response parts there), the largest jump from one
revolution to the next, the estimate's relative RMS against the peer over the whole ramp and
the estimate's largest validity indicator; charts p2p over speed, up and down, per model.
"""

import argparse
import json
import math
import os

from flexlink_ros.core.reduction.nonlinear_tables import build_nonlinear_tables
from flexlink_ros.studies.peer_linear import linear_model
from flexlink_ros.studies.peer_model import resolve_mechanism
from flexlink_ros.studies.validation import BEARINGS
import numpy as np
from ramp_sweep import branch_gap, peer_ramp, per_revolution, POINTS, \
    ramp_halves, RampProfile, stream_ramp, time_series_error

BETA = 1e-4


def load_or_run_peer(path, profile, args):
    """Return the peer's ramp run: from ``path`` when it holds this profile, else run and kept."""
    if path and os.path.exists(path):
        with np.load(path) as data:
            run = {key: data[key] for key in data.files if key != 'info'}
            run['info'] = json.loads(str(data['info']))
        if run['info']['profile'] == json.loads(json.dumps(vars(profile))):
            return run
    run = peer_ramp('cho1992', profile, elements_per_link=args.elements,
                    bearings=BEARINGS[args.bearings], beta_s=BETA,
                    steps_per_revolution=args.peer_steps)
    if path:
        np.savez(path, **{k: v for k, v in run.items() if k != 'info'},
                 info=json.dumps(run['info']))
    return run


def ramp_study(profile, args):
    """Peer and streaming runs through the ramp; {'runs': rows per model, 'summary': ...}."""
    peer = load_or_run_peer(args.peer, profile, args)
    model = linear_model(resolve_mechanism('cho1992'), elements_per_link=args.elements,
                         bearings=BEARINGS[args.bearings], gravity=True)
    tables = build_nonlinear_tables(model, BETA)
    runs = {'peer': peer,
            'streaming': stream_ramp(tables, profile, args.rate, 0.0),
            'streaming, jitter': stream_ramp(tables, profile, args.rate, args.jitter)}
    rows = {name: per_revolution(run) for name, run in runs.items()}
    summary = {}
    for name, run in runs.items():
        entry = {point: {key: value for key, value in branch_gap(rows[name], profile,
                                                                 point).items()
                         if key in ('largest_gap', 'at_rpm', 'largest_jump')}
                 for point in POINTS}
        if name != 'peer':
            for point in POINTS:
                entry[point]['rms_vs_peer'] = time_series_error(peer, run, point)
            entry['largest_validity'] = float(np.nanmax(rows[name]['validity']))
            entry['refused'] = int(run['refused'])
            entry['wall_s'] = float(run['wall_s'])
        else:
            entry['wall_s'] = float(peer['info']['wall_s'])
        summary[name] = entry
    return {'rows': rows, 'summary': summary}


def chart(result, profile, path):
    """p2p over speed, ramp up and ramp down, per model and output point (PNG)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(3, 1, figsize=(7.5, 9), sharex=True)
    styles = {'peer': ('k', 2.2), 'streaming': ('tab:blue', 1.2),
              'streaming, jitter': ('tab:orange', 0.8)}
    for ax, point in zip(axes, POINTS):
        for name, rows in result['rows'].items():
            up, down = ramp_halves(rows, profile)
            color, width = styles[name]
            ax.plot(up['rpm'], 1e3 * up[point], '-', color=color, lw=width,
                    label=f'{name}, ramp up')
            ax.plot(down['rpm'], 1e3 * down[point], '--', color=color, lw=width,
                    label=f'{name}, ramp down')
        ax.set_ylabel(f'{point.replace("_", " ")}\np2p per revolution [mm]')
        ax.grid(True)
        ax.legend(fontsize=6, ncol=3)
    for name in ('streaming', 'streaming, jitter'):
        up, down = ramp_halves(result['rows'][name], profile)
        color, width = styles[name]
        axes[2].plot(up['rpm'], up['validity'], '-', color=color, lw=width, label=f'{name}, up')
        axes[2].plot(down['rpm'], down['validity'], '--', color=color, lw=width,
                     label=f'{name}, down')
    axes[2].axhline(0.5, color='k', lw=0.8)
    axes[2].set_ylabel('validity indicator\n(largest per revolution)')
    axes[2].set_xlabel('crank speed [rpm]')
    axes[2].grid(True)
    axes[2].legend(fontsize=6)
    fig.suptitle(f'cho1992, ramp {profile.low_rpm:g}-{profile.high_rpm:g} rpm in '
                 f'{profile.ramp_s:g} s each way (beta 1e-4 s, bearing springs, gravity)')
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main():
    """Run the ramp study, print the summary, write the chart and the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--from', dest='low', type=float, default=360.0)
    parser.add_argument('--to', dest='high', type=float, default=440.0)
    parser.add_argument('--ramp-s', type=float, default=80.0, help='seconds per ramp')
    parser.add_argument('--settle', type=float, default=30.0, help='revolutions at the start')
    parser.add_argument('--hold', type=float, default=10.0, help='revolutions at each end')
    parser.add_argument('--elements', type=int, default=8)
    parser.add_argument('--peer-steps', type=int, default=720,
                        help='peer steps per revolution at the top speed')
    parser.add_argument('--bearings', default='flexible', choices=sorted(BEARINGS))
    parser.add_argument('--rate', type=float, default=1000.0, help='estimator samples/s')
    parser.add_argument('--jitter', type=float, default=0.3)
    parser.add_argument('--peer', default=None, help='NPZ the peer run is kept in')
    parser.add_argument('--chart', default=None, help='PNG path')
    parser.add_argument('--json', default=None, help='JSON path')
    args = parser.parse_args()
    profile = RampProfile(args.low, args.high, args.ramp_s, args.settle, args.hold)
    result = ramp_study(profile, args)
    print(f'ramp {profile.duration_s:.1f} s; | model | point | largest up/down gap (at rpm) '
          '| largest jump per revolution | RMS vs peer |')
    for name, entry in result['summary'].items():
        for point in POINTS:
            e = entry[point]
            rms = f"{100 * e['rms_vs_peer']:.1f} %" if 'rms_vs_peer' in e else '-'
            print(f"| {name} | {point} | {100 * e['largest_gap']:.1f} % ({e['at_rpm']:.0f}) | "
                  f"{100 * e['largest_jump']:.1f} % | {rms} |")
        print(f"  {name}: wall {entry['wall_s']:.0f} s"
              + (f", largest validity {entry['largest_validity']:.3f}, refused "
                 f"{entry['refused']}" if name != 'peer' else ''))
    if args.chart:
        chart(result, profile, args.chart)
    if args.json:
        rows = {name: {k: v.tolist() for k, v in r.items()} for name, r in result['rows'].items()}
        with open(args.json, 'w', encoding='utf-8') as out:
            json.dump({'summary': result['summary'], 'rows': rows,
                       'duration_s': profile.duration_s, 'rate_rpm_per_s':
                       (profile.high_rpm - profile.low_rpm) / profile.ramp_s}, out, indent=1,
                      default=lambda x: None if isinstance(x, float) and math.isnan(x) else x)


if __name__ == '__main__':
    main()
