"""
`flexlink fleet`: a fleet's recordings recomputed on Ray, one task per bag, into one table.

Each bag (a path or a glob; a file or a bag directory) is recomputed by
:func:`io.fleet_bag.recompute_bag` in its own Ray task: read, estimate in one sequential pass,
summarise per revolution or minute, and with ``--write-mcap`` write the MCAP ``flexlink
replay --out`` would. The rows go to ``DIR/summary.parquet`` (:mod:`.fleet_table`); ``--json``
prints one object per bag with ``flexlink replay --json``'s keys and the bag's path. Ray runs
embedded on this machine's cores (no cluster to start) or joins a running cluster with
``--address``. A bag that fails is a row with its reason and the others go on; the exit code is
1 if any bag failed. Ray is imported only here, when the command runs.
"""

import glob
import logging
import os
import pathlib
import sys
import time

from .fleet_table import TABLE_NAME, write_table
from .main import emit
from .model_args import add_estimator_arguments, model_options
from .progress import Progress
from ..core.estimation.nonlinear_follow import CHOICES
from ..core.estimation.summary import PERIODS
from ..io.fleet_bag import failed_row, FleetSettings, recompute_bag
from ..io.recorder_files import refuse_existing
from ..names import DEFAULT_FRAME_ID, NODE_NAME

# Object store of the embedded Ray [bytes]: the results are small (a few rows per bag).
OBJECT_STORE_BYTES = 200 * 1024 * 1024
GLOB_CHARACTERS = '*?['


def expand_bags(patterns):
    """
    List the bags of the command line in order, globs expanded, each once.

    Returns
    -------
    bags : list of str
    unmatched : list of str
        Patterns that name nothing (each becomes a failed row).

    """
    bags, unmatched, seen = [], [], set()
    for pattern in patterns:
        if os.path.exists(pattern) or not any(c in pattern for c in GLOB_CHARACTERS):
            found = [pattern] if os.path.exists(pattern) else []
        else:
            found = sorted(glob.glob(pattern, recursive=True))
        if not found:
            unmatched.append(pattern)
        for bag in found:
            key = os.path.realpath(bag)
            if key not in seen:
                seen.add(key)
                bags.append(bag)
    return bags, unmatched


def output_paths(bags, directory):
    """One output MCAP per bag under ``directory/mcap`` (names made unique), refused if there."""
    paths, used = [], set()
    for bag in bags:
        stem = pathlib.Path(bag.rstrip('/')).name.removesuffix('.mcap') or 'bag'
        name, number = stem, 1
        while name in used:
            number += 1
            name = f'{stem}_{number}'
        used.add(name)
        path = pathlib.Path(directory) / 'mcap' / f'{name}.mcap'
        refuse_existing(path)
        paths.append(str(path))
    return paths


def import_ray(embedded):
    """
    Import Ray (and pyarrow, the table's writer, which ``ray[data]`` brings), or refuse.

    Parameters
    ----------
    embedded : bool
        Ray will run on this machine only: every Ray process on the loopback address (Ray
        reads this when imported).

    Returns
    -------
    module
        ``ray``.

    """
    # No usage report leaves the machine; set before Ray reads it.
    os.environ['RAY_USAGE_STATS_ENABLED'] = '0'
    if embedded:
        os.environ.setdefault('RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER', '0')
    try:
        import ray
        import pyarrow   # noqa: F401
    except ImportError as exc:
        raise ValueError(f"needs Ray (pip install '.[fleet]': ray[data]==2.60.0): {exc}") from None
    return ray


def start_ray(ray, address, num_cpus):
    """Start an embedded Ray on this machine (or join the cluster at ``address``), quietly."""
    quiet = {'logging_level': logging.ERROR, 'log_to_driver': False}
    if address:
        ray.init(address=address, **quiet)
    else:
        ray.init(num_cpus=num_cpus or os.cpu_count(), include_dashboard=False,
                 object_store_memory=OBJECT_STORE_BYTES, **quiet)


def recompute_on_node(bag, fallback, settings, output):
    """:func:`recompute_bag` in a Ray task, with the address of the node that ran it."""
    import ray
    result = recompute_bag(bag, fallback, settings, output)
    result['summary']['node'] = ray.util.get_node_ip_address()
    return result


def run_tasks(ray, jobs, progress):
    """
    Run :func:`recompute_bag` once per job as Ray tasks; results in the jobs' order.

    A task that Ray could not run (its worker died) gives a failed result with Ray's reason.
    """
    # Spread over the nodes: each bag reads its own files.
    task = ray.remote(num_cpus=1, max_retries=0, scheduling_strategy='SPREAD')(
        recompute_on_node)
    pending = {task.remote(*job): k for k, job in enumerate(jobs)}
    results = [None] * len(jobs)
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        k = pending.pop(ready[0])
        try:
            results[k] = ray.get(ready[0])
        except ray.exceptions.RayError as exc:
            reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            results[k] = {'summary': {'bag': jobs[k][0], 'input': jobs[k][0], 'error': reason},
                          'rows': [failed_row(jobs[k][0], reason, jobs[k][2].per)]}
        progress(len(jobs) - len(pending))
    return results


