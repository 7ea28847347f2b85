#!/usr/bin/env python3
"""Planning benchmark (issue 19): how long planning a bay takes before the robot moves -- per wall and per site,
on seeded generated bays (locem_bridge.sim.bays) and on the shipped default site (the baseline, same run) -- and
what the plans leave to the hand.

For every site: the ground-truth scan (what SCAN reports from everywhere), the shipped robot's outline
(RobotEnvelope from the robot file, its facts and the HICEM parameters' lane overrun and cfg.plan), then
planning.reach.plan_site for taping, spraying and sanding. Printed: per site its walls, features, planning time
(total and the slowest wall), and the worked / manual share of the area; then p50 / max over the bays and the
ratio to the default site.

Goal: <= 1 s per wall on these 2 cores.

Run with the project environment:  tools/run.sh python bench/bench_plan.py [--bays N] [--seed S] [--repeats R]
Nothing is asserted; numbers are printed.
"""
import argparse
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(REPO, "src"))

from locem_bridge.hicem.config import load_params  # noqa: E402
from locem_bridge.planning.reach import RobotEnvelope, plan_site  # noqa: E402
from locem_bridge.robot_file import load_robot  # noqa: E402
from locem_bridge.sim.bays import generate_bay  # noqa: E402
from locem_bridge.sim.config import load_site, validate_site  # noqa: E402
from locem_bridge.sim.site import Site  # noqa: E402


def envelope() -> RobotEnvelope:
    params = load_params()
    raw = params.raw
    plan = raw.get("plan", {})
    overrun = {w: raw[w]["lane_overrun"] for w in ("spray", "sand") if "lane_overrun" in raw.get(w, {})}
    return RobotEnvelope.from_robot(load_robot()["robot"], params.robot, clearance=plan.get("clearance", 0.05),
                                    arm_radius=plan.get("arm_radius", 0.06),
                                    wrist_length=plan.get("wrist_length", 0.35),
                                    wrist_offset=plan.get("wrist_offset", 0.10),
                                    shoulder_radius=plan.get("shoulder_radius", 0.45), overrun=overrun)


def measure(scan, env, repeats):
    """(best total s, slowest wall s of that run, plan)."""
    best = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        plan = plan_site(scan, env)
        total = time.perf_counter() - t0
        if best is None or total < best[0]:
            best = (total, max(plan.seconds.values()) if plan.seconds else 0.0, plan)
    return best


def shares(scan, plan):
    """(m2 of area, m2 left manual for spraying) -- manual parts of the spray plan (the widest tool reach)."""
    area = sum(a["width"] * a["height"] for a in scan["areas"])
    manual = sum((m["along"][1] - m["along"][0]) * (m["height"][1] - m["height"][0])
                 for p in plan.areas.values() if p.work == "spray" for m in p.manual)
    return area, manual


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bays", type=int, default=20, help="generated bays (default %(default)s)")
    ap.add_argument("--seed", type=int, default=1, help="first seed (default %(default)s)")
    ap.add_argument("--repeats", type=int, default=3, help="plans per site, the best counts (default %(default)s)")
    args = ap.parse_args(argv)
    env = envelope()
    base_scan = Site(load_site()).to_contract()
    base_total, base_wall, base_plan = measure(base_scan, env, args.repeats)
    print("default site: %d walls, %d joints, %d areas: %.1f ms per site, slowest wall %.1f ms"
          % (len(base_scan["walls"]), len(base_scan["joints"]), len(base_scan["areas"]), base_total * 1e3,
             base_wall * 1e3))
    totals, walls_t, per_wall = [], [], []
    print("%-8s %5s %6s %5s %9s %9s %8s %8s" % ("bay", "walls", "joints", "areas", "site ms", "wall ms", "area m2",
                                             "manual"))
    for seed in range(args.seed, args.seed + args.bays):
        scan = Site(validate_site(generate_bay(seed))).to_contract()
        total, slowest, plan = measure(scan, env, args.repeats)
        area, manual = shares(scan, plan)
        totals.append(total)
        walls_t.append(slowest)
        per_wall += list(plan.seconds.values())
        print("%-8s %5d %6d %5d %9.1f %9.1f %8.2f %7.0f%%" % (
            "bay_%d" % seed, len(scan["walls"]), len(scan["joints"]), len(scan["areas"]), total * 1e3, slowest * 1e3,
            area, 100.0 * manual / area if area else 0.0))
    print("planning per site: p50 %.1f ms, max %.1f ms (default site %.1f ms: ratio p50 %.2f)"
          % (statistics.median(totals) * 1e3, max(totals) * 1e3, base_total * 1e3,
             statistics.median(totals) / base_total))
    print("planning per wall: p50 %.1f ms, max %.1f ms; goal <= 1000 ms per wall: max is %.3f of it"
          % (statistics.median(per_wall) * 1e3, max(per_wall) * 1e3, max(per_wall) / 1.0))
    return 0


if __name__ == "__main__":
    sys.exit(main())
