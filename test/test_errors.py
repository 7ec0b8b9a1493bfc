"""errors: the hierarchy the node and the CLI rely on to catch flexlink's own errors."""

import inspect
import math
import struct

from flexlink_ros import errors
import pytest

CLASSES = [value for _, value in inspect.getmembers(errors, inspect.isclass)
           if value.__module__ == errors.__name__]


def test_every_error_is_a_flexlink_error_except_the_startup_interruption():
    assert len(CLASSES) >= 12
    for cls in CLASSES:
        if cls is errors.StartupInterrupted:
            assert issubclass(cls, SystemExit) and not issubclass(cls, Exception)
            assert cls('SIGTERM').code == 0      # an orderly exit
        else:
            assert issubclass(cls, errors.FlexlinkError), cls


def test_malformed_cdr_is_caught_as_value_error_and_struct_error():
    for base in (ValueError, struct.error, errors.FlexlinkError):
        with pytest.raises(base, match='short'):
            raise errors.MalformedCdr('short buffer')
    assert issubclass(errors.InputRejected, ValueError)


def test_messages_name_their_subject():
    assert str(errors.MechanismError('links.crank', 'negative length')) == \
        'links.crank: negative length'
    text = str(errors.LoopClosureError(math.pi / 2, 'singular'))
    assert text.startswith('linkage cannot assemble at crank angle 90.000 deg')
    assert str(errors.ConvergenceError('Newton', 12, 3.5e-4)) == \
        'Newton did not converge in 12 iterations (residual 0.00035)'
    assert str(errors.OutlierSample('speed 900 rad/s')) == 'outlier: speed 900 rad/s'
