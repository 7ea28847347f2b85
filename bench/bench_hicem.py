#!/usr/bin/env python3
"""HICEM benchmark: prints (no asserts)

1. tick cost of a 50-node tree (every node ticked on every tick, a LOCEM command RUNNING at the end) with the
   HICEM engine (BT.CPP-semantics controls on py_trees), next to plain py_trees composites of the same shape
   measured in the same run (ratio). Goal: median <= 0.5 ms.
2. XML load time of every tree in trees/ (parse + validate + link), and build time per action tree.
3. HICEM overhead per high-level action: a whole taping process (3 joints, validation on) against instant
   in-process PEMKRE/LOCEM test doubles; overhead = action wall time - time inside PEMKRE calls - time inside
   LOCEM calls - idle waits between ticks. With the HDICT on a real SQLite file (synchronous FULL: a disk
   sync per commit, the default; NORMAL: no sync per commit) and with memory only. Goal: <= 20 ms per action.

Run: tools/run.sh python bench/bench_hicem.py   (add --quick for fewer repetitions)
"""
import os
import statistics
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path[:0] = [os.path.join(ROOT, "src"), os.path.join(ROOT, "test", "hicem")]

import py_trees  # noqa: E402
from py_trees.common import Status  # noqa: E402

from hicem_doubles import AutoOperator, LocemDouble, PemkreDouble  # noqa: E402  (test doubles)
from hicem_rig import params  # noqa: E402
from locem_bridge.hicem.blackboard import Blackboard  # noqa: E402
from locem_bridge.hicem.executive import create_executive  # noqa: E402
from locem_bridge.hicem.health import HealthMonitor, ModuleSpec  # noqa: E402
from locem_bridge.hicem.node_base import NodeContext  # noqa: E402
from locem_bridge.hicem.xml_loader import TreeLibrary  # noqa: E402

TREES = os.path.join(ROOT, "trees")
QUICK = "--quick" in sys.argv


def pct(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(q * len(xs)))]


def fmt_ms(xs):
    return "median %.3f ms  p99 %.3f ms" % (statistics.median(xs) * 1e3, pct(xs, 0.99) * 1e3)


# ----------------------------------------------------------------------------------------------- 1. ticks --
GROUPS = 7  # root + guard + 7 groups x 6 nodes + a 3-node group + a 2-node tail + running command = 50


def hicem_50_node_xml():
    groups = "".join(
        '<Sequence name="g%d"><CheckEqual a="{k}" b="v"/><CheckHealth/><SetBlackboard output_key="{o%d}" '
        'value="{k}"/><Inverter><AlwaysFailure/></Inverter></Sequence>' % (i, i) for i in range(GROUPS))
    return ('<root BTCPP_format="4"><BehaviorTree ID="B"><ReactiveSequence name="root"><CheckHealth/>%s'
            '<Sequence name="g_extra"><CheckEqual a="{k}" b="v"/><AlwaysSuccess/></Sequence>'
            '<ForceSuccess><AlwaysSuccess/></ForceSuccess>'
            '<SendLocemCommand command="WAIT {t}" timeout="{@t}"/></ReactiveSequence></BehaviorTree></root>'
            % groups)


def pytrees_50_node_tree():
    B = py_trees.behaviours
    kids = [B.Success("guard")]
    for i in range(GROUPS):
        kids.append(py_trees.composites.Sequence("g%d" % i, memory=False, children=[
            B.Success("a"), B.Success("b"), B.Success("c"),
            py_trees.decorators.Inverter("inv", B.Failure("f"))]))
    kids.append(py_trees.composites.Sequence("g_extra", memory=False, children=[B.Success("a"), B.Success("b")]))
    kids.append(py_trees.decorators.FailureIsSuccess("fs", B.Success("s")))
    kids.append(B.Running("cmd"))
    return py_trees.trees.BehaviourTree(py_trees.composites.Sequence("root", memory=False, children=kids))


