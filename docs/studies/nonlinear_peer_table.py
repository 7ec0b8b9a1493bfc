"""
The nonlinear full order against the Exudyn peer, scene by scene (the table of docs/nonlinear.md).

    python docs/studies/nonlinear_peer_table.py [--cache DIR] [--json PATH] [--scenes K ...]
                                                [--peer-steps N]

Each scene runs the peer (8 ANCF elements per link, rigid crank, the project's matched
conventions; kept in ``--cache``) and the package's linear and nonlinear full orders damped as
the peer, one scene after another (the peer and the marching are CPU-heavy). Prints one
Markdown row per scene as it finishes: relative RMS of the lever tip and coupler mid-point
deflection vectors, the worst p2p error per point, the spectral radius of the orbit's
monodromy, the orbit's largest element rotation against its chord (co-rotational strain;
what the nonlinear validity indicator reads), Newton iterations per step and cost per step.
``--peer-steps``: the peer's time steps per revolution (default 720; its phase converges
only at about 2880 where the response is largest).
"""

import argparse
import json
import time

from flexlink_ros.studies import nonlinear_validation, validation

# (bearings, beta [s], rpm, gravity): the full order's targets in docs/nonlinear.md
SPRING_SPEEDS = (340, 365, 391, 405, 420, 440)
SCENES = ([('flexible', 1e-4, rpm, gravity) for gravity in (True, False) for rpm in SPRING_SPEEDS]
          + [('flexible', 3e-4, rpm, True) for rpm in (391, 405)]
          + [('rigid', 1e-4, rpm, True) for rpm in (391, 405, 420)]
          + [('flexible', 1e-4, 269, True)])


def worst_p2p(table, point):
    """Return the larger-magnitude p2p error of a point's dX and dY."""
    return max((table[f'{point}_{axis}']['p2p_error'] for axis in ('dx', 'dy')), key=abs)


def row(record):
    """One Markdown table row of a :func:`validate_nonlinear` record."""
    s = record['settings']
    rms = record['point_rms_error']
    nl = record['models']['nonlinear']
    return (f"| {s['bearings']} | {s['beta_s']:g} | {record['rpm']:g} | "
            f"{'on' if s['gravity'] else 'off'} | "
            f"{100 * rms['linear']['lever_tip']:.1f} / {100 * rms['linear']['coupler_mid']:.1f} | "
            f"{100 * rms['nonlinear']['lever_tip']:.1f} / "
            f"{100 * rms['nonlinear']['coupler_mid']:.1f} | "
            f"{100 * worst_p2p(nl, 'lever_tip'):+.1f} / "
            f"{100 * worst_p2p(nl, 'coupler_mid'):+.1f} | "
            f"{record['spectral_radius']:.3f} | "
            f"{record['nonlinear_validity']['max_element_rotation_rad']:.3f} | "
            f"{record['newton_mean']:.2f} | "
            f"{1e3 * record['step_cost_s']:.1f} |")


def main():
    """Run the scenes and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--cache', default=None, help='peer cache directory')
    parser.add_argument('--json', default=None, help='write every record (no series) here')
    parser.add_argument('--scenes', type=int, nargs='*', default=None,
                        help='indices into the scene list (default: all)')
    parser.add_argument('--peer-steps', type=int, default=validation.Settings.peer_steps,
                        help='peer time steps per revolution')
    args = parser.parse_args()
    picked = SCENES if args.scenes is None else [SCENES[k] for k in args.scenes]
    print('| bearings | beta [s] | rpm | gravity | linear RMS tip / mid [%] | '
          'nonlinear RMS tip / mid [%] | nonlinear worst p2p tip / mid [%] | '
          'spectral radius | largest element rotation [rad] | Newton per step | ms per step |')
    print('|---|---|---|---|---|---|---|---|---|---|---|', flush=True)
    records = []
    for bearings, beta, rpm, gravity in picked:
        settings = validation.Settings(bearings=bearings, stiffness_damping=beta,
                                       gravity=gravity, cache=args.cache,
                                       peer_steps=args.peer_steps)
        started = time.perf_counter()
        record = nonlinear_validation.validate_nonlinear('cho1992', float(rpm), settings)
        record['scene_wall_s'] = time.perf_counter() - started
        records.append(nonlinear_validation.without_series(record))
        print(row(record), flush=True)
        if args.json:
            with open(args.json, 'w', encoding='utf-8') as out:
                json.dump(records, out, indent=1)


if __name__ == '__main__':
    main()
