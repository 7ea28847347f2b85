"""The /proc sampler of the job benchmark, on a real process tree started here.

The tree: a parent (the root, sleeping) that starts two children, one named like a ROS node started by
roslaunch (``__name:=burner``) which burns a fixed amount of CPU and allocates memory, and one unnamed helper
forked by the burner (it must count for the burner). The sampler must find the groups, attribute CPU and
memory to them, keep the CPU of processes that exited, and never read a reused pid as the old process.
"""
import subprocess
import sys
import textwrap
import time

import pytest

from locem_bridge.job.procstat import (ProcessTreeSampler, ProcStatError, node_name, read_proc, same_process,
                                       tree_pids)

BURN_S = 0.25         # CPU seconds the burner uses before it reports
ALLOC = 80 * 1024 * 1024

CHILD = textwrap.dedent("""
    import subprocess, sys, time
    helper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    data = bytearray(%d)
    for i in range(0, len(data), 4096):
        data[i] = 1
    while time.process_time() < %f:
        pass
    print("burned", helper.pid, flush=True)
    sys.stdin.readline()
    helper.kill()
    helper.wait()
""" % (ALLOC, BURN_S))

PARENT = textwrap.dedent("""
    import subprocess, sys
    child = subprocess.Popen([sys.executable, "-c", sys.argv[1], "__name:=burner", "__ns:=/robot1"],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    print(child.pid, child.stdout.readline().split()[1], flush=True)
    sys.stdin.readline()
    child.stdin.write("stop\\n")
    child.stdin.flush()
    child.wait()
    sys.stdin.readline()
""")


@pytest.fixture
def tree():
    parent = subprocess.Popen([sys.executable, "-c", PARENT, CHILD], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              text=True)
    try:
        burner, helper = (int(v) for v in parent.stdout.readline().split())
        yield parent, burner, helper
    finally:
        parent.kill()
        parent.wait(10)


def test_node_names_come_from_roslaunch_arguments():
    assert node_name(["/usr/bin/python3", "/ws/lib/hicem_node", "__name:=hicem", "__log:=/x.log"]) == "/hicem"
    assert node_name(["python3", "x", "__ns:=/robot1/", "__name:=locem"]) == "/robot1/locem"
    assert node_name(["/usr/bin/python3", "/opt/ros/bin/rosmaster", "--core", "-p", "11311"]) == "rosmaster"
    assert node_name(["python3", "-c", "pass"]) is None


def test_sampler_groups_processes_by_node_and_attributes_cpu_and_memory(tree):
    parent, burner, helper = tree
    sampler = ProcessTreeSampler(parent.pid, root_name="launch", period=0.05)
    assert sampler.sample() == 3
    groups = sampler.summary()
    assert set(groups) == {"launch", "/robot1/burner"}
    assert groups["/robot1/burner"]["pids"] == 2          # the unnamed helper counts for the node that forked it
    # the burner used its CPU before it reported: at least what it burned (clock-tick resolution aside)
    assert groups["/robot1/burner"]["cpu_s"] >= BURN_S - 0.05
    assert groups["launch"]["cpu_s"] < groups["/robot1/burner"]["cpu_s"]
    assert groups["/robot1/burner"]["peak_rss"] >= ALLOC
    assert sampler.peak_rss >= groups["/robot1/burner"]["peak_rss"] + groups["launch"]["peak_rss"]
    assert set(sampler.seen) == {parent.pid, burner, helper}


def test_cpu_of_exited_processes_is_kept_and_the_tree_ends_with_its_root(tree):
    parent, burner, helper = tree
    sampler = ProcessTreeSampler(parent.pid, root_name="launch", period=0.05)
    sampler.sample()
    used = sampler.summary()["/robot1/burner"]["cpu_s"]
    parent.stdin.write("\n")                              # the burner and its helper exit
    parent.stdin.flush()
    end = time.monotonic() + 20
    while same_process(burner, sampler.seen[burner]) and time.monotonic() < end:
        time.sleep(0.05)
    assert not same_process(burner, sampler.seen[burner])
    assert sampler.sample() == 1                          # only the parent is left
    after = sampler.summary()["/robot1/burner"]
    assert after["cpu_s"] >= used                         # its CPU did not vanish with it
    parent.stdin.write("\n")
    parent.stdin.flush()
    parent.wait(10)
    assert sampler.sample() == 0                          # the root is gone: nothing to follow


def test_the_background_thread_samples_until_stopped_and_windows_split_the_cpu(tree):
    parent, _burner, _helper = tree
    sampler = ProcessTreeSampler(parent.pid, root_name="launch", period=0.02).start()
    end = time.monotonic() + 10
    while sampler.samples < 1 and time.monotonic() < end:
        time.sleep(0.01)
    t0 = time.time()                                      # the burner has burned its CPU before this
    while sampler.samples < 5 and time.monotonic() < end:
        time.sleep(0.02)
    sampler.stop()
    count = sampler.samples
    assert count >= 5
    time.sleep(0.1)
    assert sampler.samples == count                       # stopped means stopped
    row = sampler.summary(window=(t0, time.time()))["/robot1/burner"]
    # the CPU burned before the window opened is not the window's
    assert 0.0 <= row["window_cpu_s"] <= row["cpu_s"]
    assert row["window_cpu_s"] < BURN_S / 2


def test_tree_pids_and_reused_pids(tree):
    parent, burner, helper = tree
    pids = tree_pids(parent.pid)
    assert set(pids) == {parent.pid, burner, helper}
    assert same_process(burner, pids[burner])
    assert not same_process(burner, pids[burner] + 1)     # same pid, another start time: another process
    assert read_proc(2 ** 22 + 12345) is None


def test_bad_arguments_are_refused_clearly():
    with pytest.raises(ProcStatError, match="no process with pid"):
        ProcessTreeSampler(2 ** 22 + 12345)
    with pytest.raises(ProcStatError, match="period must be > 0"):
        ProcessTreeSampler(1, period=0)
