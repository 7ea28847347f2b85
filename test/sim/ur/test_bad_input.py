"""Bad input on every port: answered like a real UR controller, logged, and the stand-in keeps serving."""
import socket
import struct
import time

import pytest

from locem_bridge.sim.ur import ConfigurationError, ListenError, UrControllerStandIn

rtde_control = pytest.importorskip("rtde_control")
rtde_receive = pytest.importorskip("rtde_receive")
dashboard_client = pytest.importorskip("dashboard_client")


class RawRtde:
    """Minimal RTDE speaker for sending what ur_rtde never would."""

    def __init__(self, addr: str) -> None:
        self.sock = socket.create_connection((addr, 30004), timeout=2.0)

    def send(self, ptype: int, payload: bytes = b"") -> None:
        self.sock.sendall(struct.pack(">HB", len(payload) + 3, ptype) + payload)

    def recv(self):
        head = self._exact(3)
        size, ptype = struct.unpack(">HB", head)
        return ptype, self._exact(size - 3)

    def recv_type(self, ptype: int, limit: int = 50):
        for _ in range(limit):
            t, body = self.recv()
            if t == ptype:
                return body
        raise AssertionError("no package of type %r" % chr(ptype))

    def _exact(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionError("closed")
            buf += chunk
        return buf

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def inproc(ur_address):
    """An in-process stand-in (no ur_rtde client talks to it from this process while it blocks)."""
    ctl = UrControllerStandIn(ur_address, time_scale=10.0).start()
    yield ctl
    ctl.stop()


def _wait_refused(ctl, text: str, timeout: float = 2.0) -> str:
    t_end = time.time() + timeout
    while time.time() < t_end:
        for line in ctl.refused:
            if text in line:
                return line
        time.sleep(0.01)
    raise AssertionError("nothing refused with %r; refused: %r" % (text, ctl.refused))


def test_malformed_rtde_framing_closes_only_that_connection(inproc):
    bad = RawRtde(inproc.address)
    bad.sock.sendall(b"\x00\x01V")          # size field 1 < header size 3
    _wait_refused(inproc, "malformed package (size field 1 < 3)")
    assert bad.sock.recv(16) == b""          # the controller hung up on it
    bad.close()
    good = RawRtde(inproc.address)
    good.send(86, struct.pack(">H", 2))
    assert good.recv() == (86, b"\x01")
    good.close()


def test_unknown_package_type_wrong_version_and_unknown_recipe_are_refused(inproc):
    raw = RawRtde(inproc.address)
    raw.send(ord("X"), b"\x01\x02")
    _wait_refused(inproc, "unknown package type 88")
    raw.send(86, struct.pack(">H", 7))                  # protocol version 7 does not exist
    assert raw.recv() == (86, b"\x00")
    raw.send(86, struct.pack(">H", 2))
    assert raw.recv() == (86, b"\x01")
    raw.send(85, b"\x09" + b"\x00" * 4)                 # data for input recipe 9 that was never set up
    _wait_refused(inproc, "unknown or failed input recipe 9")
    raw.send(73, b"input_int_register_5")               # recipe 1 (an INT32)
    body = raw.recv_type(73)
    assert body == b"\x01INT32"
    raw.send(85, b"\x01\x00\x00")                       # 2 bytes where 4 are needed
    _wait_refused(inproc, "recipe 1 has 2 bytes, expected 4")
    raw.send(85, b"\x01" + struct.pack(">i", 42))       # a correct one is applied
    time.sleep(0.05)
    assert inproc.arm.in_int[5] == 42
    raw.send(79, struct.pack(">d", 2000.0) + b"actual_q")   # faster than the controller's 500 Hz
    body = raw.recv_type(79)
    assert body[0] == 0
    _wait_refused(inproc, "output frequency 2000.0 outside")
    raw.close()


def test_not_found_output_variable(inproc):
    raw = RawRtde(inproc.address)
    raw.send(86, struct.pack(">H", 2))
    raw.recv()
    raw.send(79, struct.pack(">d", 125.0) + b"actual_q,no_such_variable,runtime_state")
    body = raw.recv_type(79)
    assert body[0] == 0
    assert body[1:].decode() == "VECTOR6D,NOT_FOUND,UINT32"
    _wait_refused(inproc, "NOT_FOUND for ['no_such_variable']")
    raw.send(83)                                         # start without a valid output recipe fails
    assert raw.recv_type(83) == b"\x00"
    raw.close()


def test_types_follow_the_rtde_table_and_streaming_is_500hz(inproc):
    raw = RawRtde(inproc.address)
    raw.send(86, struct.pack(">H", 2))
    raw.recv()
    names = (b"timestamp,actual_q,joint_mode,robot_mode,runtime_state,actual_digital_output_bits,"
             b"actual_tool_accelerometer,output_int_register_0,output_double_register_3,tool_output_mode")
    raw.send(79, struct.pack(">d", 500.0) + names)
    body = raw.recv_type(79)
    assert body[0] == 1
    assert body[1:].decode().split(",") == ["DOUBLE", "VECTOR6D", "VECTOR6INT32", "INT32", "UINT32", "UINT64",
                                            "VECTOR3D", "INT32", "DOUBLE", "UINT8"]
    raw.send(83)
    assert raw.recv_type(83) == b"\x01"
    fmt = struct.Struct(">B d 6d 6i i I Q 3d i d B")
    stamps = []
    for _ in range(200):
        body = raw.recv_type(85)
        vals = fmt.unpack(body)
        stamps.append(vals[1])
    assert vals[0] == 1                         # output recipe id
    assert vals[8:14] == (253,) * 6             # joint_mode RUNNING
    assert vals[14] == 7                        # robot_mode RUNNING
    assert vals[15] == 1                        # runtime_state STOPPED (no program yet)
    # one package per 2 ms controller cycle (the controller clock in "timestamp"; a busy machine may drop cycles,
    # the stream never repeats or reorders one)
    steps = [round((b - a) / 0.002, 6) for a, b in zip(stamps, stamps[1:])]
    assert all(s_ >= 1 and s_ == int(s_) for s_ in steps)
    assert sorted(steps)[len(steps) // 2] == 1
    raw.send(80)                                # pause
    assert raw.recv_type(80) == b"\x01"
    raw.close()


def test_dashboard_garbage_is_answered_and_logged(inproc):
    s = socket.create_connection((inproc.address, 29999), timeout=2.0)
    f = s.makefile("rb")
    assert f.readline() == b"Connected: Universal Robots Dashboard Server\n"
    s.sendall(b"make me a sandwich\n")
    assert f.readline() == b"could not understand: 'make me a sandwich'\n"
    s.sendall(b"\xff\xfe\x00garbage\n")
    assert f.readline().startswith(b"could not understand: '")
    s.sendall(b"robotmode\n")
    assert f.readline() == b"Robotmode: RUNNING\n"
    s.sendall(b"x" * 5000)                      # an over-long line without newline
    assert f.readline().startswith(b"could not understand")
    s.sendall(b"safetystatus\nprogramState\nquit\n")
    assert f.readline() == b"Safetystatus: NORMAL\n"
    assert f.readline() == b"STOPPED <unnamed>\n"
    assert f.readline() == b"Disconnected\n"
    assert f.readline() == b""                  # closed after quit
    s.close()
    _wait_refused(inproc, "make me a sandwich")


def test_script_port_garbage_is_refused_and_program_keeps_running(ur_standin):
    addr = ur_standin.address
    c = rtde_control.RTDEControlInterface(addr)
    try:
        with socket.create_connection((addr, 30003), timeout=2.0) as s:
            s.sendall(b"\x00\x01\x02\xff binary junk\n")
            s.sendall(b"this is not urscript at all !!\n")
            time.sleep(0.2)
        refused = ur_standin.refused()
        assert any("binary data is not URScript" in r for r in refused)
        assert any("syntax error in URScript line" in r for r in refused)
        assert c.isProgramRunning()
        assert c.moveJ([0.2, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], 1.0, 1.0)
    finally:
        c.disconnect()


def test_second_control_interface_gets_in_use(ur_standin):
    addr = ur_standin.address
    c = rtde_control.RTDEControlInterface(addr)
    try:
        with pytest.raises(RuntimeError, match="already in use"):
            rtde_control.RTDEControlInterface(addr)
        assert any("IN_USE" in r for r in ur_standin.refused())
        assert c.moveJ([0.1, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], 1.0, 1.0)   # the first one still works
    finally:
        c.disconnect()


def test_receive_interface_with_unknown_variable_fails_clearly(ur_standin):
    with pytest.raises(RuntimeError, match="not found by the controller"):
        rtde_receive.RTDEReceiveInterface(ur_standin.address, -1.0, ["actual_q", "no_such_variable"])
    r = rtde_receive.RTDEReceiveInterface(ur_standin.address, -1.0, ["actual_q", "timestamp"])
    try:
        assert len(r.getActualQ()) == 6
    finally:
        r.disconnect()


@pytest.mark.parametrize("kwargs, message", [
    (dict(address="robot.local"), "not an IPv4 address"),
    (dict(address="127.0.0.1", time_scale=0.0), "time_scale must be a finite number > 0"),
    (dict(address="127.0.0.1", model="kuka"), "unknown arm model 'kuka'"),
    (dict(address="127.0.0.1", q0=[0.0] * 5), "q0 must hold 6 finite joint positions"),
    (dict(address="127.0.0.1", ports={"modbus": 502}), "unknown port names"),
])
def test_bad_configuration_names_the_problem(kwargs, message):
    with pytest.raises(ConfigurationError, match=message):
        UrControllerStandIn(**kwargs)


def test_address_in_use_is_reported_and_restart_works(inproc):
    other = UrControllerStandIn(inproc.address)
    with pytest.raises(ListenError) as caught:     # one line naming address, port and why (also an OSError)
        other.start()
    assert str(caught.value) == ("UR controller stand-in cannot listen on %s:29999 (dashboard port): Address already "
                                 "in use" % inproc.address)
    assert isinstance(caught.value, OSError)
    inproc.stop()
    inproc.start()                               # same object, restarted on the same address
    s = socket.create_connection((inproc.address, 29999), timeout=2.0)
    assert s.makefile("rb").readline().startswith(b"Connected")
    s.close()


def test_random_bytes_on_every_port_never_stop_the_standin(ur_address):
    """Fuzz: random byte strings on the three ports; afterwards every server still answers correctly."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    ctl = UrControllerStandIn(ur_address, time_scale=10.0).start()
    try:
        @settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
        @given(port=st.sampled_from([29999, 30003, 30004]), data=st.binary(min_size=1, max_size=300))
        def poke(port, data):
            with socket.create_connection((ur_address, port), timeout=2.0) as s:
                s.sendall(data)

        poke()
        time.sleep(0.2)
        raw = RawRtde(ur_address)
        raw.send(86, struct.pack(">H", 2))
        assert raw.recv() == (86, b"\x01")
        raw.close()
        s = socket.create_connection((ur_address, 29999), timeout=2.0)
        f = s.makefile("rb")
        f.readline()
        s.sendall(b"robotmode\n")
        assert f.readline() == b"Robotmode: RUNNING\n"
        s.close()
        assert ctl.running and ctl.cycle_count > 0
    finally:
        ctl.stop()
