"""Command line: ``python -m locem_bridge.sim.ur --address 127.0.0.2 --time-scale 5`` runs one UR stand-in.

Without ``--stdio`` it serves until Ctrl-C / SIGTERM. With ``--stdio`` it is driven by a parent process through the
JSON-lines pipe of :mod:`locem_bridge.sim.ur.process` and ends on EOF.
"""
import argparse
import json
import logging
import signal
import sys
import threading
from typing import List, Optional

from .controller import DEFAULT_Q, UrControllerStandIn
from .errors import UrStandInError
from .process import serve_stdio


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m locem_bridge.sim.ur", description=__doc__)
    ap.add_argument("--address", default="127.0.0.1", help="IPv4 address to bind (default 127.0.0.1)")
    ap.add_argument("--time-scale", type=float, default=1.0, help="motion time / wall time (default 1.0)")
    ap.add_argument("--model", default="ur10e", help="ur10e, ur5e, ur10, ur5, ur3 or a URDF path (default ur10e)")
    ap.add_argument("--q0", default=None, help="initial joint positions, 6 comma-separated values in rad")
    ap.add_argument("--stdio", action="store_true", help="serve the JSON-lines control pipe on stdin/stdout")
    ap.add_argument("--log-level", default="INFO", help="logging level (default INFO)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=getattr(logging, args.log_level.upper(), logging.INFO), stream=sys.stderr,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    # The 500 Hz control thread shares the GIL with the I/O thread: a short switch interval keeps its wake-up
    # latency well under one control period (the default 5 ms is 2.5 periods).
    sys.setswitchinterval(0.0005)
    try:
        q0 = [float(v) for v in args.q0.split(",")] if args.q0 else list(DEFAULT_Q)
        ctl = UrControllerStandIn(args.address, time_scale=args.time_scale, model=args.model, q0=q0)
        ctl.start()
    except Exception as exc:
        if args.stdio:
            print(json.dumps({"ready": False, "error": "%s: %s" % (type(exc).__name__, exc)}), flush=True)
            return 1
        if isinstance(exc, UrStandInError):     # a port taken, a bad argument: one line, no traceback
            print("UR stand-in: cannot start: %s" % exc, file=sys.stderr, flush=True)
            return 2
        raise
    if args.stdio:
        print(json.dumps({"ready": True}), flush=True)
        serve_stdio(ctl)
        return 0
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    try:
        while not done.wait(0.5):
            pass
    except KeyboardInterrupt:
        pass
    ctl.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
