"""The raster lane switch compensates its dead time: the tool's output changes where the lane's worked stretch
starts and ends, not one sample age plus one request later (a fake clock, arm and output: exact times)."""
import numpy as np
import pytest

from locem_bridge.bridges.commands_wall import SWITCH_LEADS, LaneSwitch, RasterSwitch

SPEED = 2.0          # m/s of wall time (0.2 m/s at time scale 10 ... or a fast arm)
AGE = 0.012          # s, how old the arm's state is when read
REQUEST = 0.02       # s, one output request (Modbus write) from call to answer
PERIOD = 0.01        # s, the motion loop's wait


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


class Rig:
    """A TCP moving along +x at SPEED from x = -0.2 m; the output records where the TCP truly was when it
    changed (half way through the request)."""

    def __init__(self):
        self.clock = Clock()
        self.t0 = self.clock.t
        self.changes = []

    def x(self, t):
        return -0.2 + SPEED * (t - self.t0)

    def cached_state(self):
        stamp = self.clock.t - AGE
        return {"tcp": [self.x(stamp), 0.0, 0.5, 0.0, 0.0, 0.0], "stamp": stamp}

    def switch(self, on):
        self.changes.append((on, self.x(self.clock.t + REQUEST / 2)))
        self.clock.t += REQUEST

    def sleep(self, seconds):
        self.clock.t += seconds

    def check(self):
        pass


def _run(make, until_x=1.2):
    rig = Rig()
    sw = make(rig)
    sw.switch_s = REQUEST                    # the running average a previous lane left
    while rig.x(rig.clock.t) < until_x:
        sw.sleep(PERIOD)
    return rig.changes


def test_the_output_changes_where_the_stretch_starts_and_ends():
    changes = _run(lambda r: LaneSwitch(r, r, r.switch, [0, 0, 0.5], [1, 0, 0.5], 0.2, 0.8, clock=r.clock))
    assert [on for on, _x in changes] == [True, False]
    # left: only the loop's own step (SPEED x PERIOD = 2 cm), either side
    assert changes[0][1] == pytest.approx(0.2, abs=SPEED * PERIOD)
    assert changes[1][1] == pytest.approx(0.8, abs=SPEED * PERIOD)


def _phases(lead, margin, n=20):
    """The switch positions' errors (m, + late along the travel) at n loop phases spread over one step."""
    on_err, off_err = [], []
    for k in range(n):
        def make(r, k=k):
            r.t0 -= k / n * PERIOD                         # the loop's phase against the crossing
            return LaneSwitch(r, r, r.switch, [0, 0, 0.5], [1, 0, 0.5], 0.2, 0.8, r.clock, lead, margin)
        changes = _run(make)
        assert [on for on, _x in changes] == [True, False], changes      # once on, once off: no chatter
        on_err.append(changes[0][1] - 0.2)
        off_err.append(changes[1][1] - 0.8)
    return on_err, off_err


def test_the_step_leads_choose_which_wait_switches():
    """Over loop phases spread across one step (SPEED x PERIOD = 2 cm): with no lead the output changes at the first
    wait past each end (half a step late on average, what sanding keeps); with half a step, at the nearest wait
    (unbiased, within half a step); the spray gun's (half a step ahead, the stretch half a step wider) switches on
    at the last wait before the start and off at the first wait past the end: the whole stretch worked at every
    phase, at most a step more, and each switched once."""
    step, tol = SPEED * PERIOD, 0.002
    on_err, off_err = _phases(0.0, 0.0)
    assert min(on_err + off_err) >= -tol and float(np.mean(on_err)) >= 0.35 * step, (on_err, off_err)
    on_err, off_err = _phases(0.5, 0.0)
    for errors in (on_err, off_err):
        assert max(abs(e) for e in errors) <= 0.5 * step + tol, errors
        assert abs(float(np.mean(errors))) <= 0.1 * step, errors
    on_err, off_err = _phases(*SWITCH_LEADS["spray_gun"])
    assert max(on_err) <= tol and min(on_err) >= -step - tol, on_err            # on before the start
    assert min(off_err) >= -tol and max(off_err) <= step + tol, off_err         # off after the end


