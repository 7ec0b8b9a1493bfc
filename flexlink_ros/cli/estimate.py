"""
`flexlink estimate`, `flexlink plan`, `flexlink bench`: the streaming estimator offline.

- ``estimate`` runs :class:`core.estimator.StreamingEstimator` on a synthetic constant-speed
  crank signal (optionally jittered) and prints the last full revolution.
- ``plan`` picks the smallest model (physics: elements per link, rigid crank, geometric
  stiffness, bearings; size: modes, static directions, grid) meeting a tolerance against the
  full-order response of the richest model of the scene over a speed range, and shows the
  error and cost of the alternatives (see :func:`run_plan`).
- ``bench`` measures, side by side in one run: streaming cost per sample (median, p99),
  offline samples per second, full-order CPU per simulated second, and each configuration's
  error; it prints a table and writes a chart of error against cost.
"""

import dataclasses
import math
import pathlib
import time

import numpy as np

from ..core.numerics import RPM, relative_rms
from ..ros import parameters as node_params
from .main import emit
from ..core.reduction import model as reduced
from ..core.estimation.streaming import StreamingEstimator, compiled_step_available, replay
from ..core.mechanism import load_mechanism

# Speeds of Cho 1992's deflection plots [rpm]: the accuracy checks use them.
PAPER_RPM = (269.0, 391.0)
# Samples whose update time is measured after a warm-up (median and p99 are reported).
TIMING_WARMUP = 50
# Length of the signal the offline replay rate is measured on [s] (amortises the warm start).
OFFLINE_SECONDS = 20.0


def synthetic_signal(rpm, seconds, rate_hz, jitter=0.0, seed=0, start_angle=0.0):
    """
    Stamps, angles and speeds of a crank at constant speed sampled with jitter.

    Parameters
    ----------
    rpm : float
        Crank speed [rpm].
    seconds : float
        Duration [s].
    rate_hz : float
        Nominal sample rate [Hz].
    jitter : float
        Each step is (1 + jitter U(-1, 1)) / rate_hz.
    seed : int
        Random seed of the jitter.
    start_angle : float
        Crank angle at t = 0 [rad].

    Returns
    -------
    stamps_ns : ndarray of int, shape (m,)
    angles, speeds : ndarray, shape (m,)

    """
    if not 0.0 <= jitter < 1.0:
        raise ValueError(f'`jitter` must be in [0, 1), got {jitter}')
    if seconds <= 0.0 or rate_hz <= 0.0:
        raise ValueError('`seconds` and `rate_hz` must be positive')
    rng = np.random.default_rng(seed)
    count = int(seconds * rate_hz * (1.0 + jitter)) + 2
    steps = (1.0 + jitter * rng.uniform(-1.0, 1.0, count)) / rate_hz
    times = np.concatenate([[0.0], np.cumsum(steps)])
    times = times[times <= seconds]
    stamps = np.round(times * 1e9).astype(np.int64)
    speed = rpm * RPM
    return stamps, start_angle + speed * stamps * 1e-9, np.full(stamps.size, speed)


def last_revolution(stamps_ns, rpm):
    """Boolean mask of the samples in the last full revolution."""
    period_ns = 2.0 * math.pi / (abs(rpm) * RPM) * 1e9
    return stamps_ns > stamps_ns[-1] - period_ns


def stream_timed(model, stamps_ns, angles, speeds, warm_start=True, compiled=True):
    """
    Run the streaming estimator (its compiled step, or its numpy step) and time every update.

    Returns
    -------
    samples : list of Sample
    update_ns : ndarray of int
        perf_counter_ns duration of each update.

    """
    estimator = StreamingEstimator(model, warm_start=warm_start, compiled=compiled)
    samples, durations = [], []
    clock = time.perf_counter_ns
    for stamp, angle, speed in zip(stamps_ns.tolist(), angles.tolist(),
                                   None if speeds is None else speeds.tolist()):
        start = clock()
        samples.append(estimator.update(stamp, angle, speed))
        durations.append(clock() - start)
    return samples, np.array(durations)


def timing_summary(update_ns):
    """Median and 99th percentile [us] of update durations after the warm-up samples."""
    steady = update_ns[TIMING_WARMUP:] if update_ns.size > 2 * TIMING_WARMUP else update_ns
    return float(np.median(steady) / 1e3), float(np.percentile(steady, 99) / 1e3)


