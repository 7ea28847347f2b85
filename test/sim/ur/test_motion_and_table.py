"""Motion profiles, kinematics and the RTDE variable table, without sockets."""
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from locem_bridge.sim.ur import ArmKinematics
from locem_bridge.sim.ur.kinematics import pose_to_se3
from locem_bridge.sim.ur.motion import CartesianStop, JointMove, JointStop, LinearMove, Trapezoid
from locem_bridge.sim.ur.rtde_vars import INPUT_VARIABLES, OUTPUT_VARIABLES, InputRecipe, OutputRecipe

Q_HOME = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])


@pytest.fixture(scope="module")
def kin():
    return ArmKinematics("ur10e")


@settings(max_examples=200, deadline=None)
@given(d=st.floats(0.0, 10.0), v=st.floats(0.01, 5.0), a=st.floats(0.01, 20.0))
def test_trapezoid_respects_limits_and_arrives(d, v, a):
    p = Trapezoid(d, v, a)
    ts = np.linspace(0.0, p.duration, 400)
    pos = np.array([p.sample(t)[0] for t in ts])
    vel = np.array([p.sample(t)[1] for t in ts])
    assert p.sample(p.duration)[0] == pytest.approx(d, abs=1e-9)
    assert np.all(np.diff(pos) >= -1e-12)                 # monotone
    assert np.max(vel) <= v * (1 + 1e-9) + 1e-12
    if len(ts) > 1 and p.duration > 0:
        acc = np.abs(np.diff(vel) / np.diff(ts))
        assert np.max(acc) <= a * (1 + 1e-6) + 1e-9
    # time-optimal: nothing faster satisfies both limits
    lower_bound = max(d / v, 2 * np.sqrt(d / a)) if d > 0 else 0.0
    assert p.duration >= lower_bound - 1e-9
    assert p.duration <= d / v + v / a + 1e-9


def test_trapezoid_rejects_bad_limits():
    with pytest.raises(ValueError, match="speed and acceleration must be positive"):
        Trapezoid(1.0, 0.0, 1.0)


def test_joint_move_is_synchronised_and_ends_at_rest():
    q1 = Q_HOME + np.array([0.5, -0.2, 0.1, 0.0, 0.3, -1.0])
    m = JointMove(Q_HOME, q1, 1.0, 2.0)
    q, qd = Q_HOME.copy(), np.zeros(6)
    delta = q1 - Q_HOME
    moving = delta != 0
    for _ in range(5000):
        q, qd = m.step(0.002, q, qd)
        frac = (q - Q_HOME)[moving] / delta[moving]
        assert np.ptp(frac) < 1e-12
        assert q[3] == Q_HOME[3]
        if m.done:
            break
    assert m.done
    assert np.allclose(q, q1, atol=1e-12)
    assert np.allclose(qd, 0.0)
    assert m.profile.duration == pytest.approx(1.0 / 1.0 + 1.0 / 2.0)   # wrist_3 leads: 1 rad at 1 rad/s, 2 rad/s^2


def test_linear_move_stays_on_the_segment(kin):
    start = kin.fk_se3(Q_HOME)
    goal = pose_to_se3(list(start.translation + [0.1, 0.2, -0.15]) + [2.0, 2.3, 0.1])
    m = LinearMove(kin, Q_HOME, goal, 0.5, 2.0)
    q, qd = Q_HOME.copy(), np.zeros(6)
    a, b = start.translation, goal.translation
    worst = 0.0
    while not m.done:
        q, qd = m.step(0.01, q, qd)
        p = kin.fk_se3(q).translation
        t = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0, 1)
        worst = max(worst, float(np.linalg.norm(p - (a + t * (b - a)))))
    assert worst < 1e-6
    end = kin.fk_se3(q)
    assert np.allclose(end.translation, goal.translation, atol=1e-9)
    assert np.allclose(end.rotation, goal.rotation, atol=1e-9)


def test_stops_decelerate_to_rest(kin):
    m = JointStop(np.array([1.0, -0.5, 0, 0, 0, 0]), 2.0)
    q, qd = Q_HOME.copy(), np.array([1.0, -0.5, 0, 0, 0, 0])
    steps = 0
    while not m.done:
        q, qd = m.step(0.002, q, qd)
        steps += 1
    assert steps * 0.002 == pytest.approx(0.5, abs=0.004)   # 1 rad/s at 2 rad/s^2
    assert np.allclose(qd, 0.0)
    assert q[0] - Q_HOME[0] == pytest.approx(0.25, abs=1e-3)
    s = CartesianStop(kin, Q_HOME, np.array([0.0, 0.0, 0.1, 0, 0, 0]), 0.5)
    q = Q_HOME.copy()
    z0 = kin.fk_se3(q).translation[2]
    while not s.done:
        q, qd = s.step(0.002, q, qd)
    assert kin.fk_se3(q).translation[2] - z0 == pytest.approx(0.01, abs=1e-4)   # v^2 / 2a


