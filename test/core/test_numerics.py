"""Unit factors, angle wrapping and the relative RMS error (core/numerics.py)."""

import math

from flexlink_ros.core import numerics
from flexlink_ros.core.numerics import relative_rms, RPM, TWO_PI, wrap_to_2pi, wrap_to_pi
import numpy as np
import pytest


def test_rpm_is_one_revolution_per_minute():
    assert 60.0 * RPM == pytest.approx(2.0 * math.pi, rel=1e-15)
    assert TWO_PI == 2.0 * math.pi
    assert numerics.RPM is RPM


@pytest.mark.parametrize('turns', [-3, -1, 0, 1, 2, 7])
def test_wrap_to_2pi_sends_exact_multiples_of_two_pi_to_zero(turns):
    assert wrap_to_2pi(turns * TWO_PI) == 0.0


@pytest.mark.parametrize('angle, expected', [
    (0.5, 0.5), (TWO_PI + 0.5, 0.5), (-0.5, TWO_PI - 0.5), (-TWO_PI - 0.5, TWO_PI - 0.5),
    (math.pi, math.pi), (-math.pi, math.pi), (5 * TWO_PI + 1.25, 1.25)])
def test_wrap_to_2pi_lands_in_zero_to_two_pi(angle, expected):
    wrapped = wrap_to_2pi(angle)
    assert 0.0 <= wrapped < TWO_PI
    assert wrapped == pytest.approx(expected, abs=1e-12)


def test_wrap_to_2pi_of_a_tiny_negative_angle_stays_below_two_pi():
    # -1e-300 + 2 pi rounds to 2 pi in floats: the range [0, 2 pi) must still hold
    wrapped = wrap_to_2pi(-1e-300)
    assert 0.0 <= wrapped < TWO_PI


@pytest.mark.parametrize('angle, expected', [
    (0.0, 0.0), (math.pi, -math.pi), (-math.pi, -math.pi), (3.0 * math.pi / 2.0, -math.pi / 2.0),
    (-3.0 * math.pi / 2.0, math.pi / 2.0), (TWO_PI, 0.0), (-TWO_PI, 0.0), (TWO_PI + 0.25, 0.25)])
def test_wrap_to_pi_lands_in_minus_pi_to_pi(angle, expected):
    wrapped = wrap_to_pi(angle)
    assert -math.pi <= wrapped < math.pi
    assert wrapped == pytest.approx(expected, abs=1e-12)


def test_wrap_to_pi_works_on_arrays():
    angles = np.array([-7.0, -math.pi, 0.0, 3.5, 10.0])
    wrapped = wrap_to_pi(angles)
    assert wrapped.shape == angles.shape
    assert np.all((wrapped >= -math.pi) & (wrapped < math.pi))
    # the same direction: sine and cosine unchanged
    assert np.allclose(np.sin(wrapped), np.sin(angles))
    assert np.allclose(np.cos(wrapped), np.cos(angles))


def test_relative_rms_closed_cases():
    reference = np.array([[3.0, 4.0], [0.0, 5.0]])      # |r|^2 = 25 per point
    assert relative_rms(reference, reference) == 0.0
    assert relative_rms(2.0 * reference, reference) == pytest.approx(1.0)
    assert relative_rms(-reference, reference) == pytest.approx(2.0)
    # error (1, 0) at one point, none at the other: sqrt((1 / 2) / 25)
    estimate = reference + np.array([[1.0, 0.0], [0.0, 0.0]])
    assert relative_rms(estimate, reference) == pytest.approx(math.sqrt(0.5 / 25.0))


def test_relative_rms_of_a_series_and_a_zero_reference():
    series = np.array([1.0, -1.0, 1.0, -1.0])
    assert relative_rms(series + 0.5, series) == pytest.approx(0.5)
    assert relative_rms([0.0, 0.0], [0.0, 0.0]) == 0.0
    assert relative_rms([0.0, 1e-3], [0.0, 0.0]) == math.inf
