"""The estimator's model configurations and their errors (studies/configurations.py)."""

from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.core.reduction import reference as reduction_reference
from flexlink_ros.core.reduction.soft_basis import gap_ratios, MIN_GAP_RATIO
from flexlink_ros.core.reduction.soft_tables import node_values
from flexlink_ros.studies import configurations
from toy_system import toy_model, toy_reference


def test_configurations_vary_one_size_at_a_time_around_the_default():
    base = ModelOptions.linear(modes=6, static=2, grid_size=128)
    rows = configurations.model_configurations(base)
    assert rows[0] == ('default', base)
    by_label = dict(rows)
    assert len(by_label) == len(rows) == 6
    assert (by_label['2 modes + 2 static'].modes, by_label['10 modes + 2 static'].modes) == (2, 10)
    assert by_label['no static'].static == 0 and by_label['no static'].modes == 6
    assert by_label['grid 64'].grid_size == 64 and by_label['grid 256'].grid_size == 256
    for _, options in rows:
        assert options.bearings == base.bearings and options.rigid_crank == base.rigid_crank
    # a smaller basis keeps at least one mode
    assert configurations.model_configurations(ModelOptions.linear(modes=3))[1][1].modes == 1


def test_soft_rows_are_the_other_usable_gaps_and_soft_off():
    # the paper's rigid-crank scene, flexible bearings (16 + 2), grid 64: its model as loaded
    options = ModelOptions.linear(bearings='flexible', grid_size=64)
    model = mechanism_model.model_for_mechanism(load_mechanism('cho1992'), options)
    sizes = configurations.usable_soft_sizes(model)
    ratios = gap_ratios(node_values(model, 'M')['1'], node_values(model, 'K'),
                        float(model.speed_max), 5000.0)
    assert sizes == [p for p in range(1, model.size) if ratios[p - 1] >= MIN_GAP_RATIO ** 2]
    rows = configurations.soft_configurations(options, model)
    if model.soft is None:       # no usable gap: the default steps every coordinate already
        assert sizes == [] and rows == []
        return
    assert model.step_size == sizes[0]
    assert [m.step_size for _, _, m in rows] == sizes[1:] + [model.size]
    assert [o.soft_modes for _, o, _ in rows] == sizes[1:] + [0]
    assert rows[-1][0] == f'soft off (r = {model.size})' and rows[-1][2].soft is None
    for _, _, soft in rows:     # the same reduced tables, only the step's basis differs
        assert soft.table is model.table


def test_rows_measure_each_configuration_and_report_each_step(monkeypatch):
    monkeypatch.setattr(mechanism_model, 'model_for_mechanism', toy_model)
    monkeypatch.setattr(reduction_reference, 'reference_response', toy_reference)
    calls = []
    base = ModelOptions.linear(modes=4, static=2, grid_size=32)
    rows = configurations.configuration_rows(None, base, lambda *call: calls.append(call))
    labels = [label for label, _ in configurations.model_configurations(base)]
    assert [row['label'] for row in rows][:1] == ['default'] and rows[0]['default']
    assert set(labels) <= {row['label'] for row in rows}
    assert [what for _, _, what in calls] == (
        [f'building {label}' for label in labels] + [f'errors of {row["label"]}' for row in rows])
    assert [done for done, _, _ in calls] == list(range(len(calls)))
    for row in rows:
        assert set(row['errors']) == {'269', '391'}
        assert row['error_coupler_mid'] == max(e['error_coupler_mid']
                                               for e in row['errors'].values())
        assert 'us_per_sample' not in row           # the timing is a benchmark's
