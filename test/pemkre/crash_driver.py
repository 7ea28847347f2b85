"""A HICEM stand-in for the crash test: runs the taping process against an on-disk store, logging each
acknowledged task status; the test kills it with SIGKILL at random moments and starts it again.

usage: crash_driver.py STORE_DIR ACK_LOG
"""
import json
import os
import random
import sys
import time

_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(_HERE)), "src"))
sys.path.insert(0, _HERE)

from pemkre_testkit import scan_result  # noqa: E402

from locem_bridge.pemkre import PLB, JournaledStore, ProcessEngine  # noqa: E402

SCAN = scan_result(walls=3, joints_per_wall=4, areas_per_wall=0)


def decide(action):
    """Deterministic operator: lines whose number is a multiple of 3 are invalid."""
    if action.action_type == "SCAN":
        return json.dumps(SCAN)
    if action.action_type == "VALIDATE_TAPE_LINE":
        return "invalid" if int(action.params()["line"].rsplit("_", 1)[1]) % 3 == 0 else "valid"
    return ""


def main(store_dir: str, ack_log: str) -> int:
    store = JournaledStore(store_dir)
    engine = ProcessEngine(store)
    if engine.current_process() is None:
        engine.start_process(str(PLB.TapingProcess), {"validateLines": True})
    rnd = random.Random(os.getpid())
    with open(ack_log, "a") as log:
        for _ in range(500):
            a = engine.next_action()
            if a.status != "action":
                log.write("END %s\n" % a.status)
                log.flush()
                os.fsync(log.fileno())
                store.close()
                return 0
            if a.task_status == "issued":
                engine.set_task_status(a.task, "in_progress")
            time.sleep(rnd.random() * 0.004)
            engine.set_task_status(a.task, "succeeded", decide(a))
            log.write("ACK %s %s\n" % (a.task, a.action_type))
            log.flush()
            os.fsync(log.fileno())
    return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
