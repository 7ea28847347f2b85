#!/usr/bin/env python3
"""Skill-state benchmark of HICEM's running action (issue 18): prints numbers and ratios (no asserts).

1. The state machine's cost per action, in isolation: what the controller does for it when an action starts and
   ends (a ProgramStateMachine, Start, completion, the skill fields published to a state listener and a transition
   listener), next to one state publication (``_set_state``, which HICEM does several times per action anyway)
   measured in the same run (ratio).
2. Per tick: a tick of a 50-node tree (bench_hicem's) inside the skill lock reading the pausable clock, next to the
   same tree ticked bare on ``time.monotonic`` (ratio).
3. Whole taping processes against instant in-process doubles (memory-only HDICT): HICEM's overhead per action
   (bench_hicem's figure: wall time minus PEMKRE/LOCEM calls and idle waits) with the skill state, and with the
   state machine replaced by a do-nothing one (the baseline), runs interleaved. Goal: the difference <= 1 ms.
4. Suspend / Resume: time of ``suspend_action`` and ``resume_action`` on an action with one running LOCEM
   command (in-process double), with the HDICT on SQLite (synchronous FULL: one disk sync per call) and in memory.
   The devices' own time to rest and to move again is LOCEM's and the bridges' (their benchmarks).

Run: tools/run.sh python bench/bench_skill_state.py   (add --quick for fewer repetitions)
"""
import os
import statistics
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path[:0] = [os.path.join(ROOT, "src"), os.path.join(ROOT, "test", "hicem"), HERE]

from bench_hicem import hicem_50_node_xml  # noqa: E402
from hicem_doubles import AutoOperator, LocemDouble, PemkreDouble  # noqa: E402  (test doubles)
from hicem_rig import params  # noqa: E402
from locem_bridge.common.next_action import ACTION, NextAction  # noqa: E402
from locem_bridge.common.program_state import Method, ProgramState  # noqa: E402
from locem_bridge.common.task_status import SUCCEEDED  # noqa: E402
from locem_bridge.hicem.blackboard import Blackboard  # noqa: E402
from locem_bridge.hicem.controller import HighLevelController, _ActionSkill  # noqa: E402
from locem_bridge.hicem.executive import create_executive  # noqa: E402
from locem_bridge.hicem.health import HealthMonitor, ModuleSpec  # noqa: E402
from locem_bridge.hicem.node_base import NodeContext  # noqa: E402
from locem_bridge.hicem.skill_control import PausableClock  # noqa: E402
from locem_bridge.hicem.xml_loader import TreeLibrary  # noqa: E402

QUICK = "--quick" in sys.argv


def pct(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(q * len(xs)))]


def fmt_us(xs):
    return "median %.1f us  p99 %.1f us" % (statistics.median(xs) * 1e6, pct(xs, 0.99) * 1e6)


def executive(hdict_path=None, locem=None, pemkre=None, controller_class=None):
    ex = create_executive(pemkre or PemkreDouble(), locem or LocemDouble(), hdict_path,
                          params=params(health__modules=[{"name": "locem", "crucial": True}]), start_watchdog=False)
    if controller_class is not None:          # the same parts, another controller class (the baseline of 3.)
        old = ex.controller
        ex.controller = controller_class(old.pemkre, old.locem, old.library, old.store, old.params,
                                         health=ex.health, operator=ex.operator, data_handler=ex.data_handler)
    ex.operator.add_listener(AutoOperator(ex.controller, {"mount_tool": "done", "validate_line": "valid",
                                                          "manual_taping": "done"}))
    return ex


# ------------------------------------------------------------------------------------- 1. per action --
def bench_lifecycle(n):
    ex = executive()
    ctrl = ex.controller
    seen = []
    ctrl.add_state_listener(lambda st: seen.append(st["skill_state"]))
    ctrl.add_transition_listener(seen.append)
    na = NextAction(ACTION, task="http://example.org/run#t", action_type="TAPE_LINE", parameters="")
    life, base = [], []
    for i in range(n + 100):
        t = time.perf_counter()
        act = _ActionSkill(ctrl._new_machine(na), na)
        with ctrl._skill_lock:
            ctrl._action = act
            ctrl._last_machine = act.machine
            act.machine.call(Method.START, "HICEM runs the tree TAPE_LINE")
        with ctrl._skill_lock:
            ctrl._end_action(act, SUCCEEDED, "taped")
        dt = time.perf_counter() - t
        t = time.perf_counter()
        ctrl._set_state(node="n%d" % i)
        db = time.perf_counter() - t
        if i >= 100:
            life.append(dt)
            base.append(db)
    assert act.machine.state == ProgramState.READY
    ex.close()
    print("1. skill state per action: machine + Start + completion + published (%d actions)" % n)
    print("   state machine per action:               %s" % fmt_us(life))
    print("   one state publication (baseline):       %s" % fmt_us(base))
    print("   ratio (median): %.2f state publications   goal: <= 1 ms per action -> %s" % (
        statistics.median(life) / statistics.median(base), "met" if pct(life, 0.99) <= 1e-3 else "NOT met"))
    return statistics.median(life)


