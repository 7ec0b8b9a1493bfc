"""
The streaming update in one compiled call against the Python path it stands in for.

The same events (clean and jittered samples, outliers, a new regime, repeats, a backward
stamp, gaps, speed steps and speeds beyond the model's range, missing speeds, resets, a lowered
deflection bound, a non-finite state and filter, stamps of other types) go through two
estimators in lockstep: one with the compiled update, one with every sample on the Python path
(the same compiled step, filter and criteria). Every Sample field, every refusal, the counters
and the state after each event agree to rounding (bit for bit on x86-64), and the compiled path
took the ordinary samples while each kind of fallback happened. Against the numpy step the
samples agree to rounding, as the compiled step does (test_step.py).
"""

import dataclasses
import math
import pathlib
import re

from estimation_toys import cho_second_order_model, compiled_or_skip, SPEED, toy_model
from flexlink_ros.core.estimation import compiled_update, native
from flexlink_ros.core.estimation.compiled_update import (CompiledUpdate, FALLBACK_REASONS,
                                                          use_python_path)
from flexlink_ros.core.estimation.native import RECORD_SIZE
from flexlink_ros.core.estimation.sample import Sample, SampleFlag
from flexlink_ros.core.estimation.streaming import StreamingEstimator
from flexlink_ros.core.estimation.warm_start import WarmStartLimiter
from flexlink_ros.errors import OutlierSample
import numpy as np
import pytest

START_NS = 10**9
FLOAT_FIELDS = ('crank_angle', 'crank_speed', 'crank_accel', 'lever_tip', 'coupler_mid',
                'reaction_n', 'gamma_dot', 'criterion', 'error_indicator', 'modal',
                'nonlinearity')
EXACT_FIELDS = ('stamp_ns', 'near_zero', 'flags', 'message')


@pytest.fixture(scope='module', params=['toy', 'cho1992 order 2', 'cho1992 soft basis'])
def model(request):
    compiled_or_skip()
    if request.param == 'toy':
        return toy_model()
    if request.param == 'cho1992 order 2':
        return cho_second_order_model()
    soft = cho_second_order_model('flexible')   # stepped on 14 of its 18 coordinates
    assert soft.soft is not None and soft.step_size < soft.size
    return soft


def _signal(seed=3, seconds=0.6, jitter=0.5, rate_hz=1000.0):
    """(stamp_ns, angle, speed) of a jittered crank at SPEED with a slow speed ripple."""
    rng = np.random.default_rng(seed)
    times = np.cumsum((1.0 + jitter * rng.uniform(-1.0, 1.0, int(seconds * rate_hz))) / rate_hz)
    angle = SPEED * times + 0.2 * np.sin(3.0 * times) + 1e-3 * rng.normal(size=times.size)
    speed = SPEED + 0.6 * np.cos(3.0 * times)
    return [(START_NS + int(round(t * 1e9)), float(a), float(w))
            for t, a, w in zip(times, angle, speed)]


def _shift(events, dt_ns, angle=0.0, speed=None, speed_offset=0.0):
    """Shift events later by dt_ns, turn them by ``angle``, offset their speed (or 'none')."""
    return [(s + dt_ns, a + angle,
             None if speed == 'none' else w + speed_offset) for s, a, w in events]


def _events(model):
    """Events and actions covering the ordinary path and every fallback (see the docstring)."""
    base = _signal()
    base = base[:100] + _shift(base[100:], 12 * 10**6)                     # a 12 ms step
    out = [('event', e) for e in base[:150]]
    stamp, angle, speed = base[149]
    out += [('event', (stamp + 10**5, angle + 1.5, speed))]              # angle outlier
    out += [('event', (stamp + 2 * 10**5, angle, 3.0 * model.speed_max))]  # speed outlier
    out += [('event', e) for e in base[150:200]]
    out += [('event', base[199])]                                           # exact repeat
    out += [('event', base[190])]                                           # backward: restart
    tail = base[200:]
    out += [('event', e) for e in _shift(tail[:40], 20 * 10**6)]            # 20 ms gap
    out += [('event', e) for e in _shift(tail[40:80], 10**9)]               # gap: restart
    step = model.speed_max + 5.0                                           # speed step
    out += [('event', e) for e in _shift(tail[80:130], 10**9, speed_offset=step)]
    # A restart without speeds (the warm start deferred to the third sample), a new regime.
    out += [('event', e) for e in _shift(tail[130:170], 2 * 10**9, speed='none')]
    out += [('event', e) for e in _shift(tail[170:230], 2 * 10**9, angle=2.0)]
    fast = [(s, a, 1.3 * model.speed_max) for s, a, _ in _shift(tail[230:260], 2 * 10**9, 2.0)]
    out += [('event', e) for e in fast]                                     # beyond speed_max
    later = _shift(tail[260:], 2 * 10**9, angle=2.0)
    out += [('event', (np.int64(later[0][0]), np.float64(later[0][1]), later[0][2]))]
    out += [('event', (float(later[1][0]), later[1][1], math.nan))]       # float stamp, NaN
    out += [('event', e) for e in later[2:30]]
    out += [('reset', None)] + [('event', e) for e in later[30:60]]
    out += [('bound', 0.5)] + [('event', e) for e in later[60:90]] + [('bound', None)]
    out += [('event', e) for e in later[90:100]]     # (restarted, armed again)
    out += [('filter', None)] + [('event', e) for e in later[100:120]]
    out += [('state', None)] + [('event', e) for e in later[120:]]
    return out


