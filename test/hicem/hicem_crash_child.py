"""Child process for the kill -9 test (test code): runs HICEM over an HDICT file, the PEMKRE double persisted
in a JSON file and the LOCEM double logging to a file. argv: start|resume|suspend workdir (suspend: start, and
suspend the action once the second APPLY_TAPE runs, then log ``## suspended <state>`` and wait to be killed)."""
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [os.path.join(HERE, "..", "..", "src"), HERE]

from hicem_doubles import AutoOperator, Heartbeats, LocemDouble, PemkreDouble  # noqa: E402
from hicem_rig import params  # noqa: E402
from locem_bridge.hicem.executive import create_executive  # noqa: E402


def main() -> int:
    mode, work = sys.argv[1], sys.argv[2]
    pem = PemkreDouble(state_path=os.path.join(work, "pemkre.json"))
    loc = LocemDouble(durations={"APPLY_TAPE": 1.0, "GOTO": 0.05}, log_path=os.path.join(work, "locem.log"))
    ex = create_executive(pem, loc, os.path.join(work, "hdict.sqlite"), params=params())
    ex.operator.add_listener(AutoOperator(ex.controller, {"mount_tool": "done", "validate_line": "valid",
                                                          "manual_taping": "done", "finish_interrupted": "done"}))
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    loc.log("## %s pid %d" % (mode, os.getpid()))
    if mode == "suspend":
        ex.controller.start_process(PemkreDouble.PROCESS)
        while len([h for h in loc.running() if h.command.startswith("APPLY_TAPE ")]) < 1 or \
                len([h for h in loc.handles if h.command.startswith("APPLY_TAPE ")]) < 2:
            time.sleep(0.01)
        time.sleep(0.2)
        state = ex.controller.suspend_action("operator")
        loc.log("## suspended %s" % state.value)
        ex.controller.join()
        return 4
    phase = ex.controller.run_process(PemkreDouble.PROCESS) if mode == "start" else ex.controller.resume()
    loc.log("## finished %s" % phase)
    beats.stop()
    ex.close()
    return 0 if phase == "ended" else 3


if __name__ == "__main__":
    sys.exit(main())
