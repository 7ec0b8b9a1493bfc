"""
``flexlink plan``: the smallest model (physics and size) meeting a tolerance.

Every candidate is compared with the full-order response of the richest model of the scene
(:func:`scene_options`) over a speed range, and the error and cost of the alternatives are
kept (see :func:`run_plan`). A candidate is scored by its full-order physics error and its
reduced model's error and cost, all on the same synthetic signals and full-order references
(:class:`PlanSignals`).
"""

import dataclasses
import math
import time

import numpy as np

from .configurations import usable_soft_sizes
from .synthetic import last_revolution, PAPER_RPM, stream_timed, synthetic_signal, timing_summary
from ..core.estimation.segment_replay import replay
from ..core.fe import linkage as assembly
from ..core.numerics import relative_rms, RPM
from ..core.reduction import mechanism_model
from ..core.reduction import reference as reduction_reference

# Element counts tried as simplifications (besides the mechanism's own count).
PLAN_ELEMENTS = (2, 3, 4)
# Basis sizes of the size stage: frozen-mode directions, static directions, grid points.
PLAN_MODES = (2, 4, 6, 8, 10, 12, 16, 20, 24)
PLAN_STATIC = (0, 2, 4)
PLAN_GRIDS = (64, 128, 256)
# The quick plan's one grid: the finest (a 128-point grid leaves ~1 % on a flexible crank).
QUICK_GRIDS = (256,)


def plan_candidates(base, grids=PLAN_GRIDS):
    """
    Size candidates (modes, static, grid) of one physics, from small to large.

    Sorted by basis size r = modes + static, then grid points (of ``grids``); the last is the
    generous size at which :func:`run_plan` screens a physics choice.
    """
    candidates = []
    for modes in PLAN_MODES:
        for static in PLAN_STATIC:
            for grid in grids:
                candidates.append(dataclasses.replace(base, modes=modes, static=static,
                                                      grid_size=grid))
    return sorted(candidates, key=lambda o: (o.modes + o.static, o.grid_size))


def scene_options(mechanism, base):
    """
    Give the richest model of the scene: the reference every candidate is compared with.

    The user's bearing model, geometric stiffness on, flexible crank, and
    ``base.elements_per_link`` beam elements per link if given, else twice the mechanism's
    count (Cho 1992: 6 elements; 8 differ from 6 by < 0.1 % relative RMS at 269 and 391 rpm).
    """
    elements = base.elements_per_link or 2 * mechanism.elements_per_link
    return dataclasses.replace(base, elements_per_link=int(elements), rigid_crank=False,
                               geometric_stiffness=True)


def quick_plan(mechanism, base, rpm_max, fixed=None):
    """
    Give :func:`run_plan`'s scene, physics, speeds and grids of a quick plan (``--quick``).

    The reference is the user's own physics (the file's elements per link, flexible crank,
    geometric stiffness, the requested bearings) rather than a refined one, no simpler physics
    is screened, the only speed is ``rpm_max`` and the only grid :data:`QUICK_GRIDS`: the
    plan then measures the reduction alone (modes, static directions, soft basis) against the
    full order of the model the node builds, in a few reduced models instead of dozens.
    """
    own = dataclasses.replace(base, elements_per_link=mechanism.elements_per_link)
    scene = scene_options(mechanism, own)
    return {'scene': scene, 'physics': constrain_physics([scene], fixed or {}),
            'speeds_rpm': [rpm_max], 'grids': QUICK_GRIDS}