def _estimator(model, compiled_update):
    limiter = WarmStartLimiter(burst=1000.0, clock=lambda: 0.0)   # deterministic warm starts
    estimator = StreamingEstimator(model, warm_start_limiter=limiter)
    if not compiled_update:
        use_python_path(estimator)
    return estimator


def _act(estimator, action, value, bound_m):
    """Apply one event or action; return the sample or the refusal (bound_m: the new bound)."""
    if action == 'event':
        try:
            return estimator.update(*value)
        except OutlierSample as exc:
            return ('outlier', str(exc))
    if action == 'reset':
        estimator.reset()
    elif action == 'bound':
        estimator.deflection_bound_m = bound_m
    elif action == 'filter':
        estimator.rate_filter.state[10:18] = math.inf      # the speed fit gone non-finite
    elif action == 'state':
        estimator._stepper.z[0] = math.inf                  # the stepped state (eta or q)
    return None


def _largest(values):
    """Largest finite |value| (1 if none)."""
    values = np.abs(np.array(values, dtype=float))
    return float(np.max(values[np.isfinite(values)])) if np.any(np.isfinite(values)) else 1.0


def _assert_same(fast, python, scale):
    if not isinstance(fast, Sample):
        assert fast == python
        return
    assert isinstance(python, Sample)
    for name in EXACT_FIELDS:
        assert getattr(fast, name) == getattr(python, name), name
    for name in FLOAT_FIELDS:
        np.testing.assert_allclose(getattr(fast, name), getattr(python, name), rtol=1e-12,
                                   atol=1e-12 * scale.get(name, 0.0), equal_nan=True,
                                   err_msg=name)


def test_compiled_update_equals_the_python_path_event_by_event(model):
    fast, python = _estimator(model, True), _estimator(model, False)
    assert isinstance(fast._compiled, CompiledUpdate) and fast.compiled
    bound0 = fast.deflection_bound_m
    reasons, outputs = set(), []
    for action, value in _events(model):
        # A bound below the running deflection (half the last one), then the model's again.
        bound_m = bound0 if action != 'bound' or value is None else value * max(
            abs(d) for d in python._last.lever_tip + python._last.coupler_mid)
        expected = _act(python, action, value, bound_m)
        got = _act(fast, action, value, bound_m)
        reasons.add(fast._compiled.fallback)
        outputs.append((got, expected))
        np.testing.assert_array_equal(fast.state, python.state)
        np.testing.assert_array_equal(fast.rate_filter.state, python.rate_filter.state)
        np.testing.assert_array_equal(fast.last_record, python.last_record)
    samples = [p for _, p in outputs if isinstance(p, Sample)]
    scale = {name: _largest([getattr(s, name) for s in samples]) for name in FLOAT_FIELDS}
    for got, expected in outputs:
        _assert_same(got, expected, scale)
    for counter in ('samples', 'outliers', 'out_of_bound', 'warm_starts', 'cold_starts'):
        assert getattr(fast, counter) == getattr(python, counter), counter
    fast._compiled.fall_back(fast._gate)
    assert fast._gate.last == python._gate.last
    # The compiled path took the ordinary samples; each kind of fallback happened.
    assert fast._compiled.taken > 0.8 * fast.samples
    assert set(FALLBACK_REASONS) - {'none'} <= reasons
    assert python.out_of_bound >= 3 and python.outliers >= 6
    flags = 0
    for sample in samples:
        flags |= sample.flags
    deferred = SampleFlag.WARM_START | SampleFlag.SPEED_FROM_ANGLE
    assert any(sample.flags & deferred == deferred for sample in samples)
    for flag in ('RESET', 'OUTLIER', 'REPEATED', 'LARGE_STEP', 'CLIPPED_SPEED',
                 'CLIPPED_ACCEL', 'SPEED_FROM_ANGLE', 'OUT_OF_BOUND', 'WARM_START'):
        assert flags & SampleFlag[flag], flag


