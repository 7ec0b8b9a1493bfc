"""The update timed around the step, compiled against Python path (benchmarks/update_bench.py)."""

from flexlink_ros.core.estimation.native import compiled_step_available
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.options import ModelOptions
from flexlink_ros.core.reduction import mechanism_model
import pytest
import update_bench


@pytest.mark.skipif(not compiled_step_available(), reason='compiled step not built')
def test_both_paths_are_timed_and_agree():
    """Both paths timed on the same samples (they agree, or it raises); no timed assertion."""
    model = mechanism_model.model_for_mechanism(load_mechanism('cho1992'),
                                                ModelOptions.linear(bearings='rigid'))
    result = update_bench.update_overhead(model, rounds=2, samples=200)
    # Every sample but the first (the start, on the Python path) went through the C call.
    assert result['samples'] == 401 and result['taken'] == 400
    for name in ('compiled', 'python'):
        assert 0.0 < result[name]['median_us'] <= result[name]['p99_us']
        assert result['around_step_us'][name] == pytest.approx(
            result[name]['median_us'] - result['step_us'])
    assert result['step_us'] > 0.0
