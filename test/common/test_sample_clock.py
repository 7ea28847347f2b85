"""The device clock mapped onto the wall clock: a sample's wall time from its device stamp, whatever the delays of
the answers that brought it (seeded random delays of a busy machine: 1-40 ms, a few much longer)."""
import random

import pytest

from locem_bridge.common.sample_clock import SampleClock

MIN_DELAY = 0.001


def _feed(clock, rate, polls, seed, t0=100.0, device0=3.0, period=0.02):
    """Polls every ``period`` s of wall time of a device whose clock runs 1 / rate as fast; each answer arrives
    MIN_DELAY plus a random delay after its sample. Returns [(device time, true wall time)]."""
    rng = random.Random(seed)
    truth = []
    for k in range(polls):
        wall = t0 + k * period
        device = device0 + (wall - t0) / rate
        delay = MIN_DELAY + (rng.uniform(0.0, 0.04) if rng.random() > 0.05 else rng.uniform(0.05, 0.2))
        clock.add(device, wall + delay)
        truth.append((device, wall))
    return truth


@pytest.mark.parametrize("rate", [1.0, 0.2, 0.1])          # a device clock at the wall's pace, 5 and 10 times as fast
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_samples_wall_time_is_found_to_a_few_milliseconds_while_answers_are_late_by_up_to_200_ms(rate, seed):
    clock = SampleClock()
    truth = _feed(clock, rate, 500, seed)
    assert clock.rate == pytest.approx(rate, rel=0.01)
    for device, wall in truth[-20:]:
        # never later than the truth by more than the quickest answer's delay plus a little; never before it
        error = clock.wall(device) - wall
        assert -0.002 <= error <= MIN_DELAY + 0.004, (device, error)


def test_a_device_clock_that_starts_again_or_a_link_that_was_down_starts_the_mapping_afresh():
    clock = SampleClock()
    _feed(clock, 0.1, 300, 1)
    assert clock.rate == pytest.approx(0.1, rel=0.01)
    clock.add(0.5, 500.0)                                         # the controller restarted: its clock went back
    assert clock.wall(0.5) == pytest.approx(500.0)
    truth = _feed(clock, 1.0, 100, 2, t0=500.02, device0=0.52)
    assert clock.rate == pytest.approx(1.0, rel=0.01)             # the old pairs' rate is gone
    device, wall = truth[-1]
    assert abs(clock.wall(device) - wall) < 0.005
    # the link down for 3 s while the device clock stood still: not a rate of 3 wall seconds per device second
    clock.add(device + 0.02, wall + 3.0)
    _feed(clock, 1.0, 100, 3, t0=wall + 3.02, device0=device + 0.04)
    assert clock.rate == pytest.approx(1.0, rel=0.01)


def test_before_any_pair_there_is_no_mapping():
    assert SampleClock().wall(1.0) is None
