"""Progress lines of the node's model build: first, periodic, last."""

import time

from flexlink_ros.ros.progress_log import BUILD_MESSAGE, ProgressLog


def test_first_and_last_report_are_logged_and_the_rest_at_most_once_a_period():
    lines = []
    progress = ProgressLog(lines.append, period_s=0.05)
    for step in range(101):
        progress(step, 100, 'step')
    assert len(lines) == 2      # no period has passed between the reports
    assert lines[0] == f'{BUILD_MESSAGE}:   0 % (step)'
    assert lines[1].startswith(f'{BUILD_MESSAGE}: 100 %')
    progress(100, 100, 'again')     # 100 % is said once
    assert len(lines) == 2


def test_a_line_each_period_while_the_percentage_rises():
    lines = []
    progress = ProgressLog(lines.append, period_s=0.01)
    progress(1, 10)
    time.sleep(0.02)
    progress(1, 10)          # a period passed, but no progress: no line
    progress(5, 10)
    time.sleep(0.02)
    progress(7, 10)
    percents = [int(line.split(':')[1].split('%')[0]) for line in lines]
    assert percents == [10, 50, 70]


def test_node_first_start_logs_the_model_build_and_a_cached_start_does_not(tmp_path):
    """A real node with an empty cache directory: rising percentages up to 100 %."""
    import test_node
    from flexlink_ros.names import READY_MESSAGE
    cache = tmp_path / 'cache'
    logs = []
    for _ in range(2):      # a build, then the cached model
        node_process = test_node.NodeProcess(tmp_path, f'model.cache_dir:={cache}',
                                             'model.grid_size:=48')
        try:
            node_process.wait_for(READY_MESSAGE, test_node.READY_TIMEOUT_S)
        finally:
            node_process.stop()
        logs.append(node_process.log())
    lines = [line for line in logs[0].splitlines() if BUILD_MESSAGE in line]
    percents = [float(line.split(BUILD_MESSAGE + ':')[1].split('%')[0]) for line in lines]
    assert len(percents) >= 2 and percents[-1] == 100.0
    assert all(b > a for a, b in zip(percents, percents[1:]))
    assert logs[0].index(lines[-1]) < logs[0].index(READY_MESSAGE)
    assert BUILD_MESSAGE not in logs[1]
