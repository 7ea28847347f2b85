"""Worksite composition in process (no UR stand-in): endpoints, operator calls, SCAN, fault injection API,
outcome files, clean stop."""
import json
import os

import pytest
from pymodbus.client import ModbusTcpClient

from locem_bridge.sim.errors import SimStateError
from locem_bridge.sim.worksite import Worksite


@pytest.fixture
def ws(site_cfg, robot_cfg, port):
    w = Worksite(site_cfg, robot_cfg, modbus_port=port, can_interface="virtual",
                 can_channel="api-%d" % os.getpid(), with_ur=False)
    w.start()
    yield w
    w.stop()


def test_endpoints_operator_scan_and_outcome_files(ws, port, tmp_path):
    eps = ws.endpoints()
    assert eps["compressor_modbus_tcp"].startswith("127.0.0.1:%d" % port)
    assert "node ids [1, 2, 3, 4]" in eps["base_drives_can"]
    assert "ur_controller" not in eps
    ws.mount_tool("sander")
    with pytest.raises(SimStateError):
        ws.mount_tool("spray_gun")
    assert ws.remove_tool() == "sander"
    scan = ws.scan()
    assert {j["id"] for j in scan["joints"]} >= {"wall_1_joint_1", "wall_1_joint_2"}
    ws.mark_manual_taping("wall_1_joint_1")
    with pytest.raises(KeyError, match="unknown joint"):
        ws.mark_manual_taping("wall_9_joint_1")
    out = ws.save_outcome(str(tmp_path))
    saved = json.loads((tmp_path / "outcome.json").read_text())
    assert saved["joints_total"] == 6 and saved["joints_manual"] == 1 and saved["collisions"] == 0
    assert out["pictures"] == ["wall_1.png", "wall_2.png"]


def test_fault_injection_api(ws, port):
    with pytest.raises(SimStateError, match="allowed: compressor_overpressure"):
        ws.inject_fault("flat_tyre")
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=0.3, retries=0)
    assert client.connect()
    ws.inject_fault("compressor_link_drop")
    failed = False
    try:
        failed = client.read_input_registers(0, count=1, device_id=1).isError()
    except Exception:
        failed = True
    assert failed
    ws.clear_fault("compressor_link_drop")
    client.close()
    assert client.connect() and not client.read_input_registers(0, count=1, device_id=1).isError()
    client.close()
    ws.inject_fault("drive_fault", node_id=3)
    assert ws.drives.drive(3).snapshot()["state"] == "FAULT"
    ws.inject_fault("drive_heartbeat_loss", node_id=2)
    assert ws.drives.drive(2).snapshot()["online"] is False
    ws.clear_fault("drive_heartbeat_loss", node_id=2)
    assert ws.drives.drive(2).snapshot()["online"] is True
    with pytest.raises(SimStateError, match="no UR controller"):
        ws.inject_fault("arm_protective_stop")
