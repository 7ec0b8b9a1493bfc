"""The estimator bench's configurations and targets (studies/bench.py)."""

from flexlink_ros.core.options import ModelOptions
from flexlink_ros.studies import bench


def test_configurations_vary_one_size_at_a_time_around_the_default():
    base = ModelOptions(modes=6, static=2, grid_size=128)
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
    assert bench.bench_configurations(ModelOptions(modes=3))[1][1].modes == 1


def test_targets_are_judged_from_the_default_configuration():
    fast = {'us_per_sample': 20.0, 'offline_samples_per_s': 50_000.0}
    slow = {'us_per_sample': 20.5, 'offline_samples_per_s': 49_999.0}
    met = bench.bench_targets({'configurations': [fast, slow], 'cpu_ratio': 100.0})
    assert [t['name'] for t in met] == ['update median', 'offline', 'CPU vs full order at 1 kHz']
    assert all(t['met'] for t in met)
    missed = bench.bench_targets({'configurations': [slow, fast], 'cpu_ratio': None})
    assert not any(t['met'] for t in missed)
    assert missed[0]['value'] == 20.5 and missed[1]['unit'] == 'samples/s'
