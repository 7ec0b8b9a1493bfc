"""The estimator bench's configurations and targets (studies/bench.py)."""

import dataclasses
import math

from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.core.reduction.soft_basis import gap_ratios, MIN_GAP_RATIO
from flexlink_ros.core.reduction.soft_tables import node_values
from flexlink_ros.studies import bench
from flexlink_ros.studies.synthetic import synthetic_signal


def test_configurations_vary_one_size_at_a_time_around_the_default():
    base = ModelOptions.linear(modes=6, static=2, grid_size=128)
    rows = bench.bench_configurations(base)
    assert rows[0] == ('default', base)
    by_label = dict(rows)
    assert len(by_label) == len(rows) == 6
    assert (by_label['2 modes + 2 static'].modes, by_label['10 modes + 2 static'].modes) == (2, 10)
    assert by_label['no static'].static == 0 and by_label['no static'].modes == 6
    assert by_label['grid 64'].grid_size == 64 and by_label['grid 256'].grid_size == 256
    for _, options in rows:
        assert options.bearings == base.bearings and options.rigid_crank == base.rigid_crank
    # a smaller basis keeps at least one mode
    assert bench.bench_configurations(ModelOptions.linear(modes=3))[1][1].modes == 1


def test_targets_are_judged_from_the_default_configuration():
    fast = {'us_per_sample': 10.0, 'offline_samples_per_s': 100_000.0}
    slow = {'us_per_sample': 10.5, 'offline_samples_per_s': 99_999.0}
    met = bench.bench_targets({'configurations': [fast, slow], 'cpu_ratio': 100.0})
    assert [t['name'] for t in met] == ['update median', 'offline', 'CPU vs full order at 1 kHz']
    assert all(t['met'] for t in met)
    missed = bench.bench_targets({'configurations': [slow, fast], 'cpu_ratio': None})
    assert not any(t['met'] for t in missed)
    assert missed[0]['value'] == 10.5 and missed[1]['unit'] == 'samples/s'


def test_soft_rows_are_the_other_usable_gaps_and_soft_off():
    # the paper's rigid-crank scene, flexible bearings (16 + 2), grid 64: its model as loaded
    options = ModelOptions.linear(bearings='flexible', grid_size=64)
    model = mechanism_model.model_for_mechanism(load_mechanism('cho1992'), options)
    sizes = bench.usable_soft_sizes(model)
    ratios = gap_ratios(node_values(model, 'M')['1'], node_values(model, 'K'),
                        float(model.speed_max), 5000.0)
    assert sizes == [p for p in range(1, model.size) if ratios[p - 1] >= MIN_GAP_RATIO ** 2]
    rows = bench.soft_configurations(options, model)
    if model.soft is None:       # no usable gap: the default steps every coordinate already
        assert sizes == [] and rows == []
        return
    assert model.step_size == sizes[0]
    assert [m.step_size for _, _, m in rows] == sizes[1:] + [model.size]
    assert [o.soft_modes for _, o, _ in rows] == sizes[1:] + [0]
    assert rows[-1][0] == f'soft off (r = {model.size})' and rows[-1][2].soft is None
    for _, _, soft in rows:     # the same reduced tables, only the step's basis differs
        assert soft.table is model.table


def test_the_nonlinear_model_is_timed_against_the_linear_update_in_the_same_rounds():
    mechanism = dataclasses.replace(load_mechanism('cho1992'), elements_per_link=2)
    options = ModelOptions.linear(bearings='flexible', grid_size=32, elements_per_link=2)
    model = mechanism_model.model_for_mechanism(mechanism, options)
    timing = bench.nonlinear_timing(mechanism, options, model,
                                    synthetic_signal(391.0, 0.3, 1000.0), rounds=2)
    assert timing['refused'] == 0 and timing['newton_per_sample'] >= 1.0
    assert timing['ratio'] == timing['us_per_sample'] / timing['linear_us_per_sample']
    assert 0.0 < timing['us_per_sample'] <= timing['us_per_sample_p99']
    assert timing['offline_samples_per_s'] > 0 and timing['size'] > 0
    assert timing['damping'].startswith('beta')
    targets = {t['name']: t for t in bench.bench_targets(
        {'configurations': [{'us_per_sample': 5.0, 'offline_samples_per_s': 1e5}],
         'cpu_ratio': 100.0, 'nonlinear': timing})}
    assert targets['nonlinear update vs linear']['met'] == (timing['ratio'] <= 10.0)
    assert targets['nonlinear offline']['met'] == (timing['offline_samples_per_s'] >= 1e4)
    assert not math.isnan(targets['nonlinear update vs linear']['value'])
