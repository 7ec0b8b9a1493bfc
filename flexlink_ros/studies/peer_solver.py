"""
Exudyn's dynamic solver run for the peer: its banner held back, a failure said in one line.

Exudyn's C++ core writes "DYNAMIC SOLVER FAILED ..." to the process's standard output and
raises ``exudyn.SolverError``; a command's stdout carries its result and its errors are one
line, so :func:`solve_or_explain` holds the banner back and raises a FlexlinkError naming the
case and a hint.
"""

import contextlib
import io
import os
import sys
import tempfile

from ..errors import FlexlinkError


def solve_or_explain(exu, mbs, settings, case, bearings):
    """
    Run Exudyn's dynamic solver; a failure is one FlexlinkError with a hint, not a traceback.

    The solver's own banner ("DYNAMIC SOLVER FAILED ...", written to the process's stdout by
    its C++ core) is held back: stdout carries the command's result.

    Parameters
    ----------
    exu : module
        exudyn.
    mbs, settings
        The peer's system and simulation settings.
    case : str
        What was solved (speed, elements, bearings), for the message.
    bearings : str
        The peer's bearing model ('rigid' or 'springs'), for the hint.

    Raises
    ------
    FlexlinkError
        The case, the solver's verdict and a hint, on one line.

    """
    sys.stdout.flush()
    saved = os.dup(1)
    printed = io.StringIO()     # the banner comes through Python's print, or C++ to fd 1
    with tempfile.TemporaryFile() as held, contextlib.redirect_stdout(printed):
        os.dup2(held.fileno(), 1)
        try:
            ok = exu.SolveDynamic(mbs, settings)
            reason = ''
        except Exception as exc:   # exudyn.SolverError and the core's RuntimeErrors
            ok, reason = False, f' ({type(exc).__name__}: {" ".join(str(exc).split())})'
        finally:
            os.dup2(saved, 1)
            os.close(saved)
        held.seek(0)
        banner = held.read(65536).decode('utf-8', 'replace') + printed.getvalue()[-65536:]
    if ok:
        return
    said = ' "DYNAMIC SOLVER FAILED"' if 'SOLVER FAILED' in banner else ''
    hint = ('stiff bearing springs on light pins and short elements make its implicit steps '
            'diverge: compare with --bearings rigid, or fewer elements (--elements-per-link)'
            if bearings != 'rigid' else
            'try fewer elements per link (--elements-per-link) or another speed')
    raise FlexlinkError(f'the Exudyn peer failed at {case}{said}{reason}; hint: {hint}')
