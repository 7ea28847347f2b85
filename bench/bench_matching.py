#!/usr/bin/env python3
"""PEMKRE capability matching benchmark: matching at start_process, and next_action with and without matching.

Prints, measured in the same run:
  * match      -- matching the three shipped processes (taping, spraying, sanding) against a resource model of
                  --skills skills (the trees and commands of a robot, padded with skills realizing other
                  capabilities, some not offered, some involving the operator): cold (catalogue queries + matching,
                  as at the first start_process after the model was loaded) and warm (as at every later start);
                  goal of the issue: <= 50 ms for 3 processes x 100 skills.
  * next_action -- p50/p99 of next_action on the same world without a resource model (the baseline: today's
                  engine) and with one (the matched skill named, templates expanded), and their ratio; goal:
                  p99 no worse than today, <= 10 ms.

usage: python3 bench/bench_matching.py [--skills 100] [--repeat 200] [--features 60] [--samples 300]
Run it under the shared lock: flock /tmp/locem-heavy.lock tools/run.sh python bench/bench_matching.py
"""
import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from typing import Dict, List

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src"))

from rdflib import Graph, Literal, URIRef  # noqa: E402
from rdflib.namespace import RDF  # noqa: E402

from locem_bridge.pemkre import PLB, JournaledStore, ProcessEngine  # noqa: E402
from locem_bridge.pemkre.vocab import SK  # noqa: E402

PROCESSES = (PLB.TapingProcess, PLB.SprayingProcess, PLB.SandingProcess)
TREES = {"GET_TOOL": (PLB.cap_GetTool, True), "SCAN": (PLB.cap_ScanWalls, False),
         "VALIDATE_TAPE_LINE": (PLB.cap_ValidateTapeLine, True), "TAPE_LINE": (PLB.cap_TapeJoint, False),
         "MANUAL_TAPING": (PLB.cap_ManualTaping, True), "SPRAY_AREA": (PLB.cap_SprayArea, False),
         "SAND_AREA": (PLB.cap_SandArea, False), "GO_HOME": (PLB.cap_GoHome, False),
         "RECOVER": (PLB.cap_Recover, True)}
BASIC = {"WALL_READY": SK.cap_ArmToWallReady, "CHANGE_TOOL": SK.cap_ChangeToolAutomatically,
         "GOTO": SK.cap_DriveBase, "HOME": SK.cap_ArmHome}


def resource_model(n_skills: int) -> Graph:
    """One robot with a tool changer: the trees, four commands, padded to ``n_skills`` skills."""
    ns = "https://locem-bridge.example.org/robot/bench/"
    g = Graph()
    robot = URIRef(ns + "robot")
    g.add((robot, RDF.type, URIRef("https://locem-bridge.example.org/ont/ppr#Robot")))
    arm = URIRef(ns + "device_arm")
    g.add((robot, SK.hasDevice, arm))
    for tool, cls in (("taping_tool", "TapingTool"), ("spray_gun", "SprayGun"), ("sander", "Sander")):
        t = URIRef(ns + tool)
        g.add((t, RDF.type, URIRef("https://locem-bridge.example.org/ont/ppr#" + cls)))
        g.add((t, SK.toolName, Literal(tool)))
        g.add((robot, SK.hasTool, t))

    def skill(name: str, basic: bool, cap: URIRef, operator: bool, offered: bool = True) -> URIRef:
        s = URIRef(ns + ("skill_%s" if basic else "skill_tree_%s") % name)
        g.add((s, RDF.type, SK.BasicSkill if basic else SK.CompositeSkill))
        g.add((s, SK.skillName, Literal(name)))
        g.add((s, SK.realizesCapability, cap))
        g.add((s, SK.involvesOperator, Literal(operator)))
        g.add((s, SK.usesDevice, arm))
        if offered:
            g.add((robot, SK.providesSkill, s))
        else:
            g.add((s, SK.notOfferedBy, robot))
            g.add((s, SK.notOfferedReason, Literal("invokes MOUNT_TOOL, which this robot's LOCEM does not register")))
        return s

    count = 0
    for name, cap in BASIC.items():
        s = skill(name, True, cap, False)
        count += 1
        if name == "CHANGE_TOOL":
            p = URIRef(str(s) + "_param_tool")
            g.add((s, SK.hasParameter, p))
            g.add((p, SK.parameterName, Literal("tool")))
            for tool in ("taping_tool", "spray_gun", "sander"):
                g.add((p, SK.allowedValue, Literal(tool)))
    for name, (cap, operator) in TREES.items():
        skill(name, False, cap, operator, offered=name != "GET_TOOL")
        count += 1
    i = 0
    while count < n_skills:              # padding: other capabilities, and rivals for the plasterboard ones
        i += 1
        if i % 5 == 0:
            name, (cap, _) = list(TREES.items())[i % len(TREES)]
            skill("%s_ALT%d" % (name, i), False, cap, True, offered=i % 2 == 0)
        else:
            skill("OTHER_%d" % i, i % 2 == 0, URIRef(str(SK) + "cap_Other%d" % i), False)
        count += 1
    return g


