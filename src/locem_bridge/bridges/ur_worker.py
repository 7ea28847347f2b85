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

Safe state and watchdog: right after connecting, before it reports ready, the worker stops the arm (``stopJ``: a
LOCEM that died may have left a motion running) and, unless ``--watchdog 0``, asks the control script for an RTDE
watchdog (``setWatchdog``: the controller stops the program, and so the arm, when no input package reaches it for
1 / frequency s). Every ``state`` request (the parent polls at 50 Hz) kicks it; a script re-upload (``reupload``,
a path move) removes it on the controller, so those set it again. When LOCEM dies its poll stops, and with it the
kicks, whether or not this worker lives on.
"""

import argparse
import json
import sys
import time
from typing import Any, Callable, Dict, List, Tuple


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


STOP_DECEL_J = 10.0          # rad/s^2, the safe-state stopJ at connect
STAMP_READS = 3              # reads of a stamp and a TCP pose: all but the last checked to be of one package
REALTIME_GUARD_S = 0.2       # no watchdog kick this long after a realtime command (see kicked_state)


def _arm_watchdog(c: Any, frequency: float) -> None:
    if frequency > 0.0 and not c.setWatchdog(float(frequency)):
        raise RuntimeError("setWatchdog(%g) refused by the controller" % frequency)


def _ops(h: Dict[str, Any], watchdog: float = 0.0) -> Dict[str, Callable[..., Any]]:
    r, c, io, dash = h["r"], h["c"], h["io"], h["dash"]

    realtime_sent = [0.0]            # time.monotonic() of the last realtime command (forceMode)

    def kicked_state() -> Dict[str, Any]:
        # a kick writes command 0 into the command register: right after a realtime command (answered at once,
        # read by the script's next cycle) it could overwrite that command before the controller saw it
        if watchdog > 0.0 and time.monotonic() - realtime_sent[0] > REALTIME_GUARD_S:
            c.kickWatchdog()
        return state()

    def realtime(result: Any) -> Any:
        realtime_sent[0] = time.monotonic()
        return result

    def rearmed(result: Any) -> Any:
        if c.isProgramRunning():            # a refused path halts the script: the next re-upload re-arms
            _arm_watchdog(c, watchdog)
        return result

    def stamped_tcp() -> Tuple[float, List[float]]:
        """The controller's timestamp and the TCP pose of ONE package: ur_rtde's receive thread may store a new
        package between the two reads (the pose then one RTDE cycle newer than its stamp: 2 ms at 500 Hz, 8 ms at
        125 Hz, against 20 ms between two polls), so the stamp is read before and after the pose and the read is
        made again when they differ."""
        for _ in range(STAMP_READS - 1):
            before = float(r.getTimestamp())
            tcp = list(r.getActualTCPPose())
            if float(r.getTimestamp()) == before:
                return before, tcp
        return float(r.getTimestamp()), list(r.getActualTCPPose())

    def state() -> Dict[str, Any]:
        stamp, tcp = stamped_tcp()
        return {"timestamp": stamp, "tcp": tcp, "q": list(r.getActualQ()),
                "qd": list(r.getActualQd()),
                "safety_mode": int(r.getSafetyMode()), "safety_bits": int(r.getSafetyStatusBits()),
                "robot_mode": int(r.getRobotMode()), "runtime_state": int(r.getRuntimeState()),
                "do_bits": int(r.getActualDigitalOutputBits()), "progress": int(c.getAsyncOperationProgress()),
                "receive_connected": bool(r.isConnected()), "control_connected": bool(c.isConnected()),
                "program_running": bool(c.isProgramRunning()),
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
        "state": kicked_state,
        "q": lambda: list(r.getActualQ()),
        "tcp": lambda: list(r.getActualTCPPose()),
        "moveJ": lambda q, v, a: bool(c.moveJ(list(q), float(v), float(a), True)),
        "moveL": lambda p, v, a: bool(c.moveL(list(p), float(v), float(a), True)),
        # one path of [x, y, z, rx, ry, rz, speed, accel, blend] rows; ur_rtde re-uploads its control script
        # with the path injected, then starts it (command 45) asynchronously
        "movePath": lambda path: rearmed(bool(c.moveL([[float(v) for v in row] for row in path], True))),
        "stopJ": lambda a: c.stopJ(float(a), False),
        "stopL": lambda a: c.stopL(float(a), False),
        "forceMode": lambda frame, sel, wrench, typ, limits: realtime(bool(c.forceMode(
            [float(v) for v in frame], [int(v) for v in sel], [float(v) for v in wrench], int(typ),
            [float(v) for v in limits]))),
        "forceModeStop": lambda: bool(c.forceModeStop()),
        "zeroFt": lambda: bool(c.zeroFtSensor()),
        "setTcp": lambda p: bool(c.setTcp(list(p))),
        "setPayload": lambda m, cog: bool(c.setPayload(float(m), list(cog))),
        "setDO": lambda i, v: bool(io.setStandardDigitalOut(int(i), bool(v))),
        "dash": dash_cmd,
        "reupload": lambda: rearmed(bool(c.reuploadScript())),
        "ik": lambda p, qnear: list(c.getInverseKinematics(list(p), list(qnear))),
    }


def main(argv: List[str] = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m locem_bridge.bridges.ur_worker", description=__doc__)
    ap.add_argument("--host", required=True)
    ap.add_argument("--frequency", type=float, default=500.0)
    ap.add_argument("--watchdog", type=float, default=0.0, help="RTDE watchdog min frequency, Hz (0 = none)")
    args = ap.parse_args(argv)
    out = sys.stdout
    try:
        handles = _connect(args.host, args.frequency)
        handles["c"].stopJ(STOP_DECEL_J, False)          # safe state: whatever a dead LOCEM left moving stops
        _arm_watchdog(handles["c"], args.watchdog)
    except Exception as exc:  # report why, the parent retries with backoff
        out.write(json.dumps({"ready": False, "error": "%s: %s" % (type(exc).__name__, exc)}) + "\n")
        out.flush()
        return 1
    ops = _ops(handles, args.watchdog)
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
