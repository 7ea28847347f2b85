#!/usr/bin/env python3
"""Suspend / resume benchmark: per device, the time from a Suspend request to the device at rest and from a
Resume request to the device moving again, against the emergency path (STOP_ARM / STOP_BASE, the baseline,
measured in the same run), and the cost of the skill state machine per action.

Every bridge through one LOCEM core against the worksite stand-ins (UR controller, compressor, drives, PyBullet
world, time scale ``--time-scale``); times are sim seconds of ground truth (the stand-ins' own state, polled about
every millisecond of wall time). Devices:

- arm: a long MOVE_J suspended mid-way (stopJ), resumed;
- base: a GOTO suspended at speed (drives brake), resumed;
- spray: SPRAY_AREA suspended mid-lane: the valve closed and the arm at rest, resumed (the arm moving again).

Goal (issue 18): every device at rest within 0.3 s sim of Suspend; the state machine's overhead per action <= 1 ms.

Run with the project environment:  tools/run.sh python bench/bench_suspend.py [--repeats N] [--time-scale S]
Nothing is asserted; numbers are printed.
"""
import argparse
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(REPO, "test", "bridges"))

NORMAL = "0 -1 0"
AREA = "SPRAY_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 %s spacing=0.3 standoff=0.3 speed=0.1 pressure=3.5 run_in=0" % NORMAL
Q_A = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
Q_B = [1.2, -1.3, 1.3, -1.5708, -1.5708, 0.6]


