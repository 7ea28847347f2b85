"""End to end: ``python3 -m locem_bridge.sim`` in its own process, driven by the REAL clients only —
ur_rtde moves the arm along a joint with the taping tool switched by a UR digital output, pymodbus runs the
compressor, canopen enables a drive over udp_multicast (across processes) — then SIGTERM, and the outcome
written on exit shows the taped part of that joint."""
import copy
import faulthandler
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

rtde_control = pytest.importorskip("rtde_control")
rtde_io = pytest.importorskip("rtde_io")
rtde_receive = pytest.importorskip("rtde_receive")

pytestmark = pytest.mark.slow

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "src")


def _address() -> str:
    import socket
    third = 1 + os.getpid() % 250
    for last in range(1, 250):
        addr = "127.62.%d.%d" % (third, last)
        ok = True
        for port in (29999, 30003, 30004):
            with socket.socket() as s:
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                try:
                    s.bind((addr, port))
                except OSError:
                    ok = False
        if ok:
            return addr
    raise RuntimeError("no free loopback address")


def _joint_and_base_pose(site_cfg):
    """The taped joint (wall_1_joint_2 of the tests' site) and a base pose 1.1 m in front of it."""
    from locem_bridge.sim.site import Site
    joint = next(j for w in Site(site_cfg).walls for j in w.joints if j.id == "wall_1_joint_2")
    x, y = float(joint.start[0]), float(joint.start[1])
    return joint, (x, y - 1.1, 1.5708)


@pytest.fixture
def worksite_process(tmp_path, free_port_factory, site_cfg, test_site_path):
    faulthandler.dump_traceback_later(150, exit=True)    # ur_rtde may hold the GIL while it blocks
    addr = _address()
    modbus_port, can_port = free_port_factory(), free_port_factory()
    results = tmp_path / "results"
    # the same site file as site_cfg; the arm starts in wall_ready (--arm-pose), in front of the wall
    cmd = [sys.executable, "-m", "locem_bridge.sim", "--site", test_site_path, "--host", addr,
           "--modbus-port", str(modbus_port),
           "--can-interface", "udp_multicast", "--can-channel", "239.74.163.2", "--can-port", str(can_port),
           "--time-scale", "4", "--base-pose"] + ["%g" % v for v in _joint_and_base_pose(site_cfg)[1]] + [
           "--arm-pose", "wall_ready", "--mount-tool", "taping_tool",
           "--results", str(results), "--log-level", "WARNING"]
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, text=True)
    lines = []
    deadline = time.monotonic() + 40
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if "SIGTERM stops it" in line:
            break
    else:
        proc.kill()
    if proc.poll() is not None or not any("SIGTERM stops it" in ln for ln in lines):
        proc.kill()
        pytest.fail("worksite did not start:\n" + "".join(lines) + (proc.stdout.read() or ""))
    info = {"addr": addr, "modbus_port": modbus_port, "can_port": can_port, "results": results, "proc": proc,
            "banner": "".join(lines)}
    yield info
    if proc.poll() is None:
        proc.kill()
        proc.wait(10)
    faulthandler.cancel_dump_traceback_later()


def _stop(info):
    proc = info["proc"]
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=30)
    return proc.returncode, out


