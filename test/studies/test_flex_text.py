"""Text of the flexible four-bar report section (studies/flex_text.py): units of deflections."""

from flexlink_ros.studies.flex_text import deflection_unit
import numpy as np


def test_deflections_below_a_tenth_of_a_millimetre_are_micrometres():
    assert deflection_unit(np.array([[2e-5, -9.99e-5]])) == (1e6, '\u00b5m')
    assert deflection_unit([]) == (1e6, '\u00b5m')


def test_larger_deflections_are_millimetres_whatever_their_sign():
    assert deflection_unit(np.array([1e-5, -1e-4])) == (1e3, 'mm')
    assert deflection_unit(np.array([3e-3])) == (1e3, 'mm')
