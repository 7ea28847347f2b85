"""kill -9 of HICEM in the middle of taping a line; the restarted HICEM finds the interrupted action in the
HDICT, brings the devices safe, does not tape that line again (the recovery tree has the operator finish it by
hand) and finishes the process without repeating any completed task."""
import json
import os
import signal
import subprocess
import sys
import time

CHILD = os.path.join(os.path.dirname(os.path.abspath(__file__)), "hicem_crash_child.py")


def _log(work):
    p = os.path.join(work, "locem.log")
    return open(p).read().splitlines() if os.path.exists(p) else []


def test_kill_9_mid_tape_line_then_resume(tmp_path):
    work = str(tmp_path)
    proc = subprocess.Popen([sys.executable, CHILD, "start", work])
    try:
        deadline = time.monotonic() + 60
        # wait until the second line's APPLY_TAPE has been sent (the first line is done by then)
        while time.monotonic() < deadline:
            tapes = [line for line in _log(work) if line.startswith("APPLY_TAPE ")]
            if len(tapes) >= 2:
                break
            assert proc.poll() is None, "child ended early: %s" % _log(work)
            time.sleep(0.01)
        else:
            raise AssertionError("never reached the second APPLY_TAPE: %s" % _log(work))
        time.sleep(0.2)  # well inside the 1 s APPLY_TAPE
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=10)
    assert proc.returncode == -signal.SIGKILL
    before = len(_log(work))

    rc = subprocess.run([sys.executable, CHILD, "resume", work], timeout=120).returncode
    log = _log(work)
    after = log[before:]
    assert rc == 0, "resume did not end the process: %s" % after
    assert after[0].startswith("## resume") and after[1] == "STOP"  # devices safe before anything else

    state = json.load(open(os.path.join(work, "pemkre.json")))
    executed = state["statuses"]
    tasks = [s[1] for s in executed]
    assert len(tasks) == len(set(tasks)), "a task was reported twice"
    tape = [(s[4]["line"], s[2], s[3]) for s in executed if s[0] == "TAPE_LINE"]
    # the test site's joints run 0..2.5 m, the taping band is 0.10..2.00 m: the ends are planned manual work
    assert tape[0][:2] == ("wall_1_joint_1", "succeeded") and tape[0][2].startswith("taped; manual work on")
    assert tape[1] == ("wall_1_joint_2", "succeeded", "")  # finished by hand via RESUME_TAPE_LINE
    assert tape[2] == ("wall_2_joint_1", "succeeded", "taped")
    applies = [line for line in log if line.startswith("APPLY_TAPE ")]
    assert len(applies) == 4 and len(set(applies)) == 4  # no piece taped twice (the 2 m horizontal one in two)
    assert [s[0] for s in executed][-1] == "GO_HOME" and log[-1] == "## finished ended"