def run_estimate(model, rpm, seconds=3.0, rate_hz=1000.0, jitter=0.0, warm_start=True,
                 seed=0):
    """
    The estimate over the last full revolution of a synthetic constant-speed signal.

    Returns
    -------
    dict
        JSON-ready: crank_deg, lever_tip and coupler_mid {dx_m, dy_m}, error_indicator,
        us_per_sample_median, us_per_sample_p99, samples, flags seen.

    """
    stamps, angles, speeds = synthetic_signal(rpm, seconds, rate_hz, jitter, seed)
    samples, update_ns = stream_timed(model, stamps, angles, speeds, warm_start)
    mask = last_revolution(stamps, rpm)
    chosen = [s for s, keep in zip(samples, mask) if keep]
    median, p99 = timing_summary(update_ns)
    return {
        'crank_deg': [math.degrees(s.crank_angle) for s in chosen],
        'lever_tip': {'dx_m': [s.lever_tip[0] for s in chosen],
                      'dy_m': [s.lever_tip[1] for s in chosen]},
        'coupler_mid': {'dx_m': [s.coupler_mid[0] for s in chosen],
                        'dy_m': [s.coupler_mid[1] for s in chosen]},
        'error_indicator_max': max(s.error_indicator for s in chosen),
        'us_per_sample_median': median,
        'us_per_sample_p99': p99,
        'samples': len(samples),
        'model': {'size': model.size, 'grid_size': model.grid_size,
                  'bytes': int(model.nbytes), 'options': model.info.get('options', {})},
    }


def configuration_error(mechanism, model, options, rpm, rate_hz=1000.0, jitter=0.0,
                        seconds=None, seed=0):
    """
    Streaming error of a model against the full-order reference at one speed.

    The estimator replays (batched, the same numbers as streaming) a synthetic signal of
    ``seconds`` (default: two revolutions after a warm start) and the last revolution is
    compared with the reference response at the same crank angles.

    Returns
    -------
    dict
        error_lever_tip, error_coupler_mid (relative RMS), reference (its source).

    """
    period = 2.0 * math.pi / (rpm * RPM)
    seconds = seconds or 2.0 * period
    stamps, angles, speeds = synthetic_signal(rpm, seconds, rate_hz, jitter, seed)
    out = replay(model, stamps, angles, speeds)
    mask = last_revolution(stamps, rpm)
    ref = reduced.reference_response(mechanism, options, rpm * RPM, angles[mask])
    return {'error_lever_tip': relative_rms(out['lever_tip'][mask], ref['lever_tip']),
            'error_coupler_mid': relative_rms(out['coupler_mid'][mask], ref['coupler_mid']),
            'reference': ref.get('source')}


def full_order_cpu_per_second(mechanism, options, rpm, rate_hz=1000.0, steps=40):
    """
    CPU seconds per simulated second of a direct full-order integration at ``rate_hz``.

    Each step assembles the FE system at the two Radau stage angles (core/assembly.py),
    builds the modal damping from all frozen modes and takes one order-3 Radau IIA step:
    what integrating the unreduced model sample by sample costs.
    """
    from ..core.fe import linkage as assembly
    from ..core.integrators import RadauIIA
    mech = reduced.fe_mechanism(mechanism, options)
    linkage = assembly.FlexibleLinkage(mech, options)
    method = RadauIIA(2)
    speed, h = rpm * RPM, 1.0 / rate_hz
    q = np.zeros(linkage.size)
    v = np.zeros(linkage.size)
    start = time.process_time()
    for n in range(steps):
        system = linkage.assemble(speed * h * (n + method.c))
        mass, damping, stiffness, load = system.evaluate(speed)
        frozen = system.frozen_stiffness(speed)
        damping = damping + np.array([reduced.modal_damping_matrix(m, k, mech.damping_ratio)
                                      for m, k in zip(mass, frozen)])
        q, v, _ = method.step(q, v, h, mass, damping, stiffness, load)
    return (time.process_time() - start) / steps * rate_hz


def model_options(args, **overrides):
    """
    ModelOptions from the common command-line arguments, with overrides.

    Without size arguments the sizes are the defaults for the chosen bearing and crank models
    (core.reduced.DEFAULT_SIZES); a flexible crank gets the node's elements per link, a rigid
    crank the mechanism file's.
    """
    rigid_crank = bool(args.rigid_crank)
    node_elements = node_params.defaults()['model.elements_per_link'] or None
    values = {'rigid_crank': rigid_crank, 'bearings': args.bearings,
              'geometric_stiffness': not args.no_geometric_stiffness,
              'elements_per_link': None if rigid_crank else node_elements}
    for name in ('modes', 'static', 'grid_size', 'elements_per_link'):
        value = getattr(args, name, None)
        if value is not None:
            values[name] = value
    if getattr(args, 'rpm_max', None):
        values['speed_max'] = max(reduced.ModelOptions.speed_max, 1.05 * args.rpm_max * RPM)
    values.update(overrides)
    return reduced.ModelOptions(**values)


def load_model(mechanism, options, args):
    """The cached (or freshly built) reduced model for the command line."""
    return reduced.model_for_mechanism(mechanism, options, cache_dir=args.cache_dir,
                                       use_cache=not args.no_cache)


# ---------------------------------------------------------------------------------------
# Commands

