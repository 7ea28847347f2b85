"""The stand-in in a child process (what tests and the fault rostests restart after killing it)."""
from locem_bridge.sim.ur.process import StandInProcess


def test_restart_pose_with_negative_first_joint_is_taken(ur_address):
    # a value starting with "-" once reached argparse as an option and the child exited with code 2
    q0 = [-0.3, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
    standin = StandInProcess(ur_address, time_scale=4.0, model="ur10", q0=q0).start()
    try:
        assert max(abs(a - b) for a, b in zip(standin.get_joint_positions(), q0)) < 1e-9
    finally:
        standin.close()