def test_samples_are_made_as_the_class_makes_them(model, monkeypatch):
    """Written into Sample's slots; a class with a __post_init__ is called (it runs)."""
    events = _signal(seed=5, seconds=0.1)
    estimator = StreamingEstimator(model)
    assert estimator._compiled.fills_slots
    plain = [estimator.update(*event) for event in events]
    made = []

    @dataclasses.dataclass(slots=True)
    class Counted(Sample):

        def __post_init__(self):
            made.append(self.stamp_ns)

    monkeypatch.setattr(compiled_update, 'Sample', Counted)
    counted = StreamingEstimator(model)
    assert not counted._compiled.fills_slots
    samples = [counted.update(*event) for event in events]
    assert counted._compiled.taken == len(events) - 1 == len(made)
    assert all(type(s) is Counted for s in samples[1:])
    for got, expected in zip(samples, plain):
        _assert_same(got, expected, {})


def test_stamps_beyond_int64_stay_on_the_python_path(model):
    """The Python path takes integers of any size; the compiled path leaves them to it."""
    start = 2**63 + 10**9
    events = [(start + s - START_NS, a, w) for s, a, w in _signal(seed=6, seconds=0.05)]
    estimator, python = StreamingEstimator(model), _estimator(model, False)
    samples = [estimator.update(*event) for event in events]
    assert not estimator._compiled.armed and estimator._compiled.taken == 0
    assert samples[-1].stamp_ns == events[-1][0]
    for got, expected in zip(samples, [python.update(*event) for event in events]):
        _assert_same(got, expected, {})


def test_compiled_update_equals_the_numpy_step_to_rounding(model):
    events = _signal(seed=8, seconds=0.4)
    events += _shift(_signal(seed=9, seconds=0.2), 5 * 10**8, speed='none')
    runs = {}
    for compiled in (True, False):
        estimator = StreamingEstimator(model, compiled=compiled)
        runs[compiled] = [estimator.update(*event) for event in events]
    assert estimator.compiled is False
    for name in FLOAT_FIELDS:
        values = np.array([getattr(s, name) for s in runs[False]], dtype=float)
        scale = _largest(values)
        np.testing.assert_allclose(np.array([getattr(s, name) for s in runs[True]],
                                            dtype=float), values, rtol=0.0,
                                   atol=1e-9 * scale, equal_nan=True, err_msg=name)
    assert [s.flags for s in runs[True]] == [s.flags for s in runs[False]]


def test_compiled_update_refuses_buffers_that_do_not_fit(model):
    estimator = StreamingEstimator(model)
    stepper, record = estimator._stepper, estimator.last_record

    def build(**change):
        parts = {'stepper': stepper, 'rate_filter': estimator.rate_filter,
                 'gate': estimator._gate, 'nonlinearity': estimator.nonlinearity,
                 'record': record}
        parts.update(change)
        return CompiledUpdate(parts['stepper'], parts['rate_filter'], parts['gate'],
                              parts['nonlinearity'], parts['record'],
                              {'speed_max': 1.0, 'accel_limit': 1.0, 'large_step_s': 1.0,
                               'near_zero_fraction': 0.1, 'deflection_bound_m': 1.0,
                               'base_flags': 0})

    assert not build().armed
    with pytest.raises(ValueError, match='record'):
        build(record=np.zeros(RECORD_SIZE + 1))

    class ShortFilter:
        state = np.zeros(3)

    with pytest.raises(ValueError, match='filter'):
        build(rate_filter=ShortFilter())
    if estimator.nonlinearity.kernel_tables is not None:
        class OtherIndicator:
            context, table = estimator.nonlinearity.kernel_tables
            kernel_tables = (context[:-1], table)

        with pytest.raises(ValueError, match='context'):
            build(nonlinearity=OtherIndicator())


def test_fallback_reasons_and_flags_are_the_c_enums_in_order():
    """FALLBACK_REASONS names enum FALLBACK_* of _radau_step.c; the flags go in FLAG_* order."""
    source = pathlib.Path(native.__file__).with_name('_radau_step.c').read_text()
    reasons = re.search(r'enum\s*{\s*(FALLBACK_NONE[^}]*)}', source).group(1)
    names = [name.strip()[len('FALLBACK_'):].lower().replace('_', ' ')
             for name in reasons.split(',')]
    assert tuple(names) == FALLBACK_REASONS
    flags = re.search(r'enum\s*{\s*(FLAG_LARGE_STEP[^}]*)}', source).group(1)
    assert [name.strip() for name in flags.split(',')] == [
        'FLAG_LARGE_STEP', 'FLAG_CLIPPED_SPEED', 'FLAG_CLIPPED_ACCEL', 'FLAG_SPEED_FROM_ANGLE',
        'FLAGS']
    built = pathlib.Path(compiled_update.__file__).read_text()
    assert 'flags=(LARGE_STEP, CLIPPED_SPEED, CLIPPED_ACCEL, SPEED_FROM_ANGLE)' in built