def poll_until(predicate, clock, t0, timeout=5.0):
    """Sim seconds after ``t0`` at which ``predicate`` first held (None if not within ``timeout`` wall s)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return clock.now() - t0
    return None


def run(core, text):
    r = core.dispatcher.execute(text)
    if not r.success:
        raise SystemExit("%s failed: %s %s" % (text, r.code.value, r.message))
    return r


def bench_devices(repeats, time_scale):
    from bridge_rigs import ROBOT_YAML, WorksiteRig, wait_until
    from locem_bridge.bridges.config import load_robot_config
    from locem_bridge.bridges.robot import build_robot
    from locem_bridge.common.raster_progress import parse_progress_text
    from locem_bridge.locem.core import LocemCore
    from locem_bridge.locem.registry import Interface

    rig = WorksiteRig(load_robot_config(ROBOT_YAML), time_scale=time_scale)
    built = build_robot(rig.robot, site=rig.site_path, initial_pose=tuple(rig.world.base_pose()))
    built.start()
    core = LocemCore(grace=0.5, stop_timeout=2.0)
    rows = {}
    try:
        for command_set in built.command_sets:
            core.install(command_set)
        for kind in ("arm", "compressor", "base"):
            built.get(kind).wait_ready(20.0)
        arm_moving = lambda: rig.standin.get_state()["moving"]                         # noqa: E731
        wheels = lambda: max(abs(v) for v in rig.drives.wheel_speeds())                # noqa: E731

        def arm_case(method):
            run(core, "GOTO 2.4 1.2 1.5708")              # 2.4 m from the wall: the arm sweeps free
            run(core, "MOVE_J %s speed=1.0" % " ".join(map(str, Q_A)))
            ex = core.dispatcher.submit("MOVE_J %s speed=1.0" % " ".join(map(str, Q_B)), Interface.ACTION)
            wait_until(arm_moving, timeout=5.0)
            time.sleep(0.3)
            t0 = rig.clock.now()
            if method == "suspend":
                run(core, "SUSPEND id=%d" % ex.id)
            else:
                run(core, "STOP_ARM")
            rest = poll_until(lambda: not arm_moving(), rig.clock, t0)
            go = None
            if method == "suspend":
                time.sleep(0.2)
                t1 = rig.clock.now()
                run(core, "RESUME id=%d" % ex.id)
                go = poll_until(arm_moving, rig.clock, t1)
            ex.wait(60.0)
            return rest, go

        def base_case(method):
            run(core, "MOVE_HOME")                        # the arm tucked in before the base nears the wall
            run(core, "GOTO 2.4 2.5 1.5708")
            ex = core.dispatcher.submit("GOTO 2.4 1.2 1.5708 speed=0.8", Interface.ACTION)
            wait_until(lambda: wheels() > 3.0, timeout=10.0)
            t0 = rig.clock.now()
            run(core, "SUSPEND id=%d" % ex.id if method == "suspend" else "STOP_BASE")
            rest = poll_until(lambda: wheels() < 1e-9, rig.clock, t0)
            go = None
            if method == "suspend":
                time.sleep(0.2)
                t1 = rig.clock.now()
                run(core, "RESUME id=%d" % ex.id)
                go = poll_until(lambda: wheels() > 1e-3, rig.clock, t1)
            ex.wait(60.0)
            return rest, go

        def spray_case(_method):
            run(core, "MOVE_HOME")
            run(core, "GOTO 2.4 2.5 1.5708")
            feedback = []
            ex = core.dispatcher.submit(AREA, Interface.ACTION, listener=lambda e: feedback.append(e.message))
            wait_until(lambda: any((parse_progress_text(m) or (0,))[0] >= 1.15 for m in feedback), timeout=60.0)
            t0 = rig.clock.now()
            run(core, "SUSPEND id=%d" % ex.id)
            valve = poll_until(lambda: not rig.model.snapshot()["valve_open"], rig.clock, t0)
            rest = poll_until(lambda: not arm_moving(), rig.clock, t0)
            time.sleep(0.2)
            t1 = rig.clock.now()
            run(core, "RESUME id=%d" % ex.id)
            go = poll_until(arm_moving, rig.clock, t1)
            ex.wait(120.0)
            return max(valve or 0.0, rest or 0.0), go

        rig.world.mount_tool("spray_gun")
        run(core, "MOUNT_TOOL spray_gun")
        for name, case, baseline in (("arm (MOVE_J)", arm_case, "STOP_ARM"), ("base (GOTO)", base_case, "STOP_BASE"),
                                     ("spray (SPRAY_AREA: valve + arm)", spray_case, None)):
            sus = [case("suspend") for _ in range(repeats)]
            stops = [case("stop")[0] for _ in range(repeats)] if baseline else []
            rows[name] = (sus, stops, baseline)
            print("  measured %s" % name, flush=True)
        run(core, "COMPRESSOR_OFF")
    finally:
        core.close()
        built.close()
        rig.close()
    return rows


def bench_state_machine(n):
    """Microseconds per action of the skill state machine: Start, Suspend, Resume and completion with a listener
    (what HICEM and LOCEM add per action; without suspension only Start and completion)."""
    from locem_bridge.common.program_state import Method, ProgramStateMachine
    seen = []
    t0 = time.perf_counter()
    for i in range(n):
        m = ProgramStateMachine(str(i), "SPRAY_AREA", listener=seen.append)
        m.call(Method.START, "bench")
        m.call(Method.SUSPEND, "bench")
        m.call(Method.RESUME, "bench")
        m.complete()
        seen.clear()
    return (time.perf_counter() - t0) / n * 1e6


def fmt(values):
    v = [x for x in values if x is not None]
    if not v:
        return "n/a"
    return "median %.3f s  max %.3f s" % (statistics.median(v), max(v))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--time-scale", type=float, default=4.0)
    args = ap.parse_args()
    us = bench_state_machine(20000)
    print("skill state machine, Start + Suspend + Resume + completion: %.1f us per action (goal <= 1000 us: "
          "%.4f of it)" % (us, us / 1000.0))
    print("devices at time scale %g, %d repeats (sim seconds of ground truth):" % (args.time_scale, args.repeats))
    rows = bench_devices(args.repeats, args.time_scale)
    for name, (sus, stops, baseline) in rows.items():
        rest = [r for r, _g in sus]
        go = [g for _r, g in sus]
        print("  %-34s Suspend -> at rest: %s (goal <= 0.300 s)" % (name, fmt(rest)))
        if baseline:
            ratio = statistics.median([r for r in rest if r is not None]) / max(
                statistics.median([s for s in stops if s is not None]), 1e-6)
            print("  %-34s %s -> at rest: %s; Suspend / %s = %.2f" % ("", baseline, fmt(stops), baseline, ratio))
        print("  %-34s Resume -> moving:   %s" % ("", fmt(go)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