def full_order_dofs(mechanism, options):
    """Count the DOFs of the full-order FE model of ``options`` (None if not available)."""
    try:
        return assembly.FlexibleLinkage(mechanism_model.fe_mechanism(mechanism, options),
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


def describe_physics(options):
    """Short label: elements, crank, geometric stiffness, bearings."""
    return (f'{options.elements_per_link} el, {"rigid" if options.rigid_crank else "flex"} '
            f'crank, GS {"on" if options.geometric_stiffness else "off"}, '
            f'{options.bearings} bearings')


def constrain_physics(candidates, fixed):
    """
    Keep the physical choices the user fixed in every candidate (the plan searches the rest).

    Each candidate gets the ``fixed`` fields; duplicates (by physics) are dropped, the first
    kept, so the order (cheapest first, the scene's physics with those fields last) stays.

    Parameters
    ----------
    candidates : list of ModelOptions
        :func:`physics_candidates`.
    fixed : dict
        Fields of :class:`ModelOptions` the user fixed ('rigid_crank', 'geometric_stiffness').

    """
    constrained = {}
    for options in candidates:
        options = dataclasses.replace(options, **fixed)
        constrained.setdefault(physics_key(options), options)
    return list(constrained.values())


def size_steps(sizes):
    """Most reduced models the size stage builds from ``sizes``: per grid, one and a bisection."""
    steps = 0
    for grid in {o.grid_size for o in sizes}:
        count = sum(o.grid_size == grid for o in sizes)
        steps += 1 + math.ceil(math.log2(max(count, 1)))
    return steps


def physics_key(options):
    """Key the physical choices of ``options`` (what its full-order reference depends on)."""
    return (options.elements_per_link, options.rigid_crank, options.bearings,
            options.geometric_stiffness)


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
            self.references[key] = reduction_reference.reference_response(self.mechanism, options,
                                                                          rpm * RPM, angles[mask])
            self.seconds[key] = time.perf_counter() - start
        return self.references[key]

    def reference_seconds(self, options):
        """Time spent on the full-order references of ``options`` [s]."""
        return sum(s for (k, _), s in self.seconds.items() if k == physics_key(options))

    def replay(self, model, rpm):
        """Estimate with ``model`` over the last revolution at ``rpm``."""
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


def soft_candidates(options, model):
    """
    List the soft basis sizes a plan tries on ``model``, cheapest first: (soft_modes, model).

    ``options.soft_modes`` -1: every usable gap (:func:`studies.configurations.usable_soft_sizes`),
    then all r coordinates (soft_modes 0); otherwise only the size asked for.
    """
    bare = dataclasses.replace(model, soft=None)
    sizes = usable_soft_sizes(bare) + [0] if options.soft_modes == -1 else [options.soft_modes]
    return [(p, mechanism_model.with_soft_basis(bare, p)) for p in sizes]


def measure_model(signals, scene, options, model, rate_hz):
    """
    Cost and errors of one model on the plan's signals.

    Returns
    -------
    dict
        us_per_sample (median streaming update), error_coupler_mid and error_lever_tip
        (against the scene reference, max over the speeds), truncation_error_* (against the
        full-order model of its own physics), step_size.

    """
    total, truncation = [], []
    for rpm in signals.speeds_rpm:
        estimate = signals.replay(model, rpm)
        total.append(_errors(estimate, signals.reference(scene, rpm)))
        truncation.append(_errors(estimate, signals.reference(options, rpm)))
    stamps, angles, speeds = synthetic_signal(max(signals.speeds_rpm), 0.3, rate_hz)
    _, update_ns = stream_timed(model, stamps, angles, speeds)
    median, _ = timing_summary(update_ns)
    total, truncation = _max_errors(total), _max_errors(truncation)
    return {'us_per_sample': median, 'step_size': int(model.step_size),
            'error_coupler_mid': total['coupler_mid'], 'error_lever_tip': total['lever_tip'],
            'truncation_error_coupler_mid': truncation['coupler_mid'],
            'truncation_error_lever_tip': truncation['lever_tip']}


def evaluate_model(signals, scene, options, rate_hz, tolerance=None):
    """
    Build the reduced model of ``options`` and measure its cost and errors.

    The soft basis size is chosen here (:func:`soft_candidates`, cheapest first): the first
    within ``tolerance`` on both outputs, else the most accurate; every size tried is listed.

    Returns
    -------
    dict
        size, bytes, build_s, soft_modes (chosen; 0: all r coordinates), 'soft_tried' (per
        size tried: soft_modes and :func:`measure_model`), and the chosen size's
        :func:`measure_model`.

    """
    start = time.perf_counter()
    model = mechanism_model.model_for_mechanism(signals.mechanism,
                                                dataclasses.replace(options, soft_modes=0),
                                                use_cache=False)
    build_s = time.perf_counter() - start
    tried = []
    for soft_modes, candidate in soft_candidates(options, model):
        tried.append({'soft_modes': soft_modes,
                      **measure_model(signals, scene, options, candidate, rate_hz)})
        if tolerance is not None and max(tried[-1]['error_coupler_mid'],
                                         tried[-1]['error_lever_tip']) <= tolerance:
            break
    chosen = tried[-1] if tolerance is not None and max(
        tried[-1]['error_coupler_mid'], tried[-1]['error_lever_tip']) <= tolerance else min(
        tried, key=lambda row: max(row['error_coupler_mid'], row['error_lever_tip']))
    return {'size': model.size, 'grid_size': model.grid_size,
            'bytes': int(model.nbytes), 'build_s': build_s, **chosen, 'soft_tried': tried}


def _meets(row, tolerance):
    return (row.get('error_coupler_mid') is not None
            and row['error_coupler_mid'] <= tolerance and row['error_lever_tip'] <= tolerance)


# The fields of a row whose reduced model was not built (None in the row).
_NOT_BUILT = ('size', 'grid_size', 'bytes', 'build_s', 'us_per_sample', 'error_coupler_mid',
              'error_lever_tip')


def _size_cost(options):
    """Cost order of a size: basis size r, then grid points (options or their dict)."""
    options = options if isinstance(options, dict) else dataclasses.asdict(options)
    return (options['modes'] + options['static'], options['grid_size'])


class _Search:
    """The rows of a plan so far, the number of reduced models built, and its progress."""

    def __init__(self, signals, scene, tolerance, rate_hz, max_candidates, progress,
                 grids=PLAN_GRIDS):
        self.signals, self.scene, self.tolerance = signals, scene, tolerance
        self.grids = grids
        self.rate_hz, self.max_candidates = rate_hz, max_candidates
        self.rows, self.built = [], 0
        self.progress, self.done, self.total = progress, 0, None

    def step(self, what, total=None):
        """Report the step starting now (``what``) and the steps so far (``progress``)."""
        self.total = total if total is not None else self.total
        if self.progress is not None:
            self.progress(self.done, self.total, what)
        self.done += 1

    def may_build(self):
        """Whether another reduced model may be built (``max_candidates``)."""
        return self.max_candidates is None or self.built < self.max_candidates

    def build(self, options, stage, extra):
        """Build and measure the model of ``options``; its row (kept)."""
        self.step(f'{stage}: {describe_physics(options)}, {options.modes}+{options.static} '
                  f'grid {options.grid_size}')
        row = {'stage': stage, 'options': dataclasses.asdict(options),
               'label': describe_physics(options), **extra}
        try:
            row.update(evaluate_model(self.signals, self.scene, options, self.rate_hz,
                                      self.tolerance))
            row['options']['soft_modes'] = row['soft_modes']
        except (np.linalg.LinAlgError, ValueError) as exc:   # e.g. r above the FE DOFs
            row.update(dict.fromkeys(_NOT_BUILT), failed=str(exc))
        row['meets_tolerance'] = _meets(row, self.tolerance)
        self.rows.append(row)
        self.built += 1
        return row


def _scene_reference(search, mechanism, scene, signals):
    """Describe the plan's reference: the scene's full-order responses at every speed."""
    for rpm in signals.speeds_rpm:
        search.step(f'reference at {rpm:g} rpm')
        source = signals.reference(scene, rpm).get('source')
    return {'options': dataclasses.asdict(scene), 'label': describe_physics(scene),
            'dofs': full_order_dofs(mechanism, scene), 'source': source,
            'steps_per_revolution': reduction_reference.REFERENCE_STEPS,
            'seconds': signals.reference_seconds(scene),
            'description': 'full-order periodic response of the richest model of the '
                           'scene (flexible crank, geometric stiffness, refined '
                           'elements, the requested bearings)'}


def _screen_physics(search, mechanism, physics):
    """
    Stage 1: the first physics within half the budget whose generous size meets it.

    Returns
    -------
    (sizes, extra, row) or None
        The chosen physics' size candidates, its physics fields and its row.

    """
    budget = 0.5 * search.tolerance
    for options in physics:
        if not search.may_build():
            break
        search.step(f'physics: {describe_physics(options)}')
        errors, evaluated = physics_error(search.signals, search.scene, options, budget)
        extra = {'dofs': full_order_dofs(mechanism, options),
                 'physics_error_coupler_mid': errors['coupler_mid'],
                 'physics_error_lever_tip': errors['lever_tip'],
                 'physics_speeds_rpm': evaluated,
                 'reference_s': search.signals.reference_seconds(options)}
        if max(errors.values()) > budget:
            search.rows.append({'stage': 'physics', 'options': dataclasses.asdict(options),
                                'label': describe_physics(options), **extra,
                                **dict.fromkeys(_NOT_BUILT), 'meets_tolerance': False})
            continue
        sizes = plan_candidates(options, search.grids)
        row = search.build(sizes[-1], 'physics', extra)
        if row['meets_tolerance']:
            return sizes, extra, row
    return None


def _bisect_grid(search, below, extra, choice, sized):
    """Bisect the sizes ``below`` (the last meets the tolerance) for the first meeting it."""
    low, high = 0, len(below) - 1
    while low < high and search.may_build():
        middle = (low + high) // 2
        row = search.build(below[middle], 'size', extra)
        sized.append(row)
        if row['meets_tolerance']:
            high, choice = middle, row
        else:
            low = middle + 1
    return choice


def _size_search(search, sizes, extra, choice):
    """
    Stage 2: per grid, the smallest size beating ``choice`` that meets the tolerance.

    Returns
    -------
    choice : dict
        The chosen row.
    sized : list of dict
        Every row built in this stage.

    """
    sized = []
    for grid in sorted({o.grid_size for o in sizes}):
        if not search.may_build():
            break
        # sizes at this grid that would beat the current choice, small to large
        below = [o for o in sizes if o.grid_size == grid
                 and _size_cost(o) < _size_cost(choice['options'])]
        if not below:
            continue
        row = search.build(below[-1], 'size', extra)    # the largest: can this grid serve?
        sized.append(row)
        if row['meets_tolerance']:
            choice = _bisect_grid(search, below, extra, row, sized)
    return choice, sized


def run_plan(mechanism, base, rpm_max, tolerance, rate_hz=1000.0, speeds_rpm=None,
             max_candidates=None, physics=None, scene=None, fixed=None, progress=None,
             grids=PLAN_GRIDS):
    """
    Find the smallest model (physics and size) meeting ``tolerance`` against the scene.

    Scene reference. The full-order periodic response (core/fe/simulate.py via
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

    Every reduced model built is measured at each soft basis size p with a usable spectral
    gap, then with all r coordinates (``base.soft_modes`` -1; a fixed p is kept), cheapest
    first: the first within ``tolerance`` is the row's (its 'soft_modes' and 'step_size';
    'soft_tried' lists every p tried), so p is chosen with the other sizes.

    Parameters
    ----------
    mechanism : Mechanism
        The mechanism.
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
    fixed : dict or None
        Physical choices the user fixed ('rigid_crank', 'geometric_stiffness'): every default
        physics candidate keeps them (:func:`constrain_physics`); the scene does not.
    progress : callable or None
        ``progress(done, total, what)`` before each step (a full-order reference, a physics
        screened, a reduced model built; ``total`` an upper bound until the end).
    grids : tuple of int
        Grid sizes of the size candidates (:func:`quick_plan` gives one).

    Returns
    -------
    dict
        'choice' (a row) or None, 'alternatives' (every evaluated row: 'stage' 'physics' or
        'size', options, dofs, physics_error_* (full order vs scene), error_* (reduced vs
        scene; None when not built), truncation_error_* (reduced vs its own full order),
        size, bytes, build_s, us_per_sample), 'reference' (the scene), 'speeds_rpm',
        'tolerance', 'fixed', 'seconds'.

    """
    started = time.perf_counter()
    speeds_rpm = list(speeds_rpm or sorted({min(s, rpm_max) for s in PAPER_RPM} | {rpm_max}))
    scene = scene or scene_options(mechanism, base)
    if physics is None:
        physics = constrain_physics(physics_candidates(mechanism, base, scene), fixed or {})
    signals = PlanSignals(mechanism, speeds_rpm, rate_hz)
    search = _Search(signals, scene, tolerance, rate_hz, max_candidates, progress, grids)
    # steps: the scene's references, each physics screened and built, the size stage at most
    search.total = (len(speeds_rpm) + 2 * len(physics)
                    + size_steps(plan_candidates(physics[-1] if physics else scene, grids)))
    reference = _scene_reference(search, mechanism, scene, signals)
    chosen_physics = _screen_physics(search, mechanism, physics)
    rows, choice = search.rows, None
    if chosen_physics is not None:
        sizes, extra, choice = chosen_physics
        search.total = search.done + size_steps(sizes)
        choice, sized = _size_search(search, sizes, extra, choice)
        rows = [r for r in search.rows if r['stage'] == 'physics'] + sorted(
            sized, key=lambda r: _size_cost(r['options']))
    search.step('done', total=search.done)
    return {'speeds_rpm': speeds_rpm, 'tolerance': tolerance, 'choice': choice,
            'alternatives': rows, 'reference': reference, 'fixed': dict(fixed or {}),
            'seconds': time.perf_counter() - started}
