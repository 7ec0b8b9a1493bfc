"""
SIGINT/SIGTERM during flexlink_node's start-up: one line on stderr and exit code 0.

Imports nothing heavy: ``ros/node.py`` installs these handlers before numpy, scipy and rclpy
load (about a second). Until the node spins, a signal is acted on at once when no rclpy code
is on the interrupted stack, else at the next :func:`check_startup_signal` (an exception
raised inside rclpy can wedge it).
"""

import os
import signal

from ..errors import StartupInterrupted
from ..names import NODE_NAME

# Start-up state: 'active' until the node spins; 'signal' = a signal not acted on yet.
_STARTUP = {'active': False, 'signal': None}


def _in_rclpy(frame):
    """Whether rclpy code is on the interrupted stack (an exception there can wedge it)."""
    while frame is not None:
        if f'{os.sep}rclpy{os.sep}' in frame.f_code.co_filename:
            return True
        frame = frame.f_back
    return False


def _on_startup_signal(signum, frame):
    if not _STARTUP['active']:
        if signum == signal.SIGINT:     # spinning: rclpy has shut the context down already
            raise KeyboardInterrupt
        return
    _STARTUP['signal'] = signal.Signals(signum).name
    if not _in_rclpy(frame):
        check_startup_signal()


def check_startup_signal():
    """Exit (StartupInterrupted) if SIGINT/SIGTERM arrived during start-up; a safe point."""
    name = _STARTUP['signal']
    if _STARTUP['active'] and name is not None:
        _STARTUP['active'] = False
        os.write(2, f'{NODE_NAME}: {name} during start-up: exiting\n'.encode())
        raise StartupInterrupted(name)


def install_startup_signal_handlers():
    """SIGINT/SIGTERM end the process cleanly until the node spins (rclpy chains to these)."""
    _STARTUP['active'] = True
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _on_startup_signal)


def starting_up():
    """Whether the start-up handlers are acting (installed, and the node not spinning yet)."""
    return _STARTUP['active']


def startup_signal():
    """Name of a start-up signal not acted on yet, or None."""
    return _STARTUP['signal']


def end_startup():
    """From here on rclpy's shutdown ends the spin (signals are no longer start-up's)."""
    _STARTUP['active'] = False