def test_without_compensation_the_output_would_change_late():
    class Uncompensated(LaneSwitch):
        MAX_LEAD_S = 0.0
    changes = _run(lambda r: Uncompensated(r, r, r.switch, [0, 0, 0.5], [1, 0, 0.5], 0.2, 0.8, clock=r.clock))
    late = SPEED * (AGE + REQUEST / 2)       # 4.4 cm: the error the compensation removes
    assert changes[0][1] - 0.2 >= late - 1e-9 and changes[1][1] - 0.8 >= late - 1e-9


def test_raster_switch_predicts_the_same_way_over_several_stretches():
    stretches = [([0.0, 0, 0.5], [0.3, 0, 0.5]), ([0.6, 0, 0.5], [0.9, 0, 0.5])]
    changes = _run(lambda r: RasterSwitch(r, r, r.switch, stretches, reach=0.05, clock=r.clock))
    assert [on for on, _x in changes] == [True, False, True, False]
    assert np.allclose([x for _on, x in changes], [0.0, 0.3, 0.6, 0.9], atol=SPEED * PERIOD)


def test_raster_progress_reports_the_length_worked_never_ahead_of_the_tool_and_each_stretch_end():
    """Two stretches of 0.3 m that begin 1.0 m into a raster of 1.6 m (skip=1.0): the reports count from the
    raster's start, follow the TCP while the tool is on (at least every PERIOD_S of the clock, never beyond where
    the TCP truly is) and give each stretch's end when the tool switches off there."""
    from locem_bridge.bridges.commands_wall import RasterProgress
    from locem_bridge.common.raster_progress import parse_progress_text

    rig = Reporting.over(Rig)()
    stretches = [([0.0, 0, 0.5], [0.3, 0, 0.5]), ([0.6, 0, 0.5], [0.9, 0, 0.5])]
    switch = RasterSwitch(rig, rig, rig.switch, stretches, reach=0.05, clock=rig.clock)
    switch.switch_s = REQUEST
    hold = 0.05                    # s the spray would go on should LOCEM die: 10 cm at SPEED
    progress = RasterProgress(switch, rig, stretches, [1.0, 1.3], 1.6, reach=0.05, hold_s=hold, clock=rig.clock)
    progress.report(0.5, "waypoint 1 of 4")                         # the arm's own progress is not passed on
    while rig.x(rig.clock.t) < 1.2:
        progress.sleep(PERIOD)
    progress.finish()
    parsed = [parse_progress_text(text) for _t, _p, text in rig.reports]
    assert None not in parsed and all(total == 1.6 for _d, total, _s in parsed)
    metres = [done for done, _total, _s in parsed]
    assert metres == sorted(metres)
    assert [p for _t, p, _x in rig.reports] == pytest.approx([m / 1.6 for m in metres], abs=1e-3)

    def truth(x):
        return 1.0 + min(max(x, 0.0), 0.3) + min(max(x - 0.6, 0.0), 0.3)
    for (t, _p, text), (done, _total, if_stopped) in zip(rig.reports, parsed):
        assert done <= truth(rig.x(t)) + 1e-3, (text, rig.x(t))    # never ahead of the TCP
        # should LOCEM die now, the valve stays open `hold` more: never beyond where the TCP then is, nor beyond
        # the stretch (its end: LOCEM no longer there to switch off at the turn)
        assert done <= if_stopped <= truth(rig.x(t + hold)) + 1e-3, (text, rig.x(t))
        assert if_stopped <= (1.3 if done < 1.3 else 1.6) + 1e-9
    ahead = [s - d for d, _t, s in parsed if 1.05 < d < 1.2]
    assert ahead and min(ahead) >= SPEED * hold * 0.7, ahead        # and it does count the hold
    assert 1.3 in metres and metres[-1] == 1.6                      # each stretch's end
    assert rig.reports[-1][2] == "raster 1.600 of 1.600 m"          # the tool off: no "if LOCEM stops" part
    during = [t for t, _p, text in rig.reports if 1.0 < float(text.split()[1]) < 1.3]
    assert len(during) >= 2 and max(b - a for a, b in zip(during, during[1:])) <= RasterProgress.PERIOD_S + 2 * PERIOD