def _estimate(args):
    mechanism = load_mechanism(args.mechanism)
    options = model_options(args, speed_max=max(reduced.ModelOptions.speed_max,
                                                 1.05 * abs(args.rpm) * RPM))
    model = load_model(mechanism, options, args)
    result = run_estimate(model, args.rpm, args.seconds, args.rate_hz, args.jitter,
                          not args.no_warm_start, args.seed)
    lever = np.hypot(result['lever_tip']['dx_m'], result['lever_tip']['dy_m'])
    coupler = np.hypot(result['coupler_mid']['dx_m'], result['coupler_mid']['dy_m'])
    text = (f'{mechanism.name} at {args.rpm:g} rpm, {args.rate_hz:g} Hz '
            f'(jitter {args.jitter:g}), {result["samples"]} samples; last revolution:\n'
            f'  lever tip |d| max   {1e3 * lever.max():.4f} mm\n'
            f'  coupler mid |d| max {1e3 * coupler.max():.4f} mm\n'
            f'  update {result["us_per_sample_median"]:.1f} us median, '
            f'{result["us_per_sample_p99"]:.1f} us p99 (r = {model.size}, '
            f'{model.grid_size} grid cells)')
    return emit(result, text, args.json)


# ---------------------------------------------------------------------------------------
# plan: the smallest model (physics and size) meeting a tolerance against the scene

# Element counts tried as simplifications (besides the mechanism's own count).
PLAN_ELEMENTS = (2, 3, 4)
# Basis sizes of the size stage: frozen-mode directions, static directions, grid points.
PLAN_MODES = (2, 4, 6, 8, 10, 12, 16, 20, 24)
PLAN_STATIC = (0, 2, 4)
PLAN_GRIDS = (64, 128, 256)


def plan_candidates(base):
    """
    Size candidates (modes, static, grid) of one physics, from small to large.

    Sorted by basis size r = modes + static, then grid points; the last is the generous size
    at which :func:`run_plan` screens a physics choice.
    """
    candidates = []
    for modes in PLAN_MODES:
        for static in PLAN_STATIC:
            for grid in PLAN_GRIDS:
                candidates.append(dataclasses.replace(base, modes=modes, static=static,
                                                      grid_size=grid))
    return sorted(candidates, key=lambda o: (o.modes + o.static, o.grid_size))


def scene_options(mechanism, base):
    """
    The richest model of the scene: the reference every candidate is compared with.

    The user's bearing model, geometric stiffness on, flexible crank, and
    ``base.elements_per_link`` beam elements per link if given, else twice the mechanism's
    count (Cho 1992: 6 elements; 8 differ from 6 by < 0.1 % relative RMS at 269 and 391 rpm).
    """
    elements = base.elements_per_link or 2 * mechanism.elements_per_link
    return dataclasses.replace(base, elements_per_link=int(elements), rigid_crank=False,
                               geometric_stiffness=True)


def full_order_dofs(mechanism, options):
    """DOFs of the full-order FE model of ``options`` (None if not available)."""
    try:
        from ..core.fe import linkage as assembly
        return assembly.FlexibleLinkage(reduced.fe_mechanism(mechanism, options),
                                        options).size
    except Exception:   # noqa: BLE001 -- no FE model (toy systems, stripped checkouts)
        return None


def physics_candidates(mechanism, base, scene):
    """
    Physics simplifications of the scene, cheapest first, the scene's own physics last.

    Rigid crank yes/no x geometric stiffness off/on x elements per link (:data:`PLAN_ELEMENTS`
    and the mechanism's count, below the scene's), plus the opposite bearing model (expected
    to fail: the scene's bearing model is the user's). Ordered by full-order DOFs, geometric
    stiffness off before on, so the first acceptable one is the cheapest to build.
    """
    elements = sorted(e for e in {*PLAN_ELEMENTS, mechanism.elements_per_link}
                      if e < scene.elements_per_link)
    other = 'rigid' if scene.bearings == 'flexible' else 'flexible'
    candidates = [dataclasses.replace(scene, elements_per_link=e, rigid_crank=rigid,
                                      geometric_stiffness=geometric)
                  for e in elements for rigid in (True, False) for geometric in (False, True)]
    candidates.append(dataclasses.replace(scene, bearings=other,
                                          elements_per_link=mechanism.elements_per_link))
    if other == 'flexible' and not mechanism.bearing_stiffness:
        candidates.pop()
    costs = {o: (full_order_dofs(mechanism, o) or 0, o.geometric_stiffness)
             for o in candidates}
    return sorted(candidates, key=costs.__getitem__) + [scene]


def physics_key(options):
    """The physical choices of ``options`` (what its full-order reference depends on)."""
    return (options.elements_per_link, options.rigid_crank, options.bearings,
            options.geometric_stiffness)


def describe_physics(options):
    """Short label: elements, crank, geometric stiffness, bearings."""
    return (f'{options.elements_per_link} el, {"rigid" if options.rigid_crank else "flex"} '
            f'crank, GS {"on" if options.geometric_stiffness else "off"}, '
            f'{options.bearings} bearings')


