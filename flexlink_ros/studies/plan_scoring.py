"""
How ``plan`` scores a candidate, and the candidates it keeps and counts.

Its full-order physics error and its reduced model's error and cost, all on the same
synthetic signals and full-order references.
"""

import dataclasses
import math
import time

from .bench import usable_soft_sizes
from .synthetic import last_revolution, stream_timed, synthetic_signal, timing_summary
from ..core.estimation.offline import replay
from ..core.numerics import relative_rms, RPM
from ..core.reduction import pipeline
from ..core.reduction import reference as reduction_reference


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

    ``options.soft_modes`` -1: every usable gap (:func:`studies.bench.usable_soft_sizes`),
    then all r coordinates (soft_modes 0); otherwise only the size asked for.
    """
    bare = dataclasses.replace(model, soft=None)
    sizes = usable_soft_sizes(bare) + [0] if options.soft_modes == -1 else [options.soft_modes]
    return [(p, pipeline.with_soft_basis(bare, p)) for p in sizes]


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
    model = pipeline.model_for_mechanism(signals.mechanism,
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