class Reporting:
    """A rig that is also the command's context: it keeps the progress reports (clock time, fraction, text)."""

    def __init__(self):
        super().__init__()
        self.reports = []

    def on_cancel(self, callback):
        pass

    def report(self, progress, text=""):
        self.reports.append((self.clock.t, progress, text))

    @staticmethod
    def over(rig):
        return type("Reporting" + rig.__name__, (Reporting, rig), {})


class PathRig(Rig):
    """A TCP moving at SPEED along a serpentine: lane 1 along +x at y = 0 from x = -0.2 to 1.2, 0.1 m across to
    y = 0.1, lane 2 back along -x to x = -0.2."""

    POINTS = np.array([[-0.2, 0.0, 0.5], [1.2, 0.0, 0.5], [1.2, 0.1, 0.5], [-0.2, 0.1, 0.5]])

    def at(self, t):
        d = SPEED * (t - self.t0)
        for a, b in zip(self.POINTS, self.POINTS[1:]):
            seg = float(np.linalg.norm(b - a))
            if d <= seg:
                return a + (b - a) * d / seg
            d -= seg
        return self.POINTS[-1]

    def x(self, t):                     # distance along the path
        return SPEED * (t - self.t0)

    def cached_state(self):
        stamp = self.clock.t - AGE
        return {"tcp": list(self.at(stamp)) + [0.0, 0.0, 0.0], "stamp": stamp}


# stretches in distance along the path: lane 1 x 0.0..0.3 and 0.6..0.9; lane 2 (from 1.5 + 0.1 on) x 0.9..0.3
PATH_STRETCHES = [([0.0, 0, 0.5], [0.3, 0, 0.5]), ([0.6, 0, 0.5], [0.9, 0, 0.5]), ([0.9, 0.1, 0.5], [0.3, 0.1, 0.5])]
PATH_ENDS = [(0.2, 0.5), (0.8, 1.1), (1.4 + 0.1 + 0.3, 1.4 + 0.1 + 0.9)]      # the same along the path


def _switch_along_path(rig):
    """A spray gun's RasterSwitch over PATH_STRETCHES along the rig's path to 2.8 m; each stretch switched once."""
    lead, margin = SWITCH_LEADS["spray_gun"]
    sw = RasterSwitch(rig, rig, rig.switch, PATH_STRETCHES, reach=0.05, clock=rig.clock, lead_steps=lead,
                      margin_steps=margin, path=PathRig.POINTS)
    sw.switch_s = REQUEST
    while rig.x(rig.clock.t) < 2.8:
        sw.sleep(PERIOD)
    assert [on for on, _d in rig.changes] == [True, False] * 3, rig.changes


def test_along_a_path_the_output_changes_at_each_stretchs_ends_whatever_the_loop_phase():
    """RasterSwitch given the path: the waits a switching point falls into are cut there, so over 20 loop phases
    the output goes on EARLY_S of travel before each stretch starts and off as much after it ends (within 2 mm,
    not one loop step: SPEED x PERIOD = 2 cm), the second lane (after the turn) as exactly as the first, each
    switched once."""
    early = SPEED * RasterSwitch.EARLY_S
    for k in range(20):
        rig = PathRig()
        rig.t0 -= k / 20 * PERIOD
        _switch_along_path(rig)
        for (start, end), (_on, d_on), (_off, d_off) in zip(PATH_ENDS, rig.changes[::2], rig.changes[1::2]):
            assert d_on == pytest.approx(start - early, abs=0.002), (k, rig.changes)
            assert d_off == pytest.approx(end + early, abs=0.002), (k, rig.changes)


class JumpingStampRig(PathRig):
    """A PathRig whose ``sample_time`` (the controller clock mapped onto the wall clock) is off by an offset that
    changes from poll to poll by up to 8 ms, as a mapping renewed from the quickest answers is on a busy machine;
    its ``sample_tick`` (the controller's clock) is exact."""

    def __init__(self, seed):
        super().__init__()
        self.rng = np.random.default_rng(seed)

    def cached_state(self):
        stamp = self.clock.t - AGE
        return {"tcp": list(self.at(stamp)) + [0.0, 0.0, 0.0], "sample_time": stamp - self.rng.uniform(0.0, 0.008),
                "sample_tick": stamp - 37.0, "stamp": self.clock.t}