def test_ik_finds_the_solution_nearest_qnear(kin):
    q = Q_HOME + np.array([0.3, 0.2, -0.4, 0.1, 0.2, 0.3])
    pose = kin.fk(q)
    assert np.allclose(kin.ik(pose, q + 0.05), q, atol=1e-8)
    kin2 = ArmKinematics("ur10")
    kin2.set_tcp([0.0, 0.0, 0.15, 0.0, 0.0, 0.0])
    assert kin2.fk(q)[2] != pytest.approx(pose[2])
    assert np.allclose(kin2.ik(kin2.fk(q), q), q, atol=1e-8)


def test_rtde_table_types_match_the_ur_guide():
    expect = {"timestamp": "DOUBLE", "actual_q": "VECTOR6D", "actual_TCP_pose": "VECTOR6D",
              "joint_mode": "VECTOR6INT32", "robot_mode": "INT32", "safety_mode": "INT32",
              "runtime_state": "UINT32", "robot_status_bits": "UINT32", "safety_status_bits": "UINT32",
              "actual_digital_output_bits": "UINT64", "actual_digital_input_bits": "UINT64",
              "actual_tool_accelerometer": "VECTOR3D", "payload_cog": "VECTOR3D", "elbow_position": "VECTOR3D",
              "output_int_register_47": "INT32", "output_double_register_0": "DOUBLE",
              "input_int_register_23": "INT32", "output_bit_register_64": "BOOL", "tool_output_mode": "UINT8"}
    for name, typ in expect.items():
        assert OUTPUT_VARIABLES[name] == typ, name
    assert INPUT_VARIABLES["standard_digital_output_mask"] == "UINT8"
    assert INPUT_VARIABLES["speed_slider_mask"] == "UINT32"
    assert INPUT_VARIABLES["external_force_torque"] == "VECTOR6D"
    assert "output_int_register_48" not in OUTPUT_VARIABLES
    assert "actual_q" not in INPUT_VARIABLES


def test_recipes_pack_and_decode_with_the_table_types():
    r = OutputRecipe(3, ["timestamp", "runtime_state", "joint_mode"], 250.0, 500.0)
    assert r.valid and r.decimation == 2
    data = bytes(r.pack({"timestamp": (1.5,), "runtime_state": (2,), "joint_mode": (253,) * 6}))
    assert struct.unpack(">HBBdI6i", data) == (len(data), 85, 3, 1.5, 2) + (253,) * 6
    bad = OutputRecipe(1, ["timestamp", "nope"], 125.0, 500.0)
    assert not bad.valid and bad.missing == ["nope"] and bad.types == ["DOUBLE", "NOT_FOUND"]
    i = InputRecipe(2, ["input_int_register_0", "standard_digital_output", "input_double_register_1"])
    assert i.valid and i.payload_size == 4 + 1 + 8
    assert i.decode(struct.pack(">iBd", 7, 5, 0.5)) == [("input_int_register_0", 7),
                                                         ("standard_digital_output", 5),
                                                         ("input_double_register_1", 0.5)]
    taken = InputRecipe(3, ["input_int_register_0", "input_int_register_1"], in_use={"input_int_register_1"})
    assert not taken.valid and taken.types == ["INT32", "IN_USE"]


@pytest.mark.parametrize("model, zero_pose", [
    # a2 + a3, d4 + d6, d1 - d5 of the published UR DH parameters
    ("ur10e", (-(0.6127 + 0.57155), -(0.17415 + 0.11655), 0.1807 - 0.11985)),
    ("ur5e", (-(0.425 + 0.3922), -(0.1333 + 0.0996), 0.1625 - 0.0997)),
    ("ur10", (-(0.612 + 0.5723), -(0.163941 + 0.0922), 0.1273 - 0.1157)),
])
def test_zero_configuration_matches_ur_dh_parameters(model, zero_pose):
    k = ArmKinematics(model)
    pose = k.fk([0.0] * 6)
    assert pose[:3] == pytest.approx(zero_pose, abs=1e-6)
    assert pose[3:] == pytest.approx([np.pi / 2, 0.0, 0.0], abs=1e-9)   # tool z along -y of the base
