"""The playback schedule: message times and /clock ticks as `ros2 bag play` sends them."""

from flexlink_ros.ros.playback_schedule import CLOCK, MESSAGE, pass_events, ticks_in_pass
import numpy as np
import pytest

START = 1_700_000_000_000_000_000
LOG_NS = START + np.arange(201, dtype=np.int64) * 10_000_000     # 100 Hz for 2 s


def test_messages_keep_their_spacing_scaled_by_the_rate():
    for rate in (1.0, 4.0):
        events = list(pass_events(LOG_NS, rate=rate))
        assert [kind for _, kind, _ in events] == [MESSAGE] * 201
        assert [value for _, _, value in events] == list(range(201))
        walls = np.array([wall for wall, _, _ in events])
        np.testing.assert_allclose(walls, (LOG_NS - START) * 1e-9 / rate, atol=1e-12)


def test_fixed_frequency_ticks_carry_the_recordings_time_and_a_quarter_as_many_at_rate_4():
    ticks = {}
    for rate in (1.0, 4.0):
        clocks = [(wall, value) for wall, kind, value in
                  pass_events(LOG_NS, rate=rate, clock_hz=40.0) if kind == CLOCK]
        ticks[rate] = len(clocks)
        assert len(clocks) == ticks_in_pass(LOG_NS[-1] - START, rate, 40.0)
        values = np.array([value for _, value in clocks])
        # tick k at wall k/40 s carries START + k * rate / 40 s: a 25 ms wall grid.
        np.testing.assert_array_equal(values, START + np.arange(len(clocks)) * int(rate * 25e6))
        assert values[0] == START and values[-1] <= LOG_NS[-1]
    assert ticks == {1.0: 81, 4.0: 21}


def test_every_clock_precedes_the_messages_it_does_not_pass_and_never_goes_back():
    log_ns = LOG_NS.copy()
    log_ns[50] = log_ns[10]       # a message logged out of order
    events = list(pass_events(log_ns, rate=2.0, clock_hz=40.0, clock_per_message=True))
    clock = START
    for _, kind, value in events:
        if kind == CLOCK:
            assert value >= clock
            clock = value
        else:
            assert clock == max(log_ns[:value + 1])      # the per-message tick just before
    assert sum(kind == CLOCK for _, kind, _ in events) == 201 + 41


def test_rate_must_be_positive_and_an_empty_recording_has_no_events():
    with pytest.raises(ValueError, match='positive'):
        list(pass_events(LOG_NS, rate=0.0))
    assert list(pass_events([], clock_hz=40.0)) == []
    assert ticks_in_pass(10**9, 1.0, 0.0) == 0