@pytest.mark.parametrize("seed", range(5))
def test_along_a_path_speeds_go_by_the_controller_clock_not_by_a_jumping_wall_mapping(seed):
    """The TCP's speed between two samples comes from their ``sample_tick`` difference: with speeds from the
    ``sample_time`` differences, whose offset jumps by up to 8 ms between polls 10 ms apart, this rig's output went
    on up to 8 cm (a turn's worth at a time scale of 10) before a stretch. The stretch ends are then met within
    the sample time's own error: its age up to 8 ms too long, the output changes up to 8 ms of travel earlier
    than EARLY_S before each stretch and after it, each stretch switched once."""
    rig = JumpingStampRig(seed)
    _switch_along_path(rig)
    early, aged = SPEED * RasterSwitch.EARLY_S, SPEED * 0.008
    for (start, end), (_on, d_on), (_off, d_off) in zip(PATH_ENDS, rig.changes[::2], rig.changes[1::2]):
        assert start - early - aged - 0.002 <= d_on <= start - early + 0.002, (seed, rig.changes)
        assert end + early - aged - 0.002 <= d_off <= end + early + 0.002, (seed, rig.changes)


def test_on_a_path_the_point_reached_should_locem_die_goes_through_the_turn_into_the_next_lanes():
    """A raster that is one controller path (``gaps_m``): should LOCEM die, the arm goes on along the path and the
    valve stays open for ``hold`` s, so the point each report gives runs on through the turn into the next
    stretches -- where the TCP truly is ``hold`` s after the sample, never beyond it. Speeds from the controller's
    sample times, over several samples: the poll answers' arrival stamps jitter by up to 15 ms here (a busy
    machine) and the controller's stamps by one 8 ms cycle, which made the slowest speed between two samples a
    fraction of the true one and the point fall far behind the spray. Within 20 % of the true travel here."""
    from locem_bridge.bridges.commands_wall import RasterProgress
    from locem_bridge.common.raster_progress import parse_progress_text

    rng = np.random.default_rng(7)

    class Ctx(Reporting.over(PathRig)):
        def cached_state(self):
            taken = self.clock.t - AGE
            # the controller's stamp may be one 8 ms cycle older than the pose read after it; the poll's arrival
            # time up to 15 ms late
            return {"tcp": list(self.at(taken)) + [0.0, 0.0, 0.0], "sample_time": taken - 0.008 * int(rng.integers(2)),
                    "stamp": taken + float(rng.uniform(0.0, 0.015))}

    # along the path (distance d from its start): stretch A d 0.2..0.5, B 0.8..1.1 (lane 1), C 1.55..2.4 (lane 2,
    # starting 5 cm after the turn: the last speeds before it are partly across the lane)
    stretches = [([0.0, 0, 0.5], [0.3, 0, 0.5]), ([0.6, 0, 0.5], [0.9, 0, 0.5]),
                 ([1.15, 0.1, 0.5], [0.3, 0.1, 0.5])]
    gaps = [0.3, 0.3 + 0.1 + 0.05]

    def truth(d):                                   # raster metres worked when the TCP is d along the path
        return (min(max(d - 0.2, 0.0), 0.3) + min(max(d - 0.8, 0.0), 0.3) + min(max(d - 1.55, 0.0), 0.85))

    hold = 0.5                                      # s: 1.0 m of travel at SPEED
    rig = Ctx()
    switch = RasterSwitch(rig, rig, rig.switch, stretches, reach=0.05, clock=rig.clock, path=PathRig.POINTS)
    switch.switch_s = REQUEST
    progress = RasterProgress(switch, rig, stretches, [0.0, 0.3, 0.6], 1.45, reach=0.05, hold_s=hold,
                              clock=rig.clock, gaps_m=gaps)
    while rig.x(rig.clock.t) < 2.8:
        progress.sleep(PERIOD)
    progress.finish()
    checked = 0
    for t, _p, text in rig.reports:
        done, _total, if_stopped = parse_progress_text(text)
        if "if LOCEM stops now" not in text or done <= 0.0:
            continue                                # the tool off (a stretch's end): nothing sprays on
        sampled = rig.x(t - AGE)                    # the TCP sample the report was made from
        assert if_stopped <= truth(rig.x(t + hold)) + 1e-3, (text, sampled)        # never ahead of the spray
        assert if_stopped >= truth(sampled + 0.8 * SPEED * hold) - 1e-3, (text, sampled)  # not far behind it
        checked += 1
    assert checked >= 10
    parsed = [parse_progress_text(text) for _t, _p, text in rig.reports]
    beyond = [if_stopped for done, _total, if_stopped in parsed if 0.3 < done < 0.6]
    assert beyond and max(beyond) > 0.65, beyond    # from lane 1's second stretch into lane 2, past the turn


