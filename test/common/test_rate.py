"""The shared fixed-rate timer: ticks on the period, counts late ticks, no burst after a stall, stops."""
import threading
import time

import pytest

from locem_bridge.common.rate import FixedRate


def test_ticks_at_the_period_and_restarts_after_a_stall_instead_of_bursting():
    stop = threading.Event()
    rate = FixedRate(0.02, stop)
    start = time.monotonic()
    for _ in range(5):
        assert rate.sleep()
    assert 0.09 <= time.monotonic() - start < 0.5
    time.sleep(0.1)  # a stall of five periods
    assert rate.sleep() and rate.late >= 1
    after_stall = time.monotonic()
    assert rate.sleep()
    assert time.monotonic() - after_stall >= 0.015  # the next tick waits a period: no catch-up burst


def test_stop_ends_the_wait_at_once():
    stop = threading.Event()
    rate = FixedRate(10.0, stop)
    threading.Timer(0.05, stop.set).start()
    start = time.monotonic()
    assert rate.sleep() is False and not rate.running()
    assert time.monotonic() - start < 1.0


def test_period_must_be_positive():
    with pytest.raises(ValueError, match="positive"):
        FixedRate(0.0, threading.Event())
