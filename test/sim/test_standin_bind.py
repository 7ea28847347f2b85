"""A device stand-in that cannot bind says which address and port, in one line: the port is bound first (as
another run's stand-in would hold it), then the stand-in is started. Addresses in 127.76.1.x (no other test uses
them), CAN ports of their own."""
import os
import socket
import subprocess
import sys
import time

import pytest

from locem_bridge.sim.modbus.compressor import CompressorModel
from locem_bridge.sim.errors import DeviceStandInError
from locem_bridge.sim.modbus.modbus_server import CompressorServer

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ENV = dict(os.environ, PYTHONPATH=os.path.join(REPO, "src") + os.pathsep + os.environ.get("PYTHONPATH", ""))


def listen(host, port):
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    sock.listen(1)
    return sock


def run(args, timeout=60):
    return subprocess.run([sys.executable, "-m"] + args, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          universal_newlines=True, timeout=timeout)


def test_compressor_on_a_taken_port_names_address_and_port(robot_cfg):
    taken = listen("127.76.1.1", 5020)
    try:
        server = CompressorServer(CompressorModel(robot_cfg["robot"]["compressor"], time.monotonic),
                                  "127.76.1.1", 5020, 1)
        with pytest.raises(DeviceStandInError) as caught:
            server.start()
    finally:
        taken.close()
    assert str(caught.value) == "compressor Modbus stand-in cannot listen on 127.76.1.1:5020: Address already in use"


def test_ur_standin_process_on_a_taken_port_ends_with_one_line():
    taken = listen("127.76.1.2", 30004)
    try:
        done = run(["locem_bridge.sim.ur", "--address", "127.76.1.2"])
    finally:
        taken.close()
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip() == ("UR stand-in: cannot start: UR controller stand-in cannot listen on "
                                   "127.76.1.2:30004 (rtde port): Address already in use"), done.stderr


def test_worksite_on_a_taken_ur_port_ends_with_one_line_and_frees_what_it_had_bound(tmp_path):
    """The whole worksite (python -m locem_bridge.sim) whose UR dashboard port is taken: one line on stderr, exit
    status 2, no traceback; the Modbus port it had bound before is free again."""
    taken = listen("127.76.1.3", 29999)
    try:
        done = run(["locem_bridge.sim", "--host", "127.76.1.3", "--can-channel", "239.74.177.1",
                    "--can-port", "44813", "--log-level", "ERROR"], timeout=120)
    finally:
        taken.close()
    assert done.returncode == 2, done.stdout + done.stderr
    lines = [line for line in done.stderr.splitlines()      # pybullet's C library prints its banner at import
             if line.strip() and not line.startswith("pybullet build time")]
    assert lines == ["worksite: cannot start: UR controller stand-in cannot listen on 127.76.1.3:29999 "
                     "(dashboard port): Address already in use"], done.stderr
    listen("127.76.1.3", 5020).close()      # the compressor stand-in started before the UR one was stopped
