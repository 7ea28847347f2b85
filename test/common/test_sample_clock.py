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


@pytest.mark.parametrize("rate", [1.0, 0.2, 0.1])          # hardware, time scale 5, time scale 10
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_samples_wall_time_is_found_to_a_few_milliseconds_while_answers_are_late_by_up_to_200_ms(rate, seed):
    clock = SampleClock()
    truth = _feed(clock, rate, 500, seed)
    assert clock.rate == pytest.approx(rate, rel=0.01)
    for device, wall in truth[-20:]:
        # never later than the truth by more than the quickest answer's delay plus a little; never before it
        error = clock.wall(device) - wall
        assert -0.002 <= error <= MIN_DELAY + 0.004, (device, error)


def test_the_arrival_time_alone_would_be_tens_of_milliseconds_off():
    clock = SampleClock()
    rng = random.Random(5)
    worst = 0.0
    for k in range(300):
        wall = 100.0 + 0.02 * k
        arrival = wall + MIN_DELAY + rng.uniform(0.0, 0.04)
        clock.add(3.0 + (wall - 100.0) * 10.0, arrival)
        worst = max(worst, arrival - wall)
    assert worst > 0.03                                           # what the poll's stamp would have said
    assert abs(clock.wall(3.0 + (wall - 100.0) * 10.0) - wall) < 0.005


def test_a_device_clock_that_starts_again_starts_the_mapping_afresh():
    clock = SampleClock()
    _feed(clock, 0.1, 300, 1)
    assert clock.wall(1.0) is not None
    clock.add(0.5, 500.0)                                         # the controller restarted: its clock went back
    assert clock.wall(0.5) == pytest.approx(500.0)
    assert clock.wall(0.6) == pytest.approx(500.0 + 0.1 * clock.rate)


def test_before_any_pair_there_is_no_mapping():
    assert SampleClock().wall(1.0) is None