# --------------------------------------------------------------------------------------- 2. per tick --
def bench_tick(n):
    lib = TreeLibrary()
    lib.load_string(hicem_50_node_xml(), "bench.xml")
    trees = []
    for clock in (PausableClock(time.monotonic), time.monotonic):
        locem = LocemDouble(durations={"WAIT": 1e9})
        ctx = NodeContext(locem=locem, health=HealthMonitor([ModuleSpec("locem", crucial=True)]), clock=clock)
        bb = Blackboard()
        bb.update({"k": "v", "t": 1e9})
        trees.append(lib.build("B", ctx, bb))
    lock = threading.RLock()
    skill, bare = trees
    for _ in range(50):
        skill.tick()
        bare.tick()
    a, b = [], []
    for _ in range(n):
        t = time.perf_counter()
        with lock:
            skill.tick()
        a.append(time.perf_counter() - t)
        t = time.perf_counter()
        bare.tick()
        b.append(time.perf_counter() - t)
    print("2. tick of a 50-node tree (%d ticks)" % n)
    print("   in the skill lock, pausable clock:      %s" % fmt_us(a))
    print("   bare, time.monotonic (baseline):        %s" % fmt_us(b))
    print("   ratio (median): %.3f   per tick: %+.1f us" % (statistics.median(a) / statistics.median(b),
                                                           (statistics.median(a) - statistics.median(b)) * 1e6))


# -------------------------------------------------------------------------------- 3. whole processes --
class _NullMachine:
    """The baseline: a state machine that does nothing (no transitions, no listeners, no publication)."""

    def __init__(self, instance, skill):
        self.instance, self.skill, self.state = instance, skill, ProgramState.RUNNING

    def call(self, method, cause=""):
        return None

    def complete(self, cause=""):
        return None

    def fail(self, cause=""):
        return None

    def check(self, method):
        return None

    def describe(self):
        return self.skill

    def allowed(self):
        return []


class _NoSkillController(HighLevelController):
    def _new_machine(self, na, state=ProgramState.READY):
        return _NullMachine(na.task, na.skill or na.action_type)

    def _publish_skill(self):
        return None


def run_process(controller_class=None):
    ex = executive(controller_class=controller_class)
    phase = ex.controller.run_process(PemkreDouble.PROCESS)
    stats = list(ex.controller.stats)
    ex.close()
    assert phase == "ended", phase
    return [s.overhead_s for s in stats]


def bench_process(reps):
    with_skill, without = [], []
    for i in range(reps):
        for cls in ((None, _NoSkillController) if i % 2 == 0 else (_NoSkillController, None)):
            (with_skill if cls is None else without).extend(run_process(cls))
    a, b = statistics.median(with_skill), statistics.median(without)
    print("3. HICEM overhead per action, whole taping processes (%d runs each, interleaved; memory-only HDICT)"
          % reps)
    print("   with the skill state:                   median %.3f ms  p95 %.3f ms" % (a * 1e3,
                                                                                     pct(with_skill, 0.95) * 1e3))
    print("   without (do-nothing machine, baseline): median %.3f ms  p95 %.3f ms" % (b * 1e3,
                                                                                     pct(without, 0.95) * 1e3))
    print("   ratio (median): %.2f   difference %+.3f ms per action   goal: <= 1 ms -> %s" % (
        a / b, (a - b) * 1e3, "met" if a - b <= 1e-3 else "NOT met"))


# -------------------------------------------------------------------------------- 4. suspend / resume --
def bench_suspend(n):
    print("4. suspend_action / resume_action with one running LOCEM command (in-process double; %d each)" % n)
    for label in ("HDICT synchronous=FULL", "memory only (no HDICT)"):
        with tempfile.TemporaryDirectory() as d:
            locem = LocemDouble(durations={"APPLY_TAPE": 1e9})
            pem = PemkreDouble(validate_lines=False)
            ex = executive(os.path.join(d, "hdict.sqlite") if label.startswith("HDICT") else None, locem, pem)
            ctrl = ex.controller
            ctrl.start_process(PemkreDouble.PROCESS)
            deadline = time.monotonic() + 30
            while not (ctrl.state()["node"] == "locem_command" and ctrl.state()["tree"] == "TAPE_LINE"):
                assert time.monotonic() < deadline, ctrl.state()
                time.sleep(0.005)
            sus, res = [], []
            for _ in range(n):
                t = time.perf_counter()
                assert ctrl.suspend_action("bench") == ProgramState.SUSPENDED
                sus.append(time.perf_counter() - t)
                t = time.perf_counter()
                assert ctrl.resume_action("bench") == ProgramState.RUNNING
                res.append(time.perf_counter() - t)
            ctrl.stop("bench over")
            ctrl.join(10)
            ex.close()
        print("   %-24s suspend: median %.3f ms  p95 %.3f ms   resume: median %.3f ms  p95 %.3f ms" % (
            label, statistics.median(sus) * 1e3, pct(sus, 0.95) * 1e3, statistics.median(res) * 1e3,
            pct(res, 0.95) * 1e3))


def main():
    print("HICEM skill-state benchmark (python %s; load average %.2f on %d CPUs - numbers vary with load)" % (
        sys.version.split()[0], os.getloadavg()[0], os.cpu_count() or 0))
    bench_lifecycle(500 if QUICK else 5000)
    bench_tick(1000 if QUICK else 5000)
    bench_process(4 if QUICK else 20)
    bench_suspend(20 if QUICK else 100)
    return 0


if __name__ == "__main__":
    sys.exit(main())
