"""A node and the crank driver run as a user runs them, and a small plan's parameters file."""

import argparse
import signal
import subprocess
import time

from flexlink_ros.cli import plan_params
from flexlink_ros.core.mechanism_file import load_mechanism
from flexlink_ros.core.reduction import mechanism_model
from flexlink_ros.names import FIRST_INPUT_MESSAGE, READY_MESSAGE

READY_TIMEOUT_S = 300.0     # node start-up incl. a first model build on a loaded machine


def wait_for_log(log_path, fragment, process, timeout_s):
    """Wait until ``fragment`` is in the log; fail with the log if the process ends first."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if fragment in log_path.read_text():
            return
        assert process.poll() is None, log_path.read_text()
        time.sleep(0.05)
    raise AssertionError(f'{fragment!r} not logged in {timeout_s} s:\n' + log_path.read_text())


def stream_node_with_driver(node_argv, driver_argv, log_path, env, stream_s, cwd=None,
                            first_input_timeout_s=20.0):
    """
    Start the node, then the driver once it is ready; stop both after ``stream_s``.

    The driver gets SIGINT once the node has streamed ``stream_s`` seconds, then the node,
    which must exit with 0; whatever is still running at the end is killed.
    """
    with open(log_path, 'w') as log:
        node = subprocess.Popen(node_argv, cwd=cwd, stdout=log, stderr=subprocess.STDOUT,
                                env=env)
        driver = None
        try:
            wait_for_log(log_path, READY_MESSAGE, node, READY_TIMEOUT_S)
            driver = subprocess.Popen(driver_argv, cwd=cwd, env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            wait_for_log(log_path, FIRST_INPUT_MESSAGE, node, first_input_timeout_s)
            time.sleep(stream_s)
            driver.send_signal(signal.SIGINT)
            driver.wait(timeout=20)
            node.send_signal(signal.SIGINT)
            assert node.wait(timeout=30) == 0, log_path.read_text()
        finally:
            for process in (driver, node):
                if process is not None and process.poll() is None:
                    process.kill()
                    process.wait()


def write_small_plan_params(path, mechanism_path, options, cache_dir, rpm_max, tolerance):
    """
    Write the node's parameters file `flexlink plan --params-out` writes, for ``options``.

    The plan's own function (:func:`cli.plan_params.write_params_file`) on a model of
    ``options`` built into ``cache_dir`` (a small one stands in for the plan's choice, which
    takes minutes to find). Returns the parameter values written.
    """
    mechanism = load_mechanism(mechanism_path)
    model = mechanism_model.model_for_mechanism(mechanism, options, cache_dir=cache_dir)
    args = argparse.Namespace(mechanism=str(mechanism_path), rpm_max=rpm_max, rate_hz=1000.0,
                              tolerance=tolerance)
    return plan_params.write_params_file(path, mechanism, options, model, args)
