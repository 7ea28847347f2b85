"""Child process of test_base_across_processes.py (not a test): the worksite of ``python3 -m locem_bridge.sim``
without the UR stand-in, its base drives on a udp_multicast CAN bus, with a line protocol on stdin/stdout that
reports the ground truth a test in another process cannot see otherwise.

Usage: ``python base_worksite_child.py SITE_YAML HOST MODBUS_PORT CAN_CHANNEL CAN_PORT``. Prints one JSON line
``{"ready": true}`` once started (or ``{"ready": false, "error": ...}``), then answers each stdin line:
``pose`` -> ``[x, y, yaw]`` of the base in map (World.base_pose), ``wheels`` -> drive velocities (rad/s,
polarity applied), ``exit`` (or EOF) -> stops the worksite and ends.
"""
import json
import sys
from typing import List


def main(argv: List[str]) -> int:
    from locem_bridge.sim.config import load_robot, load_site
    from locem_bridge.sim.worksite import Worksite
    site_path, host, modbus_port, channel, can_port = argv[1:6]
    try:
        ws = Worksite(load_site(site_path), load_robot(), host=host, modbus_port=int(modbus_port),
                      can_interface="udp_multicast", can_channel=channel, can_port=int(can_port), time_scale=1.0,
                      gui=False, with_ur=False)
        ws.start()
    except Exception as exc:
        print(json.dumps({"ready": False, "error": "%s: %s" % (type(exc).__name__, exc)}), flush=True)
        return 1
    try:
        print(json.dumps({"ready": True}), flush=True)
        for line in sys.stdin:
            cmd = line.strip()
            if cmd == "pose":
                out = ws.world.base_pose()
            elif cmd == "wheels":
                out = ws.drives.wheel_speeds()
            elif cmd == "exit":
                break
            else:
                out = {"error": "unknown command %r (pose, wheels, exit)" % cmd}
            print(json.dumps(out), flush=True)
    finally:
        ws.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