def test_worksite_process_serves_all_devices_and_records_a_taping_pass(worksite_process, site_cfg, robot_cfg):
    info = worksite_process
    addr = info["addr"]
    banner = info["banner"]
    assert "%s:%d" % (addr, info["modbus_port"]) in banner and "RTDE 30004" in banner
    assert "udp_multicast channel 239.74.163.2 port %d" % info["can_port"] in banner

    # compressor over Modbus TCP
    from pymodbus.client import ModbusTcpClient
    mb = ModbusTcpClient(addr, port=info["modbus_port"], timeout=1.0)
    assert mb.connect()
    assert not mb.write_register(0, 400, device_id=1).isError()
    assert not mb.write_coil(0, True, device_id=1).isError()
    deadline = time.monotonic() + 10
    p = 0.0
    while time.monotonic() < deadline and abs(p - 4.0) > 0.05:
        p = mb.read_input_registers(0, count=1, device_id=1).registers[0] / 100.0
        time.sleep(0.1)
    assert abs(p - 4.0) <= 0.05
    mb.close()

    # one drive over udp_multicast from this (another) process
    import canopen
    from locem_bridge.sim.config import resolve_relative
    from locem_bridge.common.can_bus import open_bus
    eds = resolve_relative(robot_cfg, robot_cfg["robot"]["base"]["eds"])
    net = canopen.Network(open_bus({"interface": "udp_multicast", "channel": "239.74.163.2",
                                    "port": info["can_port"]}))
    net.NOTIFIER_CYCLE = 0.1
    net.connect()
    try:
        node = canopen.BaseNode402(1, eds)
        net.add_node(node)
        node.nmt.wait_for_heartbeat(2.0)
        node.setup_402_state_machine()
        node.nmt.state = "OPERATIONAL"
        node.op_mode = "PROFILED VELOCITY"
        node.state = "OPERATION ENABLED"
        assert node.state == "OPERATION ENABLED"
        node.state = "SWITCH ON DISABLED"
    finally:
        net.disconnect()

    # targets: TCP poses in the UR base frame, computed from the same configuration
    from locem_bridge.sim.world import World
    joint, base_pose = _joint_and_base_pose(site_cfg)
    jx, wy = float(joint.start[0]), float(joint.start[1])
    site = copy.deepcopy(site_cfg)
    site["site"]["robot_start"] = list(base_pose)
    helper = World(site, robot_cfg, gui=False)
    try:
        helper.mount_tool("taping_tool")
        into_wall = [0.0, 1.0, 0.0]
        approach = helper.tcp_target_in_arm_base([jx, wy - 0.1, 1.0], into_wall)
        contact = helper.tcp_target_in_arm_base([jx, wy, 1.0], into_wall)
        top = helper.tcp_target_in_arm_base([jx, wy, 1.8], into_wall)
        retract = helper.tcp_target_in_arm_base([jx, wy - 0.1, 1.8], into_wall)
    finally:
        helper.close()
    tcp = robot_cfg["robot"]["tools"]["taping_tool"]["tcp"]
    ready = robot_cfg["robot"]["arm"]["named_poses"]["wall_ready"]
    do_index = robot_cfg["robot"]["tools"]["taping_tool"]["switch"]["index"]

    c = rtde_control.RTDEControlInterface(addr)
    io = rtde_io.RTDEIOInterface(addr)
    r = rtde_receive.RTDEReceiveInterface(addr)
    try:
        assert c.setTcp(tcp)
        assert c.moveJ(ready, 3.0, 3.0)
        assert c.moveL(approach, 0.5, 1.0)
        assert io.setStandardDigitalOut(do_index, True)
        assert c.moveL(contact, 0.1, 0.5)
        assert c.moveL(top, 0.2, 0.5)
        assert io.setStandardDigitalOut(do_index, False)
        time.sleep(0.2)
        assert c.moveL(retract, 0.1, 0.5)
        assert np.allclose(r.getActualTCPPose()[:3], retract[:3], atol=1e-3)
        time.sleep(0.3)                               # at least one more world step
    finally:
        for client in (c, io, r):
            try:
                client.disconnect()
            except Exception:
                pass

    code, out = _stop(info)
    assert code == 0, out
    assert "worksite stopped" in out
    outcome = json.loads((info["results"] / "outcome.json").read_text())
    joints = outcome["joints"]
    assert joints["wall_1_joint_2"]["coverage"] == pytest.approx(0.8 / joint.length, abs=0.03)
    from locem_bridge.sim.site import Site
    kinds = {j.id: j.kind for w in Site(site_cfg).walls for j in w.joints}
    assert all(v["coverage"] == 0.0 for k, v in joints.items() if k != "wall_1_joint_2" and kinds[k] == "vertical")
    assert all(v["coverage"] < 0.05 for k, v in joints.items() if kinds[k] == "horizontal")    # only crossed
    assert outcome["collisions"] == 0
    assert sorted(outcome["pictures"]) == ["wall_1.png", "wall_2.png"]
    assert (info["results"] / "wall_1.png").stat().st_size > 1000