def test_a_raster_progress_needs_one_gap_between_each_two_stretches():
    from locem_bridge.bridges.commands_wall import RasterProgress
    rig = PathRig()
    switch = RasterSwitch(rig, rig, rig.switch, [([0.0, 0, 0.5], [0.3, 0, 0.5]), ([0.6, 0, 0.5], [0.9, 0, 0.5])],
                          reach=0.05, clock=rig.clock)
    for gaps in ([0.3, 0.2], []):
        with pytest.raises(ValueError, match="%d gaps for 2 stretches" % len(gaps)):
            RasterProgress(switch, rig, [([0.0, 0, 0.5], [0.3, 0, 0.5]), ([0.6, 0, 0.5], [0.9, 0, 0.5])],
                           [0.0, 0.3], 0.6, reach=0.05, gaps_m=gaps)


@pytest.mark.parametrize("speed", [0.3, 0.5, 1.0])
def test_a_path_gap_is_never_shorter_than_the_arm_takes_through_the_turn(speed):
    """The gaps ``_raster_path`` gives RasterProgress count each turn as the length the arm covers at lane speed in
    the time the UR stand-in's blended path (its time-optimal profile, v <= sqrt(a R) on each arc) takes from one
    stretch's end to the next one's start: never shorter (the point should LOCEM die would run ahead of the spray)
    and not much longer. The turn's bare path length is too short at every one of these speeds."""
    import math
    from locem_bridge.bridges.commands_wall import LANE_ACCEL, PATH_BLEND, RUNUP_MARGIN, path_gaps
    from locem_bridge.sim.ur.blended import BlendedCurve

    spacing, width = 0.146, 0.6
    blend = min(PATH_BLEND, 0.45 * spacing)
    runup = speed * speed / (2.0 * LANE_ACCEL) + RUNUP_MARGIN + blend
    points, ends = [], []
    for k in range(4):
        sign = 1.0 if k % 2 == 0 else -1.0
        w0, w1 = (0.0, width) if sign > 0 else (width, 0.0)
        z = k * spacing
        points += [np.array([w0 - sign * runup, 0.0, z]), np.array([w1 + sign * runup, 0.0, z])]
        ends.append((np.array([w0, 0.0, z]), np.array([w1, 0.0, z])))
    gaps = path_gaps(points, ends, speed, blend, spacing)
    m = len(points) - 1
    curve = BlendedCurve(np.array(points), [blend] * (m - 1), [speed] * m, [LANE_ACCEL] * m)
    cells = np.arange(len(curve.times)) * curve.ds

    def arc_length(k, point):                      # the curve's length at ``point`` on straight segment k
        a, b = curve.points[k - 1], curve.points[k]
        f = float(np.linalg.norm(point - a) / np.linalg.norm(b - a))
        for kind, s0, length, kk, data, _v, _a in curve.pieces:
            if kind == "line" and kk == k and data[0] - 1e-9 <= f <= data[1] + 1e-9:
                return s0 + (f - data[0]) / (data[1] - data[0]) * length
        raise AssertionError("no straight piece of segment %d at %.3f" % (k, f))

    for i, gap in enumerate(gaps):
        s_end, s_next = arc_length(2 * i + 1, ends[i][1]), arc_length(2 * i + 3, ends[i + 1][0])
        taken = float(np.interp(s_next, cells, curve.times) - np.interp(s_end, cells, curve.times))
        assert speed * taken <= gap + 1e-3, (i, speed * taken, gap)
        assert gap <= 1.5 * speed * taken, (i, speed * taken, gap)
        bare = 2.0 * runup + spacing
        if speed > math.sqrt(LANE_ACCEL * blend):
            assert speed * taken > bare, (speed * taken, bare)   # the old, unweighted length ran ahead

