"""Progress of the long subcommands: a tqdm bar on a terminal, plain lines otherwise."""

import fcntl
import io
import os
import pathlib
import pty
import struct
import subprocess
import sys
import termios
import time

from flexlink_ros.cli import progress as progress_module
from flexlink_ros.cli.progress import OnDemandProgress, Progress
from flexlink_ros.cli.report import _section_progress
from flexlink_ros.report.criteria import plot_criteria
from flexlink_ros.report.estimator import plot_estimator

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_not_a_terminal_gives_plain_lines_and_a_last_one_at_close():
    stream = io.StringIO()
    with Progress('job', 3, stream=stream) as progress:
        assert not progress.tty
        progress(0, what='first')
        progress(2, 4, 'second')        # a new total
        progress(4, what='last')
    text = stream.getvalue()
    assert '\r' not in text and text.count('\n') == 1
    assert text.startswith('job: 100% 4/4 [') and text.endswith('step/s] last\n')


def test_a_line_every_period_while_a_step_runs(monkeypatch):
    monkeypatch.setattr(progress_module, 'TICK_S', 0.01)
    monkeypatch.setattr(progress_module, 'LINE_PERIOD_S', 0.0)
    stream = io.StringIO()
    progress = Progress('slow', 2, stream=stream)
    progress(1, what='the long step')
    deadline = time.monotonic() + 60.0      # the ticker writes without further calls
    while stream.getvalue().count('\n') < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    progress.close()
    lines = stream.getvalue().splitlines()
    assert len(lines) >= 3 and all(line.startswith('slow:  50% 1/2') for line in lines)
    assert lines[0].endswith('the long step')


def test_a_terminal_gets_a_tqdm_bar_on_stderr_and_stdout_keeps_the_result():
    """Run a job with stderr on a real pseudo-terminal and stdout on a pipe."""
    code = ('from flexlink_ros.cli.progress import Progress\n'
            'with Progress("bench", 4) as progress:\n'
            '    for n in range(5):\n'
            '        progress(n, what=f"step {n}")\n'
            'print("{\\"result\\": 1}")\n')
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack('HHHH', 24, 100, 0, 0))  # 100 columns
    run = subprocess.Popen([sys.executable, '-c', code], cwd=ROOT, stdout=subprocess.PIPE,
                           stderr=slave, stdin=subprocess.DEVNULL)
    os.close(slave)
    terminal = b''
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:         # EIO: the child closed the terminal
            break
        if not chunk:
            break
        terminal += chunk
    os.close(master)
    stdout = run.stdout.read()
    assert run.wait() == 0
    assert stdout == b'{"result": 1}\n'
    text = terminal.decode()
    assert '\r' in text and 'bench: 100%|' in text and '4/4' in text
    assert '\u2588' in text      # the bar itself


def test_a_report_section_with_its_own_steps_reports_them_within_the_report():
    calls = []
    kwargs = _section_progress(plot_estimator, lambda *call: calls.append(call), 3, 4,
                               'Streaming estimator')
    kwargs['progress'](5, 16, 'timing round 1 of 3')
    assert calls == [(3, 4, 'Streaming estimator: timing round 1 of 3 (5/16)')]
    assert _section_progress(plot_criteria, calls.append, 0, 4, 'criteria') == {}
    assert _section_progress(plot_estimator, None, 0, 4, 'estimator') == {}


def test_on_demand_progress_is_silent_without_reports_and_shows_a_build(capsys):
    with OnDemandProgress('building') as progress:
        pass                                  # a cached model: nothing reported
    assert capsys.readouterr().err == ''
    with OnDemandProgress('building') as progress:
        progress(5.0, 100, 'assembled')
        progress(57.9, 100, 'basis')
        progress(100.0, 100, 'model built')
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2 and lines[0].startswith('building:   5%')
    assert lines[1].startswith('building: 100%') and lines[1].endswith('model built')