class PlanSignals:
    """
    Per speed: the synthetic signal, the last revolution's angles, and full-order references.

    Every candidate sees the same signal at a speed, so references at those angles are
    computed once per physics (``reduced.reference_response`` keeps one entry only).
    """

    def __init__(self, mechanism, speeds_rpm, rate_hz):
        self.mechanism = mechanism
        self.speeds_rpm = list(speeds_rpm)
        self.signals = {}
        for rpm in self.speeds_rpm:
            period = 2.0 * math.pi / (rpm * RPM)
            stamps, angles, speeds = synthetic_signal(rpm, 2.0 * period, rate_hz)
            self.signals[rpm] = (stamps, angles, speeds, last_revolution(stamps, rpm))
        self.references = {}
        self.seconds = {}

    def reference(self, options, rpm):
        """Full-order response of the physics of ``options`` at ``rpm`` (cached)."""
        key = (physics_key(options), rpm)
        if key not in self.references:
            _, angles, _, mask = self.signals[rpm]
            start = time.perf_counter()
            self.references[key] = reduced.reference_response(self.mechanism, options,
                                                              rpm * RPM, angles[mask])
            self.seconds[key] = time.perf_counter() - start
        return self.references[key]

    def reference_seconds(self, options):
        """Time spent on the full-order references of ``options`` [s]."""
        return sum(s for (k, _), s in self.seconds.items() if k == physics_key(options))

    def replay(self, model, rpm):
        """The model's estimate over the last revolution at ``rpm``."""
        stamps, angles, speeds, mask = self.signals[rpm]
        out = replay(model, stamps, angles, speeds)
        return {key: out[key][mask] for key in ('lever_tip', 'coupler_mid')}


def _errors(estimate, reference):
    return {key: relative_rms(estimate[key], reference[key])
            for key in ('coupler_mid', 'lever_tip')}


def _max_errors(rows_per_speed):
    return {key: max(row[key] for row in rows_per_speed)
            for key in ('coupler_mid', 'lever_tip')}


def physics_error(signals, scene, options, budget):
    """
    Full-order response of ``options`` against the scene's: relative RMS, max over speeds.

    Speeds are taken highest first; one already over ``budget`` ends the evaluation (the
    candidate cannot be accepted), so the returned maximum covers ``speeds`` only.

    Returns
    -------
    errors : dict
        'coupler_mid', 'lever_tip'.
    speeds : list of float
        Speeds evaluated [rpm].

    """
    per_speed, speeds = [], []
    for rpm in sorted(signals.speeds_rpm, reverse=True):
        if physics_key(options) == physics_key(scene):
            per_speed.append({'coupler_mid': 0.0, 'lever_tip': 0.0})
        else:
            per_speed.append(_errors(signals.reference(options, rpm),
                                     signals.reference(scene, rpm)))
        speeds.append(rpm)
        if max(per_speed[-1].values()) > budget:
            break
    return _max_errors(per_speed), speeds


def evaluate_model(signals, scene, options, rate_hz):
    """
    Build the reduced model of ``options`` and measure its cost and errors.

    Returns
    -------
    dict
        size, bytes, build_s, us_per_sample (median streaming update), error_coupler_mid and
        error_lever_tip (against the scene reference, max over the speeds), and
        truncation_error_* (against the full-order model of its own physics).

    """
    start = time.perf_counter()
    model = reduced.model_for_mechanism(signals.mechanism, options, use_cache=False)
    build_s = time.perf_counter() - start
    total, truncation = [], []
    for rpm in signals.speeds_rpm:
        estimate = signals.replay(model, rpm)
        total.append(_errors(estimate, signals.reference(scene, rpm)))
        truncation.append(_errors(estimate, signals.reference(options, rpm)))
    stamps, angles, speeds = synthetic_signal(max(signals.speeds_rpm), 0.3, rate_hz)
    _, update_ns = stream_timed(model, stamps, angles, speeds)
    median, _ = timing_summary(update_ns)
    total, truncation = _max_errors(total), _max_errors(truncation)
    return {'size': model.size, 'grid_size': model.grid_size, 'bytes': int(model.nbytes),
            'build_s': build_s, 'us_per_sample': median,
            'error_coupler_mid': total['coupler_mid'], 'error_lever_tip': total['lever_tip'],
            'truncation_error_coupler_mid': truncation['coupler_mid'],
            'truncation_error_lever_tip': truncation['lever_tip']}


def _meets(row, tolerance):
    return (row.get('error_coupler_mid') is not None
            and row['error_coupler_mid'] <= tolerance and row['error_lever_tip'] <= tolerance)