def run_fleet(args):
    """
    Recompute every bag, write the table, and return the per-bag results and timings.

    Returns
    -------
    results : list of dict
        :func:`recompute_bag`'s results, the unmatched patterns' failures last.
    times : dict
        'ray_start_s', 'tasks_s', 'table' (path), 'rows'.

    """
    bags, unmatched = expand_bags(args.bags)
    out = pathlib.Path(args.out)
    if out.exists() and not out.is_dir():
        raise ValueError(f'`--out` {out} is not a directory')
    try:    # refused before any work, with the recorder's own test
        refuse_existing(out / TABLE_NAME)
        outputs = output_paths(bags, out) if args.write_mcap else [None] * len(bags)
    except FileExistsError as exc:
        raise ValueError(f'`--out` {exc}') from None
    fallback = (args.mechanism, model_options(args)) if args.mechanism else None
    settings = FleetSettings(per=args.per, joint=args.joint, topic=args.topic,
                             warm_start=not args.no_warm_start, cache_dir=args.cache_dir,
                             use_cache=not args.no_cache, node_name=args.node_name,
                             frame_id=args.frame_id, markers_every_n=args.markers_every_n,
                             nonlinear=args.nonlinear)
    ray = import_ray(embedded=not args.address)
    times = {}
    results = []
    if bags:
        start = time.perf_counter()
        start_ray(ray, args.address, args.num_cpus)
        times['ray_start_s'] = time.perf_counter() - start
        try:
            with Progress('fleet', len(bags), unit='bag') as progress:
                results = run_tasks(ray, [(bag, fallback, settings, output)
                                          for bag, output in zip(bags, outputs)], progress)
        finally:
            ray.shutdown()
        times['tasks_s'] = time.perf_counter() - start - times['ray_start_s']
    for pattern in unmatched:
        reason = f'no such file, directory or match: {pattern}'
        results.append({'summary': {'bag': pattern, 'input': pattern, 'error': reason},
                        'rows': [failed_row(pattern, reason, args.per)]})
    out.mkdir(parents=True, exist_ok=True)
    rows = [row for result in results for row in result['rows']]
    times.update(table=str(write_table(rows, out)), rows=len(rows))
    return results, times


def bag_line(summary):
    """One line of text per bag: its samples and peak-to-peak, or why it failed."""
    if summary.get('error'):
        return f"{summary['bag']}: FAILED: {summary['error']}"
    lever, coupler = summary['lever_tip_peak_to_peak_um'], summary['coupler_mid_peak_to_peak_um']
    return (f"{summary['bag']}: {summary['samples']} samples, {summary['skipped']} skipped, "
            f"{summary['outliers']} outlier(s); lever tip p2p {lever[0]:.1f} / {lever[1]:.1f} "
            f'um, coupler mid p2p {coupler[0]:.1f} / {coupler[1]:.1f} um '
            f"({summary['seconds']:.2f} s)")


def _fleet_command(args):
    if args.num_cpus is not None and (args.num_cpus < 1 or args.address):
        raise ValueError('`--num-cpus` must be >= 1, and is for the embedded Ray only')
    started = time.perf_counter()
    results, times = run_fleet(args)
    failed = [r['summary'] for r in results if r['summary'].get('error')]
    for result in results:
        summary = result['summary']
        emit(summary, bag_line(summary), args.json)
    footer = (f"{len(results)} bag(s), {len(failed)} failed; {times['rows']} row(s) in "
              f"{times['table']}; Ray start {times.get('ray_start_s', 0.0):.2f} s, tasks "
              f"{times.get('tasks_s', 0.0):.2f} s, total {time.perf_counter() - started:.2f} s")
    print(footer, file=sys.stderr if args.json else sys.stdout)
    return 1 if failed else 0


def register(subparsers):
    """Add the fleet subcommand."""
    parser = subparsers.add_parser(
        'fleet', help='recompute many bags on Ray (one task per bag) into DIR/summary.parquet')
    parser.add_argument('bags', nargs='+', metavar='BAG',
                        help='rosbag2 MCAP files or bag directories, or globs of them')
    parser.add_argument('--out', required=True, metavar='DIR',
                        help=f'output directory ({TABLE_NAME} must not exist in it)')
    parser.add_argument('--per', choices=PERIODS, default='revolution',
                        help='one table row per crank revolution or per minute '
                        '(default: %(default)s)')
    parser.add_argument('--write-mcap', action='store_true',
                        help="also write each bag's replay MCAP into DIR/mcap/")
    parser.add_argument('--address', help='join the running Ray cluster at this address '
                        '(default: an embedded Ray on this machine)')
    parser.add_argument('--num-cpus', type=int, help='CPUs of the embedded Ray (default: all)')
    parser.add_argument('--topic', help='input JointState topic (default: the one carrying '
                        'the joint)')
    parser.add_argument('--joint', default='crank', help='crank joint name (default: crank)')
    parser.add_argument('--node-name', default=NODE_NAME,
                        help=f'namespace of the written output topics (default: {NODE_NAME})')
    parser.add_argument('--frame-id', default=DEFAULT_FRAME_ID, help='frame of the outputs')
    parser.add_argument('--markers-every-n', type=int, default=10,
                        help='markers on every n-th sample of --write-mcap (0: none)')
    parser.add_argument('--no-warm-start', action='store_true',
                        help='start from the static deflection, not the periodic state')
    parser.add_argument('--nonlinear', choices=CHOICES, default=None,
                        help="the reduced geometrically nonlinear model's deflections: auto "
                        '(where the linear estimate of the bag is not valid), on, off '
                        '(default: the model the recording says made it, else auto; as '
                        'replay)')
    add_estimator_arguments(parser)
    parser.set_defaults(func=_fleet_command, mechanism=None)
    fleet_help = {'mechanism': 'mechanism YAML file or bare name for the bags that carry no '
                  'recorded mechanism (default: none; such bags fail)',
                  'json': 'print one JSON object per bag (the last line goes to stderr)'}
    for action in parser._actions:
        action.help = fleet_help.get(action.dest, action.help)
