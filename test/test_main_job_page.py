"""The page ``tools/main.sh`` prints, opened in a real headless browser while the main job runs, then the job cut
short by Ctrl-C: what a person watching the default (automatic operator) run sees and gets.

Runs ``python -m locem_bridge.ros.main_job`` (the driver behind tools/main.sh: the whole launch, automatic
operator) on config/sites/no_joints.yaml (one wall: taping has nothing to do, spraying works its areas), reads the
``operator page:`` URL it prints, opens it in chromium and checks that the page shows the running spraying
process and its progress in areas. Then it presses Ctrl-C (SIGINT to the driver, which stops the launch as it
does for a person) and checks that the job still wrote its report, saying it ended early because the launch shut
down, with sanding not run, and that the driver printed that. Needs the environment of tools/test.sh and, as every
whole-job run (it binds the simulated devices' fixed addresses), the machine's heavy lock
(``flock /tmp/locem-heavy.lock``); it lives outside the unit-test folders for that reason. About 20 s.
"""
import json
import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import threading
import time

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "test", "hmi"))          # the browser fixture of the HMI tests

from test_browser import CHROMIUM, ON_UBUNTU, browser  # noqa: E402,F401 - the chromium fixture
READY = os.environ.get("LOCEM_REPO") == REPO and shutil.which("roslaunch") is not None
pytestmark = [pytest.mark.slow, pytest.mark.ros,
              pytest.mark.skipif(not READY, reason="needs the environment of tools/test.sh (setup done, ROS sourced)"),
              pytest.mark.skipif(ON_UBUNTU and not os.path.exists(CHROMIUM),
                                 reason="platform: Ubuntu 20.04 has no Debian chromium package at /usr/bin/chromium")]


def test_the_printed_page_shows_the_job_and_a_cut_short_job_still_reports(browser, tmp_path):  # noqa: F811
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    results = tmp_path / "results"
    env = dict(os.environ, ROS_HOME=str(tmp_path / "ros_home"), ROS_LOG_DIR=str(tmp_path / "log"))
    proc = subprocess.Popen([sys.executable, "-m", "locem_bridge.ros.main_job", "--site",
                             os.path.join(REPO, "config", "sites", "no_joints.yaml"), "--results-dir", str(results),
                             "--time-scale", "10", "--timeout", "400", "--launch-arg", "state_dir:=%s" % tmp_path],
                            cwd=str(tmp_path), env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            bufsize=1)
    lines: "queue.Queue[str]" = queue.Queue()
    out = []

    def pump():
        for line in proc.stdout:
            out.append(line)
            lines.put(line)
    threading.Thread(target=pump, daemon=True).start()
    try:
        url = None
        end = time.monotonic() + 60
        while url is None and time.monotonic() < end:
            try:
                found = re.search(r"\[main\] operator page: (http://\S+)", lines.get(timeout=1))
            except queue.Empty:
                continue
            url = found.group(1) if found else None
        assert url, "main_job printed no operator page:\n" + "".join(out)

        def text(elem_id):
            return browser.find_element(By.ID, elem_id).text

        end = time.monotonic() + 120                     # the launch starts its nodes
        while True:
            try:
                browser.get(url)
                break
            except Exception:  # noqa: BLE001 - connection refused until the node serves
                assert time.monotonic() < end and proc.poll() is None, "the page was never served:\n" + "".join(out)
                time.sleep(1.0)
        wait = WebDriverWait(browser, 240, poll_frequency=0.2)
        wait.until(lambda d: text("connection") == "live", "the event stream to connect")
        seen = set()

        def spraying_with_progress():
            seen.add((text("status-process"), text("status-phase"), text("progress-text")))
            return (text("status-process") == "SprayingProcess" and text("status-phase") == "running"
                    and re.match(r"areas sprayed: \d+ of [1-9]\d*\Z", text("progress-text")))
        wait.until(lambda d: spraying_with_progress(), "the page to show spraying with its progress in areas")
        assert "SPRAY_AREA" in text("status-action") or text("status-action"), text("status-action")
        assert browser.save_screenshot(str(tmp_path / "main_job_page.png"))
        assert not [s for s in seen if s[0] == "SprayingProcess" and "joints" in s[2]], seen
        assert not [e["message"] for e in browser.get_log("browser") if e["level"] == "SEVERE"]

        proc.send_signal(signal.SIGINT)                   # Ctrl-C in the middle of spraying
        proc.wait(90)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    time.sleep(0.2)
    text_out = "".join(out)
    print(text_out[-3000:])
    assert proc.returncode == 1, text_out[-4000:]
    assert "[main] ended early: shutdown" in text_out, text_out[-4000:]
    report = text_out.rsplit("report: ", 1)[1].strip().splitlines()[0]
    with open(os.path.join(os.path.dirname(report), "report.json"), encoding="utf-8") as handle:
        data = json.load(handle)
    ended = data["ended"]
    assert ended["reason"] == "shutdown" and ended["early"] is True and ended["not_run"] == ["sanding"], ended
    assert "(SIGINT) while spraying was running" in ended["detail"], ended
    assert [(p["name"], p["status"]) for p in data["processes"]] == [("taping", "succeeded"),
                                                                    ("spraying", "interrupted")]
    assert data["outcome"]["measured"] is True and data["outcome"]["walls"], data["outcome"]
    assert not [line for line in out if "Traceback" in line], text_out[-4000:]