def run_plan(mechanism, base, rpm_max, tolerance, rate_hz=1000.0, speeds_rpm=None,
             max_candidates=None, physics=None, scene=None):
    """
    The smallest model (physics and size) meeting ``tolerance`` against the scene reference.

    Scene reference. The full-order periodic response (core/simulate.py via
    ``reduced.reference_response``) of the richest model of the scene,
    :func:`scene_options`: the user's bearings, flexible crank, geometric stiffness, refined
    elements. Outputs are physical points (lever side of B, coupler material mid-point,
    ground-frame elastic deflection), the same for every element count and crank model, so
    every candidate is compared with this one reference at the same crank angles: the last
    revolution of a constant-speed signal at each speed (the paper's speeds up to ``rpm_max``,
    and ``rpm_max``); errors are relative RMS, the max over the speeds.

    Search (two stages, every evaluated candidate is a row of 'alternatives').

    1. Physics: the candidates of :func:`physics_candidates` (rigid crank, geometric stiffness
       off/on, elements per link, the opposite bearing model; the scene's own physics last),
       cheapest first. Each one's full-order response is compared with the scene's (the
       physics error, no truncation in it). One within ``tolerance / 2`` (half the budget is
       left to the reduction) is then built at the generous size (the last of
       :func:`plan_candidates`); the first whose reduced model meets ``tolerance`` there is
       chosen, and the later physics candidates are not evaluated.
    2. Size: :func:`plan_candidates` of the chosen physics (modes x static x grid; cost is
       basis size r, then grid). Per grid, smallest first: the largest r that would still
       beat the current choice is built; if it meets ``tolerance`` the smaller r of that grid
       are bisected for the first meeting it (assuming the error falls with r; the rows show
       every size tried). The grid matters on its own: with a flexible crank the angle
       interpolation of a 128-point grid leaves ~1 % on the coupler whatever the basis.

    Parameters
    ----------
    mechanism : Mechanism
    base : ModelOptions
        Bearings, speed range, and the scene's elements (``elements_per_link``, None: twice
        the mechanism's); its crank, geometric stiffness and sizes are what the plan chooses.
    rpm_max : float
        Largest speed [rpm].
    tolerance : float
        Relative RMS error target on both outputs.
    rate_hz : float
        Sample rate of the synthetic signals [Hz].
    speeds_rpm : sequence of float or None
        Speeds checked (default: PAPER_RPM capped at ``rpm_max``, and ``rpm_max``).
    max_candidates : int or None
        Stop after this many reduced models built.
    physics : list of ModelOptions or None
        Physics candidates in order (default :func:`physics_candidates`).
    scene : ModelOptions or None
        Options of the scene reference (default :func:`scene_options`).

    Returns
    -------
    dict
        'choice' (a row) or None, 'alternatives' (every evaluated row: 'stage' 'physics' or
        'size', options, dofs, physics_error_* (full order vs scene), error_* (reduced vs
        scene; None when not built), truncation_error_* (reduced vs its own full order),
        size, bytes, build_s, us_per_sample), 'reference' (the scene), 'speeds_rpm',
        'tolerance', 'seconds'.

    """
    started = time.perf_counter()
    speeds_rpm = list(speeds_rpm or sorted({min(s, rpm_max) for s in PAPER_RPM} | {rpm_max}))
    scene = scene or scene_options(mechanism, base)
    physics = physics if physics is not None else physics_candidates(mechanism, base, scene)
    signals = PlanSignals(mechanism, speeds_rpm, rate_hz)
    for rpm in speeds_rpm:
        source = signals.reference(scene, rpm).get('source')
    reference = {'options': dataclasses.asdict(scene), 'label': describe_physics(scene),
                 'dofs': full_order_dofs(mechanism, scene), 'source': source,
                 'steps_per_revolution': reduced.REFERENCE_STEPS,
                 'seconds': signals.reference_seconds(scene),
                 'description': 'full-order periodic response of the richest model of the '
                                'scene (flexible crank, geometric stiffness, refined '
                                'elements, the requested bearings)'}
    rows, built, chosen_physics = [], 0, None
    budget = 0.5 * tolerance

    def build(options, stage, extra):
        nonlocal built
        row = {'stage': stage, 'options': dataclasses.asdict(options),
               'label': describe_physics(options), **extra}
        try:
            row.update(evaluate_model(signals, scene, options, rate_hz))
        except (np.linalg.LinAlgError, ValueError) as exc:   # e.g. r above the FE DOFs
            row.update({'size': None, 'grid_size': None, 'bytes': None, 'build_s': None,
                        'us_per_sample': None, 'error_coupler_mid': None,
                        'error_lever_tip': None, 'failed': str(exc)})
        row['meets_tolerance'] = _meets(row, tolerance)
        rows.append(row)
        built += 1
        return row

    for options in physics:
        if max_candidates is not None and built >= max_candidates:
            break
        errors, evaluated = physics_error(signals, scene, options, budget)
        extra = {'dofs': full_order_dofs(mechanism, options),
                 'physics_error_coupler_mid': errors['coupler_mid'],
                 'physics_error_lever_tip': errors['lever_tip'],
                 'physics_speeds_rpm': evaluated,
                 'reference_s': signals.reference_seconds(options)}
        if max(errors.values()) > budget:
            rows.append({'stage': 'physics', 'options': dataclasses.asdict(options),
                         'label': describe_physics(options), **extra, 'size': None,
                         'grid_size': None, 'bytes': None, 'build_s': None,
                         'us_per_sample': None, 'error_coupler_mid': None,
                         'error_lever_tip': None, 'meets_tolerance': False})
            continue
        sizes = plan_candidates(options)
        row = build(sizes[-1], 'physics', extra)
        if row['meets_tolerance']:
            chosen_physics = (sizes, extra, row)
            break
    choice = None
    if chosen_physics is not None:
        sizes, extra, choice = chosen_physics
        sized = []

        def cost(options):
            options = options if isinstance(options, dict) else dataclasses.asdict(options)
            return (options['modes'] + options['static'], options['grid_size'])

        for grid in sorted({o.grid_size for o in sizes}):
            if max_candidates is not None and built >= max_candidates:
                break
            # sizes at this grid that would beat the current choice, small to large
            below = [o for o in sizes if o.grid_size == grid
                     and cost(o) < cost(choice['options'])]
            if not below:
                continue
            row = build(below[-1], 'size', extra)    # the largest: can this grid serve?
            sized.append(row)
            if not row['meets_tolerance']:
                continue
            choice = row
            low, high = 0, len(below) - 1            # below[high] meets the tolerance
            while low < high and (max_candidates is None or built < max_candidates):
                middle = (low + high) // 2
                row = build(below[middle], 'size', extra)
                sized.append(row)
                if row['meets_tolerance']:
                    high, choice = middle, row
                else:
                    low = middle + 1
        rows = [r for r in rows if r['stage'] == 'physics'] + sorted(
            sized, key=lambda r: cost(r['options']))
    return {'speeds_rpm': speeds_rpm, 'tolerance': tolerance, 'choice': choice,
            'alternatives': rows, 'reference': reference,
            'seconds': time.perf_counter() - started}