def bench_ticks(n):
    lib = TreeLibrary()
    lib.load_string(hicem_50_node_xml(), "bench.xml")
    assert lib.count_nodes("B") == 50, lib.count_nodes("B")
    locem = LocemDouble(durations={"WAIT": 1e9})
    ctx = NodeContext(locem=locem, health=HealthMonitor([ModuleSpec("locem", crucial=True)]))
    bb = Blackboard()
    bb.update({"k": "v", "t": 1e9})
    tree = lib.build("B", ctx, bb)
    base = pytrees_50_node_tree()
    assert sum(1 for _ in base.root.iterate()) == 50
    for _ in range(50):  # warm up
        tree.tick()
        base.tick()
    h, p = [], []
    for _ in range(n):
        t = time.perf_counter()
        st = tree.tick()
        h.append(time.perf_counter() - t)
        t = time.perf_counter()
        base.tick()
        p.append(time.perf_counter() - t)
    assert st == Status.RUNNING and len(locem.sent) == 1  # the command kept running, never re-sent
    print("1. tick of a 50-node tree (%d ticks, all 50 nodes ticked each time)" % n)
    print("   HICEM engine (BT.CPP semantics, ports, blackboard):  %s" % fmt_ms(h))
    print("   plain py_trees composites, same shape (baseline):    %s" % fmt_ms(p))
    print("   ratio HICEM / py_trees (median): %.2f   goal: median <= 0.5 ms -> %s" % (
        statistics.median(h) / statistics.median(p), "met" if statistics.median(h) <= 0.5e-3 else "NOT met"))


# ------------------------------------------------------------------------------------------------ 2. load --
def bench_load(n):
    times = []
    for _ in range(n):
        t = time.perf_counter()
        lib = TreeLibrary()
        lib.load_directory(TREES)
        times.append(time.perf_counter() - t)
    files = [f for f in os.listdir(TREES) if f.endswith(".xml") and f != "node_catalogue.xml"]
    nodes = sum(lib.count_nodes(i) for i in lib.tree_ids())
    print("2. XML load of all trees (%d files, %d trees, %d node instances incl. subtrees), %d runs:" % (
        len(files), len(lib.tree_ids()), nodes, n))
    print("   %s" % fmt_ms(times))
    bb = Blackboard()
    builds = {}
    for tid in lib.tree_ids():
        xs = []
        for _ in range(max(5, n)):
            t = time.perf_counter()
            lib.build(tid, NodeContext(), bb)
            xs.append(time.perf_counter() - t)
        builds[tid] = statistics.median(xs)
    print("   build (instantiate) per tree, median: " + ", ".join(
        "%s %.3f ms" % (k, v * 1e3) for k, v in sorted(builds.items())))


# -------------------------------------------------------------------------------------------- 3. overhead --
def run_process(hdict_path, synchronous="FULL"):
    pem = PemkreDouble()
    loc = LocemDouble()
    ex = create_executive(pem, loc, hdict_path, params=params(health__modules=[{"name": "locem", "crucial": True}],
                                                              datastore__hdict_synchronous=synchronous),
                          start_watchdog=False)
    ex.operator.add_listener(AutoOperator(ex.controller, {"mount_tool": "done", "validate_line": "valid",
                                                          "manual_taping": "done"}))
    t = time.perf_counter()
    phase = ex.controller.run_process(PemkreDouble.PROCESS)
    wall = time.perf_counter() - t
    stats = list(ex.controller.stats)
    ex.close()
    assert phase == "ended", phase
    return stats, wall


def bench_overhead(reps):
    print("3. HICEM overhead per high-level action (taping process: SCAN, GET_TOOL, 3x VALIDATE+TAPE, GO_HOME;"
          " %d runs)" % reps)
    for label in ("HDICT synchronous=FULL", "HDICT synchronous=NORMAL", "memory only (no HDICT)"):
        per_type = {}
        totals = []
        for _ in range(reps):
            with tempfile.TemporaryDirectory() as d:
                stats, wall = run_process(os.path.join(d, "hdict.sqlite") if label.startswith("HDICT") else None,
                                          "NORMAL" if "NORMAL" in label else "FULL")
            for s in stats:
                per_type.setdefault(s.action_type, []).append(s.overhead_s)
                totals.append(s.overhead_s)
        print("   %-26s all actions: median %.2f ms  p95 %.2f ms  max %.2f ms  (goal <= 20 ms: %s)" % (
            label, statistics.median(totals) * 1e3, pct(totals, 0.95) * 1e3, max(totals) * 1e3,
            "met" if pct(totals, 0.95) <= 0.020 else "NOT met"))
        print("      per type (median): " + ", ".join(
            "%s %.2f" % (k, statistics.median(v) * 1e3) for k, v in sorted(per_type.items())) + "  [ms]")


def main():
    print("HICEM benchmark (python %s, py_trees %s; load average %.2f on %d CPUs - numbers vary with load)" % (
        sys.version.split()[0], py_trees.version.__version__, os.getloadavg()[0], os.cpu_count() or 0))
    bench_ticks(1000 if QUICK else 5000)
    bench_load(5 if QUICK else 30)
    bench_overhead(2 if QUICK else 10)
    return 0


if __name__ == "__main__":
    sys.exit(main())
