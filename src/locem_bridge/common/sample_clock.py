"""When a device's sample was taken, in local wall time, from the device's own clock.

A controller stamps each state package with its own clock (UR RTDE ``timestamp``: control cycles x period, in the
controller's seconds). The local time at which a poll's answer arrives says little about when the sample was
taken: it adds the transport and, on a busy machine, tens of milliseconds of scheduling, different at every poll.
A velocity from the arrival times of two samples is then off by the ratio of those delays (a TCP at 5 m/s measured
at 40 m/s), and a prediction from the newest sample by its age.

:class:`SampleClock` maps the device clock onto the local one from the pairs (device time, arrival time) it is
given: ``wall = rate x device + offset``, both from the answers that arrived soonest after their samples (the lower
envelope: the quickest answer's delay, the others' extra delays left out). ``rate`` (wall seconds per device
second, about 1: the clocks drift apart slowly) is the slope between the quickest answer of the first and of the
last ``edge_s`` of the last ``window_s`` of wall time; ``offset`` comes from the quickest answer of the last
``edge_s``. A device clock that goes backwards (a controller restarted, a new connection), or answers more than
``MAX_GAP_S`` apart (a link that was down: the device clock may have stood still meanwhile), start the mapping
afresh.
"""
from collections import deque
from typing import Deque, Optional, Tuple

#: s of device time the pairs must span before the rate is taken from them (before: 1.0, or the last rate known)
MIN_SPAN_S = 0.2
#: s of wall time between two answers after which the mapping starts afresh
MAX_GAP_S = 1.0


class SampleClock:
    """Device time -> local wall time, from (device time, arrival time) pairs (see the module docstring)."""

    def __init__(self, window_s: float = 4.0, edge_s: float = 1.0) -> None:
        self.window_s, self.edge_s = float(window_s), float(edge_s)
        self._pairs: Deque[Tuple[float, float]] = deque()
        self.rate = 1.0
        self._offset: Optional[float] = None

    def add(self, device_t: float, wall_t: float) -> None:
        """One sample's device time and the local wall time its answer arrived at."""
        device_t, wall_t = float(device_t), float(wall_t)
        if self._pairs and (device_t < self._pairs[-1][0] or wall_t - self._pairs[-1][1] > MAX_GAP_S):
            self._pairs.clear()                          # the device clock started again, or the link was down
            self._offset = None
        if self._pairs and device_t == self._pairs[-1][0]:
            return                                       # the same sample once more: no new information
        self._pairs.append((device_t, wall_t))
        while len(self._pairs) > 2 and wall_t - self._pairs[1][1] >= self.window_s:
            self._pairs.popleft()
        recent = [p for p in self._pairs if p[1] >= wall_t - self.edge_s]
        if self._pairs[-1][0] - self._pairs[0][0] >= MIN_SPAN_S:
            early = [p for p in self._pairs if p[1] <= self._pairs[0][1] + self.edge_s]
            a = min(early, key=lambda p: p[1] - self.rate * p[0])
            b = min(recent, key=lambda p: p[1] - self.rate * p[0])
            if b[0] - a[0] >= MIN_SPAN_S:
                self.rate = (b[1] - a[1]) / (b[0] - a[0])
        self._offset = min(w - self.rate * d for d, w in recent)

    def wall(self, device_t: float) -> Optional[float]:
        """The local wall time the sample stamped ``device_t`` was taken at (None before any pair)."""
        if self._offset is None:
            return None
        return self.rate * float(device_t) + self._offset