def _fmt(value, spec, width):
    return f'{"-":>{width}}' if value is None else f'{value:>{width}{spec}}'


def plan_table(result):
    """Text table of :func:`run_plan`'s rows."""
    ref = result['reference']
    speeds = ', '.join(f'{s:g}' for s in result['speeds_rpm'])
    lines = [f'reference: {ref["label"]} ({ref["dofs"]} DOFs, {ref["source"]}, '
             f'{ref["seconds"]:.1f} s), speeds {speeds} rpm, tolerance {result["tolerance"]:g}',
             f'{"stage":<7} {"physics":<42} {"n":>3} {"modes":>5} {"stat":>4} {"grid":>4} '
             f'{"r":>3} {"MB":>6} {"build s":>7} {"us":>6} {"phys c":>8} {"phys l":>8} '
             f'{"trunc c":>8} {"trunc l":>8} {"coupler":>8} {"lever":>8} ok']
    for row in result['alternatives']:
        o = row['options']
        built = row['size'] is not None
        lines.append(
            f'{row["stage"]:<7} {row["label"]:<42} {_fmt(row.get("dofs"), "d", 3)} '
            f'{_fmt(o["modes"] if built else None, "d", 5)} '
            f'{_fmt(o["static"] if built else None, "d", 4)} '
            f'{_fmt(o["grid_size"] if built else None, "d", 4)} {_fmt(row["size"], "d", 3)} '
            f'{_fmt(None if row["bytes"] is None else row["bytes"] / 1e6, ".1f", 6)} '
            f'{_fmt(row["build_s"], ".1f", 7)} {_fmt(row["us_per_sample"], ".0f", 6)} '
            f'{_fmt(row.get("physics_error_coupler_mid"), ".2e", 8)} '
            f'{_fmt(row.get("physics_error_lever_tip"), ".2e", 8)} '
            f'{_fmt(row.get("truncation_error_coupler_mid"), ".2e", 8)} '
            f'{_fmt(row.get("truncation_error_lever_tip"), ".2e", 8)} '
            f'{_fmt(row["error_coupler_mid"], ".2e", 8)} '
            f'{_fmt(row["error_lever_tip"], ".2e", 8)} '
            f'{"yes" if row["meets_tolerance"] else "no"}')
    chosen = result['choice']
    if chosen:
        o = chosen['options']
        lines.append(f'choice: {chosen["label"]}, {o["modes"]} modes + {o["static"]} static, '
                     f'grid {o["grid_size"]} (r = {chosen["size"]}): coupler '
                     f'{chosen["error_coupler_mid"]:.2e}, lever {chosen["error_lever_tip"]:.2e}, '
                     f'{chosen["us_per_sample"]:.0f} us/sample')
    else:
        lines.append('choice: none of the candidates meets the tolerance')
    lines.append(f'(physics error: full order vs the reference; trunc: reduced vs its own full '
                 f'order; coupler/lever: reduced vs the reference; plan took '
                 f'{result["seconds"]:.0f} s)')
    return '\n'.join(lines)


def _plan(args):
    mechanism = load_mechanism(args.mechanism)
    base = model_options(args)
    result = run_plan(mechanism, base, args.rpm_max, args.tolerance, args.rate_hz)
    return emit(result, plan_table(result), args.json)


def reference_cpu_per_second(mechanism, options, rpm, rate_hz):
    """Full-order CPU per simulated second (None if the FE model is not available)."""
    try:
        return full_order_cpu_per_second(mechanism, options, rpm, rate_hz)
    except (ImportError, AttributeError, TypeError):
        return None


def bench_configurations(base):
    """The configurations compared by ``bench``: the default first."""
    smaller = dataclasses.replace(base, modes=max(1, base.modes - 4))
    larger = dataclasses.replace(base, modes=base.modes + 4)
    return [('default', base),
            (f'{smaller.modes} modes + {smaller.static} static', smaller),
            (f'{larger.modes} modes + {larger.static} static', larger),
            ('no static', dataclasses.replace(base, static=0)),
            ('grid 64', dataclasses.replace(base, grid_size=64)),
            ('grid 256', dataclasses.replace(base, grid_size=256))]


