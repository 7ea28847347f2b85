"""A fixed-rate loop timer on the monotonic clock, shared by the device loops (world, base control, polling).

``sleep()`` waits until the next tick. A late tick is counted in ``late``; after a stall longer than one period
the timer restarts from now instead of firing a burst of ticks to catch up (a device loop wants fresh cycles,
not old ones). It returns False once the stop event is set, so a loop reads::

    rate = FixedRate(1.0 / hz, stop_event)
    while rate.running():
        work()
        rate.sleep()
"""

import threading
import time


class FixedRate:
    def __init__(self, period: float, stop: threading.Event) -> None:
        if period <= 0.0:
            raise ValueError("period must be positive, got %r" % period)
        self.period = float(period)
        self.late = 0
        self._stop = stop
        self._next = time.monotonic()

    def running(self) -> bool:
        return not self._stop.is_set()

    def sleep(self) -> bool:
        """Wait for the next tick; False when the stop event was set meanwhile."""
        self._next += self.period
        delay = self._next - time.monotonic()
        if delay < 0.0:
            self.late += 1
            if delay < -self.period:
                self._next = time.monotonic()
                delay = 0.0
        return not self._stop.wait(max(0.0, delay))
