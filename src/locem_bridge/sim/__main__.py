"""``python3 -m locem_bridge.sim``: run the simulated worksite (world + every device stand-in) until Ctrl-C/SIGTERM.

Prints where each stand-in listens; on exit writes the outcome (numbers + wall pictures) when ``--results`` is
given. Everything else comes from the site and robot files; the options override addresses for a second robot.
"""
from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading
from typing import List, Optional

from ..common.can_bus import CAN_INTERFACES
from ..robot_file import default_robot_path
from .config import default_site_path, load_robot, load_site
from .errors import SimError
from .worksite import Worksite


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m locem_bridge.sim", description=__doc__.splitlines()[0])
    ap.add_argument("--site", default=default_site_path(), help="site YAML (default: %(default)s)")
    ap.add_argument("--robot", default=default_robot_path(), help="robot YAML (default: %(default)s)")
    ap.add_argument("--time-scale", type=float, help="sim seconds per wall second (overrides the site file)")
    ap.add_argument("--gui", action="store_true", help="open the PyBullet GUI")
    ap.add_argument("--host", help="loopback address for the UR and Modbus stand-ins (e.g. 127.0.0.2)")
    ap.add_argument("--modbus-port", type=int, help="Modbus TCP port of the compressor")
    ap.add_argument("--can-interface", choices=CAN_INTERFACES)
    ap.add_argument("--can-channel", help="CAN channel (multicast group, socketcan device, virtual name)")
    ap.add_argument("--can-port", type=int, help="UDP port of the udp_multicast CAN bus")
    ap.add_argument("--no-ur", action="store_true", help="run without the UR controller stand-in")
    ap.add_argument("--base-pose", type=float, nargs=3, metavar=("X", "Y", "YAW"),
                    help="start pose of the base in map (overrides robot_start)")
    ap.add_argument("--arm-pose", help="named arm pose (robot.arm.named_poses) the arm starts in (default: home)")
    ap.add_argument("--mount-tool", choices=("taping_tool", "spray_gun", "sander"),
                    help="tool the operator has mounted before the start")
    ap.add_argument("--results", help="folder for outcome.json and the wall pictures, written on exit")
    ap.add_argument("--log-level", default="INFO")
    args = ap.parse_args(argv)
    logging.basicConfig(level=getattr(logging, args.log_level.upper(), logging.INFO),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if args.log_level.upper() != "DEBUG":
        logging.getLogger("canopen").setLevel(logging.WARNING)     # per-frame chatter
    try:
        site = load_site(args.site)
        robot = load_robot(args.robot)
        if args.base_pose:
            site["site"]["robot_start"] = list(args.base_pose)
        ws = Worksite(site, robot, host=args.host, modbus_port=args.modbus_port, can_interface=args.can_interface,
                      can_channel=args.can_channel, can_port=args.can_port, time_scale=args.time_scale,
                      gui=True if args.gui else None, with_ur=not args.no_ur, arm_pose=args.arm_pose)
        endpoints = ws.start()
    except (SimError, OSError) as exc:
        print("worksite: cannot start: %s" % exc, file=sys.stderr)
        return 2
    try:
        if args.mount_tool:
            ws.mount_tool(args.mount_tool)
    except SimError as exc:
        ws.stop()
        print("worksite: cannot start: %s" % exc, file=sys.stderr)
        return 2
    done = threading.Event()

    def _signal(signum: int, frame: object) -> None:
        done.set()
    signal.signal(signal.SIGINT, _signal)
    signal.signal(signal.SIGTERM, _signal)
    print("worksite running (site %s, robot %s)" % (site["site"]["name"], robot["robot"]["name"]))
    for name, where in endpoints.items():
        print("  %-22s %s" % (name, where))
    print("Ctrl-C or SIGTERM stops it.", flush=True)
    try:
        while not done.wait(0.5):
            pass
    finally:
        if args.results:
            out = ws.save_outcome(args.results)
            print("outcome written to %s: %s" % (args.results, json.dumps(
                {k: out[k] for k in ("joints_total", "joints_taped", "tape_coverage", "spray_coverage",
                                     "sand_coverage", "collisions")})))
        ws.stop()
        print("worksite stopped", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
