"""Child process that holds the ur_rtde clients of one UR controller, driven over a JSON-lines pipe.

Why a child process: ur_rtde's bindings keep the GIL while they block (the connection handshake takes tens of
ms to seconds, during which LOCEM's other threads would starve), and after the controller vanishes some of its
calls abort the whole interpreter (an uncaught C++ exception in a background thread). Here a crash costs one
worker; :class:`~.ur_arm.UrRtdeArm` notices EOF and starts a fresh one (a clean reconnect, script upload
included) with backoff.

Protocol: the worker connects (dashboard, receive, control, IO) and prints ``{"ready": true}`` or
``{"ready": false, "error": "..."}``; then it answers one JSON line per request line
``{"id": n, "op": name, "args": [...]}`` with ``{"id": n, "ok": true, "result": ...}`` or
``{"id": n, "ok": false, "error": "..."}``. Motions are always started asynchronously, so every request is
short and a stop can follow at once. EOF on stdin ends the worker.
"""

import argparse
import json
import sys
from typing import Any, Callable, Dict, List


def _connect(host: str, frequency: float) -> Dict[str, Any]:
    import dashboard_client
    import rtde_control
    import rtde_io
    import rtde_receive

    dash = dashboard_client.DashboardClient(host)
    dash.connect()
    receive = rtde_receive.RTDEReceiveInterface(host, frequency)
    control = rtde_control.RTDEControlInterface(host, frequency)
    io = rtde_io.RTDEIOInterface(host)
    return {"dash": dash, "r": receive, "c": control, "io": io}


def _ops(h: Dict[str, Any]) -> Dict[str, Callable[..., Any]]:
    r, c, io, dash = h["r"], h["c"], h["io"], h["dash"]

    def state() -> Dict[str, Any]:
        return {"q": list(r.getActualQ()), "qd": list(r.getActualQd()), "tcp": list(r.getActualTCPPose()),
                "safety_mode": int(r.getSafetyMode()), "safety_bits": int(r.getSafetyStatusBits()),
                "robot_mode": int(r.getRobotMode()), "runtime_state": int(r.getRuntimeState()),
                "do_bits": int(r.getActualDigitalOutputBits()), "progress": int(c.getAsyncOperationProgress()),
                "receive_connected": bool(r.isConnected()), "control_connected": bool(c.isConnected()),
                "program_running": bool(c.isProgramRunning()), "timestamp": float(r.getTimestamp()),
                "tcp_force": list(r.getActualTCPForce())}

    def dash_cmd(name: str) -> str:
        if not dash.isConnected():
            dash.connect()
        fn = {"unlock_protective_stop": dash.unlockProtectiveStop, "close_safety_popup": dash.closeSafetyPopup,
              "power_on": dash.powerOn, "brake_release": dash.brakeRelease,
              "safety_status": dash.safetystatus, "robot_mode": dash.robotmode}[name]
        out = fn()
        return out if isinstance(out, str) else str(out)

    return {
        "state": state,
        "q": lambda: list(r.getActualQ()),
        "tcp": lambda: list(r.getActualTCPPose()),
        "moveJ": lambda q, v, a: bool(c.moveJ(list(q), float(v), float(a), True)),
        "moveL": lambda p, v, a: bool(c.moveL(list(p), float(v), float(a), True)),
        # one path of [x, y, z, rx, ry, rz, speed, accel, blend] rows; ur_rtde re-uploads its control script
        # with the path injected, then starts it (command 45) asynchronously
        "movePath": lambda path: bool(c.moveL([[float(v) for v in row] for row in path], True)),
        "stopJ": lambda a: c.stopJ(float(a), False),
        "stopL": lambda a: c.stopL(float(a), False),
        "forceMode": lambda frame, sel, wrench, typ, limits: bool(c.forceMode(
            [float(v) for v in frame], [int(v) for v in sel], [float(v) for v in wrench], int(typ),
            [float(v) for v in limits])),
        "forceModeStop": lambda: bool(c.forceModeStop()),
        "zeroFt": lambda: bool(c.zeroFtSensor()),
        "setTcp": lambda p: bool(c.setTcp(list(p))),
        "setPayload": lambda m, cog: bool(c.setPayload(float(m), list(cog))),
        "setDO": lambda i, v: bool(io.setStandardDigitalOut(int(i), bool(v))),
        "dash": dash_cmd,
        "reupload": lambda: bool(c.reuploadScript()),
        "ik": lambda p, qnear: list(c.getInverseKinematics(list(p), list(qnear))),
    }


def main(argv: List[str] = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m locem_bridge.bridges.ur_worker", description=__doc__)
    ap.add_argument("--host", required=True)
    ap.add_argument("--frequency", type=float, default=500.0)
    args = ap.parse_args(argv)
    out = sys.stdout
    try:
        handles = _connect(args.host, args.frequency)
    except Exception as exc:  # report why, the parent retries with backoff
        out.write(json.dumps({"ready": False, "error": "%s: %s" % (type(exc).__name__, exc)}) + "\n")
        out.flush()
        return 1
    ops = _ops(handles)
    out.write(json.dumps({"ready": True}) + "\n")
    out.flush()
    for line in sys.stdin:
        line = line.strip()
        if not line:
            continue
        req: Dict[str, Any] = {}
        try:
            req = json.loads(line)
            if req.get("op") == "exit":
                break
            result = ops[req["op"]](*req.get("args", []))
            reply = {"id": req.get("id"), "ok": True, "result": result}
        except Exception as exc:
            reply = {"id": req.get("id"), "ok": False, "error": "%s: %s" % (type(exc).__name__, exc)}
        out.write(json.dumps(reply) + "\n")
        out.flush()
    for key in ("c", "io", "r"):
        try:
            handles[key].disconnect()
        except Exception:
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
