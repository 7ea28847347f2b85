"""The README's main job.

Today (LOCEM alone): a ROS master (11311, or the one already running), the LOCEM node, and its command
catalogue printed through the real ``rosservice call /locem/command "command: 'HELP'"``; then LOCEM keeps
serving until Ctrl-C. ``--once`` (or ``CI`` set in the environment) stops after printing.
"""

import argparse
import os
import subprocess
import sys
import time
from typing import List, Optional

from .processes import RosProcesses


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--once", action="store_true", help="stop after printing the catalogue")
    parser.add_argument("--port", type=int, default=11311, help="ROS master port (default 11311)")
    args = parser.parse_args(argv)
    once = args.once or bool(os.environ.get("CI"))
    with RosProcesses(port=args.port, log_dir=os.path.join(os.environ.get("ROS_HOME", os.path.expanduser("~/.ros")),
                                                           "locem_main")) as ros:
        print("[main] ROS master at %s" % ros.env["ROS_MASTER_URI"], flush=True)
        ros.start_master()
        print("[main] starting LOCEM (roslaunch locem_bridge locem.launch)", flush=True)
        ros.spawn(["roslaunch", "--wait", "locem_bridge", "locem.launch"], "locem")
        ros.wait_for_service("/locem/command", timeout=60)
        print('[main] rosservice call /locem/command "command: \'HELP\'"', flush=True)
        reply = subprocess.run(["rosservice", "call", "/locem/command", "command: 'HELP'"], env=ros.env,
                               capture_output=True, text=True, timeout=60)
        if reply.returncode != 0:
            print(reply.stdout + reply.stderr, file=sys.stderr)
            return 1
        import yaml

        answer = yaml.safe_load(reply.stdout)
        print(answer["message"], flush=True)
        if not answer["success"]:
            return 1
        if once:
            print("[main] done (--once)", flush=True)
            return 0
        print("[main] LOCEM is serving on %s; try:\n  ROS_MASTER_URI=%s rosservice call /locem/command "
              "\"command: 'WAIT 1'\"\n[main] Ctrl-C to stop" % ("/locem/command", ros.env["ROS_MASTER_URI"]),
              flush=True)
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            print("\n[main] stopping", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
