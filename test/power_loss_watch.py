#!/usr/bin/env python3
"""Helper of test_power_loss.py (not a test): a ROS client of a running job's master that waits until the process
``argv[1]`` runs SPRAY_AREA in its second section (the simulated base stands more than 0.1 m from where it stood at
the first opening of the spray valve seen) and the valve has just opened for a lane, waits ``argv[3]`` wall seconds
(into the lane) and, when the valve is still open for that same lane, prints one JSON line ``{"hicem": state, "opened_sim": sim time of that opening}`` and exits 0;
exit 1 when ``argv[2]`` wall seconds pass first. It prints ``armed: ...`` at the first opening of the valve (every
process of the run is up by then). The valve
is read from the compressor stand-in's own record (``/sim/compressor``), the base from the world's ground truth."""
import json
import math
import sys
import time

import rospy
from geometry_msgs.msg import Pose2D

from locem_bridge.msg import HicemState
from locem_bridge.srv import JsonCall


def main() -> int:
    process, timeout, hold = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
    rospy.init_node("power_loss_watch", anonymous=True, disable_signals=True)
    latest, base = {}, {}
    rospy.Subscriber("/hicem/state", HicemState, lambda m: latest.update(
        process=m.process, phase=m.phase, action_type=m.action_type, task=m.task))
    rospy.Subscriber("/sim/ground_truth/base_pose", Pose2D, lambda m: base.update(x=m.x, y=m.y))
    first_at = None
    was_open = True          # a lane counts from an opening of the valve seen here
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        time.sleep(0.02)
        if latest.get("process") != process or latest.get("action_type") != "SPRAY_AREA" or not base:
            continue
        try:
            rospy.wait_for_service("/sim/compressor", timeout=1.0)
            state = json.loads(rospy.ServiceProxy("/sim/compressor", JsonCall)("{}").result)
        except Exception as exc:  # noqa: BLE001 - the worksite may be busy or starting; try again
            print("compressor not read: %s" % exc, flush=True)
            continue
        opened, was_open = state.get("valve_open") and not was_open, bool(state.get("valve_open"))
        if not opened:
            continue
        here = (base["x"], base["y"])
        if first_at is None:
            first_at = here
            print("armed: the first section sprays", flush=True)     # every process of the run is up by now
        elif math.hypot(here[0] - first_at[0], here[1] - first_at[1]) > 0.1 and latest.get("phase") == "running":
            openings = [e["sim"] for e in state["history"] if e["what"] == "valve_open" and e["value"]]
            time.sleep(hold)       # into the lane, not at its end
            try:
                again = json.loads(rospy.ServiceProxy("/sim/compressor", JsonCall)("{}").result)
            except Exception as exc:  # noqa: BLE001 - busy: look for the next lane
                print("compressor not read: %s" % exc, flush=True)
                was_open = True
                continue
            still = [e["sim"] for e in again["history"] if e["what"] == "valve_open" and e["value"]]
            if again.get("valve_open") and still[-1] == openings[-1]:      # the same lane, still spraying
                print(json.dumps({"hicem": dict(latest), "opened_sim": openings[-1]}), flush=True)
                return 0
            was_open = bool(again.get("valve_open"))
    print("no second section with the valve open within %.0f s (last state %s)" % (timeout, latest), flush=True)
    return 1


if __name__ == "__main__":
    sys.exit(main())