def interleaved_timing(entries, signal, long_signal, rounds=3):
    """
    Streaming and offline cost of several (model, step) entries, timed in interleaved rounds.

    Every round times every entry once, so a slow spell of a shared machine hits all of them
    alike; each entry keeps its best round (lowest median: the slower rounds measure the
    neighbours). Streaming over ``signal``, offline replay over ``long_signal`` (stamps,
    angles, speeds).

    Parameters
    ----------
    entries : dict
        key -> (model, compiled).

    Returns
    -------
    dict
        key -> us_per_sample, us_per_sample_p99, offline_samples_per_s.
    """
    best = {key: {'us_per_sample': math.inf, 'offline_samples_per_s': 0.0} for key in entries}
    for _ in range(rounds):
        for key, (model, compiled) in entries.items():
            median, p99 = timing_summary(stream_timed(model, *signal, compiled=compiled)[1])
            start = time.perf_counter()
            replay(model, *long_signal, compiled=compiled)
            offline = long_signal[0].size / (time.perf_counter() - start)
            row = best[key]
            if median < row['us_per_sample']:
                row.update(us_per_sample=median, us_per_sample_p99=p99)
            row['offline_samples_per_s'] = max(row['offline_samples_per_s'], offline)
    return best


def run_bench(mechanism, base, rate_hz=1000.0, seconds=2.0, speeds_rpm=PAPER_RPM,
              configurations=None, chart=None):
    """
    Side-by-side costs and errors of the configurations (see module docstring).

    Returns
    -------
    dict
        'configurations': per configuration us/sample (median, p99), offline samples/s,
        errors per speed, model bytes; 'reference_cpu_s_per_s'; 'cpu_ratio'; 'chart'.

    """
    rows = []
    reference_cpu = None
    signal = synthetic_signal(max(speeds_rpm), seconds, rate_hz)
    long_signal = synthetic_signal(max(speeds_rpm), OFFLINE_SECONDS, rate_hz)
    models, entries = [], {}
    for label, options in configurations or bench_configurations(base):
        model = reduced.model_for_mechanism(mechanism, options, use_cache=False)
        models.append((label, options, model))
        entries[label] = (model, compiled_step_available())
    # The default's numpy step too (the compiled step's reference and fallback).
    numpy_key = ('numpy step',)
    entries[numpy_key] = (models[0][2], False)
    timings = interleaved_timing(entries, signal, long_signal)
    numpy_step = timings.pop(numpy_key)
    for label, options, model in models:
        timing = timings[label]
        errors = {}
        for rpm in speeds_rpm:
            errors[f'{rpm:g}'] = configuration_error(mechanism, model, options, rpm, rate_hz)
        if reference_cpu is None:
            reference_cpu = reference_cpu_per_second(mechanism, options, max(speeds_rpm),
                                                     rate_hz)
        rows.append({
            'label': label, 'default': label == 'default', 'size': model.size,
            'grid_size': model.grid_size, 'bytes': int(model.nbytes),
            'us_per_sample': timing['us_per_sample'],
            'us_per_sample_p99': timing['us_per_sample_p99'],
            'offline_samples_per_s': timing['offline_samples_per_s'],
            'error_coupler_mid': max(e['error_coupler_mid'] for e in errors.values()),
            'error_lever_tip': max(e['error_lever_tip'] for e in errors.values()),
            'errors': errors})
    estimator_cpu = rows[0]['us_per_sample'] * 1e-6 * rate_hz  # CPU s per simulated s
    result = {'rate_hz': rate_hz, 'configurations': rows,
              'reference_cpu_s_per_s': reference_cpu,
              'estimator_cpu_s_per_s': estimator_cpu,
              'cpu_ratio': (reference_cpu / estimator_cpu) if reference_cpu else None,
              'compiled_step': compiled_step_available(),
              'numpy_step': numpy_step}
    default = rows[0]
    result['targets'] = [
        {'name': 'update median', 'value': default['us_per_sample'], 'unit': 'us',
         'target': '<= 20', 'met': default['us_per_sample'] <= 20.0},
        {'name': 'offline', 'value': default['offline_samples_per_s'], 'unit': 'samples/s',
         'target': '>= 50000', 'met': default['offline_samples_per_s'] >= 50_000.0},
        {'name': 'CPU vs full order at 1 kHz', 'value': result['cpu_ratio'], 'unit': 'x less',
         'target': '>= 100', 'met': bool(result['cpu_ratio'] and result['cpu_ratio'] >= 100.0)},
    ]
    if chart:
        from ..report.estimator import plot_error_vs_cost
        result['chart'] = str(plot_error_vs_cost(rows, chart))
    return result


