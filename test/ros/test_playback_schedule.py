"""The playback schedule: message times and /clock ticks as `ros2 bag play` sends them."""

from flexlink_ros.ros.playback_schedule import (CLOCK, FALLBACK_PERIOD_NS, MAX_CLOCK_HZ, MESSAGE,
                                                pass_events, playback_times, ticks_in_pass)
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


def test_log_times_that_go_back_play_at_the_stamps_or_a_constant_period():
    stamps = 10**18 + np.arange(6, dtype=np.int64) * 10_000_000
    ordered = stamps + 200_000
    times, note = playback_times(ordered, stamps)
    np.testing.assert_array_equal(times, ordered)
    assert note == ''
    # Crafted: back by 1 ms per message, or a first log time of 2**63 - 1.
    for crafted in (ordered[0] - np.arange(6) * 1_000_000,
                    np.concatenate([[2**63 - 1], ordered[1:]])):
        times, note = playback_times(crafted, stamps)
        np.testing.assert_array_equal(times, stamps)
        assert 'go back' in note and 'header stamps' in note and '\n' not in note
        # The stamps go back too: a constant period, the median positive log spacing.
        times, note = playback_times(crafted, stamps[::-1])
        assert np.all(np.diff(times) == np.diff(times)[0]) and 'stored order' in note
    times, _ = playback_times(np.concatenate([[2**63 - 1], ordered[1:]]), stamps[::-1])
    assert np.diff(times)[0] == 10_000_000
    times, _ = playback_times(ordered[0] - np.arange(6) * 1_000_000, stamps[::-1])
    assert np.diff(times)[0] == FALLBACK_PERIOD_NS


def test_the_clock_frequency_is_bounded():
    assert list(pass_events([0, 1_000_000], clock_hz=MAX_CLOCK_HZ))
    with pytest.raises(ValueError, match='/clock frequency'):
        list(pass_events([0, 1_000_000], clock_hz=MAX_CLOCK_HZ * 1.01))
