"""
The nonlinear full order's periodic branch over crank speed, continued up and down.

    python docs/studies/nonlinear_branch.py [--from 360] [--to 440] [--step 5]
        [--bearings flexible|rigid] [--elements 8] [--steps 720] [--chart PATH] [--json PATH]

Periodic orbits of :func:`core.fe.nonlinear_response.nonlinear_response` (rigid crank, the
peer's conventions, beta = 1e-4 s, gravity), each started from its neighbour's orbit: once
sweeping up, once sweeping down. Where the response branches (two periodic solutions over a
speed range) the two sweeps part, and a Floquet multiplier approaches +1 at the fold ends.
Prints per speed and direction the lever tip and coupler mid-point peak-to-peak, the spectral
radius, the distance of the nearest multiplier to +1 and the largest element rotation; the
chart shows them over speed.
"""

import argparse
import json
import math

from flexlink_ros.core.fe.nonlinear_response import nonlinear_response
from flexlink_ros.core.fe.nonlinear_validity import orbit_validity
from flexlink_ros.studies.peer_linear import linear_model
from flexlink_ros.studies.peer_model import resolve_mechanism
from flexlink_ros.studies.validation import BEARINGS
import numpy as np

BETA = 1e-4


def sweep(model, speeds_rpm, steps, points):
    """Orbits at ``speeds_rpm`` in order, each started from the previous one; list of rows."""
    rows, start = [], None
    for rpm in speeds_rpm:
        response = nonlinear_response(model, rpm * math.pi / 30.0, steps=steps, points=points,
                                      zeta=0.0, beta=BETA, start=start)
        start = np.concatenate([response.displacement[0], response.velocity[0]])
        validity = orbit_validity(model, response)
        p2p = response.peak_to_peak
        rows.append({'rpm': float(rpm), 'lever_tip_p2p_m': float(np.hypot(p2p[0], p2p[1])),
                     'coupler_mid_p2p_m': float(np.hypot(p2p[2], p2p[3])),
                     'spectral_radius': response.info['spectral_radius'],
                     'fold_distance': validity.fold_distance,
                     'max_element_rotation_rad': validity.max_rotation,
                     'revolutions': response.info['revolutions']})
    return rows


def branch(bearings='flexible', low=360.0, high=440.0, step=5.0, elements=8, steps=720,
           points=72):
    """Sweep up then down; returns {'up': rows, 'down': rows}."""
    model = linear_model(resolve_mechanism('cho1992'), elements_per_link=elements,
                         bearings=BEARINGS[bearings], gravity=True)
    speeds = np.arange(low, high + 0.5 * step, step)
    return {'up': sweep(model, speeds, steps, points),
            'down': sweep(model, speeds[::-1], steps, points)}


def chart(result, path):
    """Peak-to-peak, fold distance and element rotation over speed, up and down (PNG)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    for direction, style in (('up', 'o-'), ('down', 'x--')):
        rows = result[direction]
        rpm = [r['rpm'] for r in rows]
        axes[0].plot(rpm, [1e3 * r['lever_tip_p2p_m'] for r in rows], style,
                     label=f'lever tip, sweep {direction}')
        axes[0].plot(rpm, [1e3 * r['coupler_mid_p2p_m'] for r in rows], style,
                     label=f'coupler mid, sweep {direction}')
        axes[1].plot(rpm, [r['fold_distance'] for r in rows], style, label=direction)
        axes[2].plot(rpm, [r['max_element_rotation_rad'] for r in rows], style, label=direction)
    axes[0].set_ylabel('p2p deflection [mm]')
    axes[1].set_ylabel('min |1 - mu|')
    axes[1].axhline(0.1, color='k', lw=0.8)
    axes[2].set_ylabel('largest element\nrotation [rad]')
    axes[2].axhline(0.12, color='k', lw=0.8)
    axes[2].set_xlabel('crank speed [rpm]')
    for ax in axes:
        ax.grid(True)
        ax.legend(fontsize=7)
    fig.suptitle('cho1992 nonlinear full order: periodic branch continued up and down')
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main():
    """Run the sweeps, print the rows, write the chart and the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--from', dest='low', type=float, default=360.0)
    parser.add_argument('--to', dest='high', type=float, default=440.0)
    parser.add_argument('--step', type=float, default=5.0)
    parser.add_argument('--bearings', default='flexible', choices=sorted(BEARINGS))
    parser.add_argument('--elements', type=int, default=8)
    parser.add_argument('--steps', type=int, default=720)
    parser.add_argument('--chart', default=None, help='PNG path')
    parser.add_argument('--json', default=None, help='JSON path')
    args = parser.parse_args()
    result = branch(args.bearings, args.low, args.high, args.step, args.elements, args.steps)
    print('| sweep | rpm | p2p lever tip / coupler mid [mm] | spectral radius | '
          'min abs(1 - mu) | largest element rotation [rad] | revolutions |')
    print('|---|---|---|---|---|---|---|')
    for direction in ('up', 'down'):
        for r in result[direction]:
            print(f"| {direction} | {r['rpm']:g} | {1e3 * r['lever_tip_p2p_m']:.3f} / "
                  f"{1e3 * r['coupler_mid_p2p_m']:.3f} | {r['spectral_radius']:.3f} | "
                  f"{r['fold_distance']:.3f} | {r['max_element_rotation_rad']:.3f} | "
                  f"{r['revolutions']} |")
    if args.chart:
        chart(result, args.chart)
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as out:
            json.dump(result, out, indent=1)


if __name__ == '__main__':
    main()
