"""Warnings at most once per period (core/estimation/throttled_log.py), on a real logger."""

import logging
import time

from flexlink_ros.core.estimation import throttled_log
from flexlink_ros.core.estimation.throttled_log import ThrottledWarning

LOGGER_NAME = 'flexlink_ros.test.throttled'


def _messages(caplog):
    return [r.getMessage() for r in caplog.records if r.name == LOGGER_NAME]


def test_a_storm_of_warnings_logs_one_per_period(caplog, monkeypatch):
    # a period far longer than this test: every call after the first falls inside it
    monkeypatch.setattr(throttled_log, 'WARNING_PERIOD_S', 3600.0)
    warning = ThrottledWarning(logging.getLogger(LOGGER_NAME))
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        for k in range(200):
            warning.warn('bad sample %d of %s', k, 'crank')
    assert _messages(caplog) == ['bad sample 0 of crank']
    assert caplog.records[0].levelno == logging.WARNING


def test_the_next_warning_goes_out_once_the_period_has_passed(caplog):
    warning = ThrottledWarning(logging.getLogger(LOGGER_NAME))
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        warning.warn('first')
        # as if the last warning were logged two periods ago
        warning.last = time.monotonic() - 2.0 * throttled_log.WARNING_PERIOD_S
        warning.warn('second %s', 'later')
    assert _messages(caplog) == ['first', 'second later']


def test_each_kind_has_its_own_period(caplog, monkeypatch):
    monkeypatch.setattr(throttled_log, 'WARNING_PERIOD_S', 3600.0)
    logger = logging.getLogger(LOGGER_NAME)
    bound, warm = ThrottledWarning(logger), ThrottledWarning(logger)
    with caplog.at_level(logging.WARNING, logger=LOGGER_NAME):
        for _ in range(3):
            bound.warn('out of bound')
            warm.warn('warm start skipped')
    assert _messages(caplog) == ['out of bound', 'warm start skipped']
