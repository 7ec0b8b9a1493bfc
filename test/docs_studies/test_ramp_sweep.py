"""
The ramp sweep (docs/studies/ramp_sweep.py) at a reduced size in CI time.

The profile's crank angle is the integral of its speed; a ramp that does not change the speed
drives the Exudyn peer exactly as the constant-speed peer; the streaming estimate steps
through a jittered ramp without a refusal; the branch measures find a hysteresis loop where
there is one and none where ramp-up and ramp-down agree; the ramp's size is bounded.
"""

import math

from flexlink_ros.core.reduction.nonlinear_tables import build_nonlinear_tables
from flexlink_ros.studies.peer_exudyn import peer_response
from flexlink_ros.studies.peer_linear import linear_model
from flexlink_ros.studies.peer_model import exudyn_available, OUTPUT_KEYS, resolve_mechanism
import numpy as np
import pytest
import ramp_sweep

needs_exudyn = pytest.mark.skipif(not exudyn_available(), reason='exudyn is not installed')

PROFILE = ramp_sweep.RampProfile(low_rpm=380.0, high_rpm=420.0, ramp_s=1.0,
                                 settle_revolutions=3.0, hold_revolutions=2.0)


def test_the_crank_angle_is_the_integral_of_the_speed():
    t = np.linspace(0.0, PROFILE.duration_s, 200_001)
    angle = PROFILE.angle(t)
    rate = np.gradient(angle, t)
    assert np.max(np.abs(rate - PROFILE.speed(t))) < 1e-6 * PROFILE.speed(t).max()
    scalar = PROFILE.angle_function()
    picks = t[::997]
    assert [scalar(x) for x in picks] == pytest.approx(PROFILE.angle(picks), abs=1e-12)
    times, speeds = PROFILE.knots()
    assert speeds[0] == pytest.approx(380.0 * math.pi / 30.0)
    assert speeds[2] == pytest.approx(420.0 * math.pi / 30.0)
    assert times[2] - times[1] == pytest.approx(1.0)


@needs_exudyn
def test_a_ramp_at_one_speed_drives_the_peer_as_the_constant_speed_peer():
    flat = ramp_sweep.RampProfile(low_rpm=400.0, high_rpm=400.0, ramp_s=0.15,
                                  settle_revolutions=1.0, hold_revolutions=0.5)
    ramp = ramp_sweep.peer_ramp('cho1992', flat, elements_per_link=2, steps_per_revolution=120,
                                stride=1)
    steady = peer_response('cho1992', 400.0, elements_per_link=2, bearings='springs',
                           mass_placement='split', revolutions=4, steps_per_revolution=120)
    count = min(len(ramp['time']), len(steady['time']))
    assert count > 400
    assert ramp['time'][:count] == pytest.approx(steady['time'][:count], abs=1e-12)
    for key in OUTPUT_KEYS:
        scale = np.max(np.abs(steady[key][:count]))
        assert scale > 1e-5
        assert np.max(np.abs(ramp[key][:count] - steady[key][:count])) < 1e-9 * scale + 1e-14


@needs_exudyn
def test_the_peer_follows_the_ramp_speed():
    run = ramp_sweep.peer_ramp('cho1992', PROFILE, elements_per_link=2,
                               steps_per_revolution=120, stride=2)
    rows = ramp_sweep.per_revolution(run)
    up, down = ramp_sweep.ramp_halves(rows, PROFILE)
    assert np.all(np.diff(up['rpm']) > 0) and np.all(np.diff(down['rpm']) < 0)
    assert up['rpm'][0] > 380.0 and up['rpm'][-1] < 420.0
    assert np.all(np.isfinite(rows['lever_tip'])) and np.all(rows['lever_tip'] > 0)


def test_the_streaming_estimate_steps_through_a_jittered_ramp():
    model = linear_model(resolve_mechanism('cho1992'), elements_per_link=2, bearings='springs',
                         gravity=True)
    tables = build_nonlinear_tables(model, 1e-4)
    run = ramp_sweep.stream_ramp(tables, PROFILE, rate_hz=1000.0, jitter=0.3, seed=3)
    steps = np.diff(run['time'])
    assert steps.min() >= 0.7e-3 - 1e-9 and steps.max() <= 1.3e-3 + 1e-9
    assert steps.std() > 0.1e-3
    assert run['refused'] == 0
    assert run['speed'] == pytest.approx(PROFILE.speed(run['time']))
    rows = ramp_sweep.per_revolution(run)
    assert np.all(rows['lever_tip'] > 0) and np.all(np.isfinite(rows['validity']))


def _rows(up_amplitude, down_amplitude):
    """Per-revolution rows of a ramp whose p2p over speed is given per half."""
    times, _ = PROFILE.knots()
    t_up = np.linspace(times[1], times[2], 41)[1:-1]
    t_down = np.linspace(times[3], times[4], 41)[1:-1]
    t = np.concatenate([t_up, t_down])
    rpm = PROFILE.speed(t) * 30.0 / math.pi
    half = len(t_up)
    amplitude = np.concatenate([up_amplitude(rpm[:half]), down_amplitude(rpm[half:])])
    return {'time': t, 'rpm': rpm, 'lever_tip': amplitude, 'coupler_mid': amplitude,
            'validity': np.zeros_like(t)}


def test_a_hysteresis_loop_shows_as_a_gap_and_a_jump():
    up = lambda rpm: np.where(rpm < 410.0, 2e-3, 1e-3)       # noqa: E731 jumps down at 410
    down = lambda rpm: np.where(rpm < 395.0, 2e-3, 1e-3)     # noqa: E731 jumps up at 395
    gap = ramp_sweep.branch_gap(_rows(up, down), PROFILE)
    assert gap['largest_gap'] == pytest.approx(0.5)
    assert 395.0 <= gap['at_rpm'] <= 410.0
    assert gap['largest_jump'] == pytest.approx(1.0)


def test_one_branch_shows_no_gap():
    smooth = lambda rpm: 1e-3 + 1e-5 * (rpm - 380.0)         # noqa: E731
    gap = ramp_sweep.branch_gap(_rows(smooth, smooth), PROFILE)
    assert gap['largest_gap'] < 1e-3
    assert gap['largest_jump'] < 0.02


def test_per_revolution_measures_the_deflection_vector_p2p():
    t = np.linspace(0.0, 1.0, 10_001)
    speed = np.full_like(t, 4.0 * math.pi)                     # two revolutions a second
    angle = speed * t
    run = {'time': t, 'crank_angle': angle, 'speed': speed,
           'lever_tip_dx': 3e-3 * np.sin(angle), 'lever_tip_dy': 4e-3 * np.sin(angle),
           'coupler_mid_dx': np.zeros_like(t), 'coupler_mid_dy': 1e-3 * np.cos(2 * angle)}
    rows = ramp_sweep.per_revolution(run)
    assert rows['rpm'] == pytest.approx([120.0])
    assert rows['lever_tip'] == pytest.approx([1e-2], rel=1e-3)
    assert rows['coupler_mid'] == pytest.approx([2e-3], rel=1e-3)
    assert np.isnan(rows['validity']).all()


def test_a_ramp_too_long_for_the_bound_is_refused():
    long = ramp_sweep.RampProfile(ramp_s=3000.0)
    with pytest.raises(ValueError, match='samples'):
        ramp_sweep.ramp_signal(long, rate_hz=1000.0)