def _bench(args):
    mechanism = load_mechanism(args.mechanism)
    chart = None if args.no_chart else pathlib.Path(args.out) / 'estimator_error_vs_cost.png'
    result = run_bench(mechanism, model_options(args), args.rate_hz, chart=chart)
    lines = [f'{"configuration":<22} {"r":>3} {"grid":>5} {"us p50":>7} {"us p99":>7} '
             f'{"offline/s":>10} {"coupler":>9} {"lever":>9} {"MB":>6}']
    for row in result['configurations']:
        lines.append(f'{row["label"]:<22} {row["size"]:>3} {row["grid_size"]:>5} '
                     f'{row["us_per_sample"]:>7.1f} {row["us_per_sample_p99"]:>7.1f} '
                     f'{row["offline_samples_per_s"]:>10.0f} '
                     f'{row["error_coupler_mid"]:>9.2e} {row["error_lever_tip"]:>9.2e} '
                     f'{row["bytes"] / 1e6:>6.2f}')
    numpy_step = result['numpy_step']
    lines.append(f'{"default, numpy step":<22} {"":>3} {"":>5} '
                 f'{numpy_step["us_per_sample"]:>7.1f} {numpy_step["us_per_sample_p99"]:>7.1f} '
                 f'{numpy_step["offline_samples_per_s"]:>10.0f}   (the same numbers; '
                 + ('every row timed in interleaved rounds, best of 3)'
                    if result['compiled_step'] else 'the compiled step is NOT built)'))
    if result['cpu_ratio']:
        lines.append(f'full-order reference: {result["reference_cpu_s_per_s"]:.3g} CPU s per '
                     f'simulated s; estimator {result["estimator_cpu_s_per_s"]:.3g} '
                     f'({result["cpu_ratio"]:.0f}x less)')
    for target in result['targets']:
        value = target['value']
        lines.append(f'target {target["name"]}: {"n/a" if value is None else f"{value:.4g}"} '
                     f'{target["unit"]} (target {target["target"]}) '
                     f'{"met" if target["met"] else "NOT met"}')
    if result.get('chart'):
        lines.append(f'chart: {result["chart"]}')
    return emit(result, '\n'.join(lines), args.json)


def _common(parser):
    parser.add_argument('--mechanism', default='cho1992',
                        help='mechanism file or name (default: cho1992)')
    crank = parser.add_mutually_exclusive_group()
    crank.add_argument('--rigid-crank', dest='rigid_crank', action='store_true', default=False,
                       help='treat the crank as rigid (pin A fixed; the paper\'s Figs 20-22 '
                       'case)')
    crank.add_argument('--flexible-crank', dest='rigid_crank', action='store_false',
                       help='model the crank as a flexible beam (default, as the node)')
    parser.add_argument('--bearings', choices=('flexible', 'rigid'), default='flexible',
                        help='revolute bearings: springs of the mechanism file, or rigid')
    parser.add_argument('--no-geometric-stiffness', action='store_true',
                        help='leave out the geometric stiffness of the axial forces')
    parser.add_argument('--modes', type=int, help='basis directions from frozen modes')
    parser.add_argument('--static', type=int, help='basis directions from static responses')
    parser.add_argument('--grid-size', type=int, help='crank-angle grid points')
    parser.add_argument('--elements-per-link', type=int, help='beam elements per link')
    parser.add_argument('--rate-hz', type=float, default=1000.0, help='sample rate [Hz]')
    parser.add_argument('--cache-dir', default=None,
                        help='model cache directory (default: ~/.cache/flexlink_ros)')
    parser.add_argument('--no-cache', action='store_true', help='build without the cache')
    parser.add_argument('--json', action='store_true', help='print one JSON object')


def register(subparsers):
    """Add the estimate, plan and bench subcommands."""
    parser = subparsers.add_parser('estimate', help='streaming estimator on a synthetic '
                                   'constant-speed crank signal (last revolution)')
    _common(parser)
    parser.add_argument('--rpm', type=float, required=True, help='crank speed [rpm]')
    parser.add_argument('--seconds', type=float, default=3.0, help='signal length [s]')
    parser.add_argument('--jitter', type=float, default=0.0,
                        help='relative sample-time jitter, steps (1 +- jitter) / rate')
    parser.add_argument('--no-warm-start', action='store_true',
                        help='start from the static deflection, not the periodic state')
    parser.add_argument('--seed', type=int, default=0, help='jitter random seed')
    parser.set_defaults(func=_estimate)

    parser = subparsers.add_parser('plan', help='smallest model (physics and size) meeting a '
                                   'tolerance against the full-order response of the scene '
                                   '(flexible crank, geometric stiffness, refined elements, '
                                   '--bearings); --elements-per-link sets the reference\'s '
                                   'elements, crank and geometric-stiffness flags are ignored')
    _common(parser)
    parser.add_argument('--rpm-max', type=float, required=True, help='largest speed [rpm]')
    parser.add_argument('--tolerance', type=float, default=0.01,
                        help='relative RMS error target (default 0.01)')
    parser.set_defaults(func=_plan)

    parser = subparsers.add_parser('bench', help='estimator cost and accuracy side by side')
    _common(parser)
    parser.add_argument('--out', default='out', help='directory of the chart (default out/)')
    parser.add_argument('--no-chart', action='store_true', help='skip the chart')
    parser.set_defaults(func=_bench)