def world(n: int) -> Dict:
    joints, areas = n // 2, n - n // 2
    return {"stamp": 1.0, "walls": [{"id": "wall_1", "p0": [0.0, 3.0], "p1": [4.8, 3.0], "height": 2.5}],
            "joints": [{"id": "wall_1_joint_%d" % i, "wall": "wall_1", "kind": "vertical", "start": [1.2, 3.0, 0.0],
                        "end": [1.2, 3.0, 2.5], "width": 0.05} for i in range(joints)],
            "areas": [{"id": "wall_1_area_%d" % i, "wall": "wall_1", "origin": [0.0, 3.0, 0.0], "u": [1.0, 0.0, 0.0],
                       "width": 4.8, "height": 2.5} for i in range(areas)]}


def pct(xs: List[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, max(0, int(round(q / 100.0 * (len(xs) - 1)))))]


def next_action_times(engine: ProcessEngine, samples: int) -> List[float]:
    """next_action latency over taping runs (each task reported succeeded, untimed), restarted as needed."""
    out: List[float] = []
    while len(out) < samples:
        engine.start_process(str(PLB.TapingProcess), {"validateLines": False}, abort_running=True)
        for _ in range(samples):
            t0 = time.perf_counter()
            a = engine.next_action()
            out.append(time.perf_counter() - t0)
            if a.status != "action" or len(out) >= samples:
                break
            engine.set_task_status(a.task, "in_progress")
            engine.set_task_status(a.task, "succeeded")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--skills", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=200)
    ap.add_argument("--features", type=int, default=60)
    ap.add_argument("--samples", type=int, default=300)
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="bench_matching_")
    try:
        model = resource_model(args.skills)
        store = JournaledStore(os.path.join(tmp, "db"))
        engine = ProcessEngine(store)
        engine.update_world(world(args.features))
        next_action_times(engine, 50)       # warm-up (first queries, caches), not counted
        base = next_action_times(engine, args.samples)
        t0 = time.perf_counter()
        engine.load_resource_model(model)
        load_s = time.perf_counter() - t0
        cold, warm = [], []
        for _ in range(args.repeat):
            engine._catalog = None          # as after loading a model: the catalogue queries run again
            t0 = time.perf_counter()
            for p in PROCESSES:
                assert engine.match_process(str(p)).ok
            cold.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            for p in PROCESSES:
                engine.match_process(str(p))
            warm.append(time.perf_counter() - t0)
        matched = next_action_times(engine, args.samples)
        store.close()
        ms = 1000.0
        print("resource model: %d skills, %d triples; loaded into the store in %.0f ms (once per model change)"
              % (args.skills, len(model), load_s * ms))
        print("matching 3 processes x %d skills   cold (catalogue + match): median %.1f ms  p99 %.1f ms   "
              "warm: median %.2f ms  p99 %.2f ms   goal <= 50 ms"
              % (args.skills, statistics.median(cold) * ms, pct(cold, 99) * ms, statistics.median(warm) * ms,
                 pct(warm, 99) * ms))
        print("next_action (%d features, %d samples)   without model: p50 %.2f ms p99 %.2f ms   with model: "
              "p50 %.2f ms p99 %.2f ms   ratio p99 %.2f   goal p99 <= 10 ms"
              % (args.features, args.samples, statistics.median(base) * ms, pct(base, 99) * ms,
                 statistics.median(matched) * ms, pct(matched, 99) * ms, pct(matched, 99) / pct(base, 99)))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
