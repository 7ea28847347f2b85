"""The one base kinematics module (common/base_kinematics.py): both models round-trip wheel speeds <-> body twist,
respect their wheel limits, and the name -> model table builds each from a robot file's wheel section."""
import math
import random

import pytest

from locem_bridge.common.base_kinematics import (KINEMATICS, WHEEL_KEYS, WHEEL_ORDER, DifferentialKinematics,
                                                 MecanumKinematics, kinematics_for)


@pytest.mark.parametrize("kin", [MecanumKinematics(0.1275, 0.236, 0.2605), DifferentialKinematics(0.10, 0.52)],
                         ids=["mecanum", "differential"])
def test_wheel_speeds_and_twist_round_trip(kin):
    rnd = random.Random(7)
    for _ in range(200):
        vx, wz = rnd.uniform(-0.5, 0.5), rnd.uniform(-0.8, 0.8)
        vy = rnd.uniform(-0.5, 0.5) if kin.holonomic else 0.0
        wheels = kin.wheel_speeds(vx, vy, wz)
        assert len(wheels) == len(WHEEL_ORDER[kin.kind]) == len(kin.wheel_positions())
        assert kin.twist(wheels) == pytest.approx((vx, vy, wz), abs=1e-12)
        back = kin.wheel_speeds(*kin.twist(wheels))
        assert back == pytest.approx(wheels, abs=1e-12)


def test_differential_wheels_are_the_rim_speeds_of_a_rigid_body_turning_about_the_axle_midpoint():
    kin = DifferentialKinematics(0.10, 0.52)
    left, right = kin.wheel_speeds(0.0, 0.0, 0.8)            # turn in place: opposite rims, 0.26 m x 0.8 rad/s
    assert left == pytest.approx(-0.26 * 0.8 / 0.10) and right == pytest.approx(0.26 * 0.8 / 0.10)
    assert kin.wheel_speeds(0.4, 0.0, 0.0) == pytest.approx([4.0, 4.0])
    assert kin.twist([3.0, 5.0]) == pytest.approx((0.4, 0.0, 0.1 * 2.0 / 0.52))
    assert not kin.holonomic and MecanumKinematics(0.1, 0.2, 0.2).holonomic
    # a sideways component cannot be produced: dropped, the rest kept
    assert kin.twist(kin.wheel_speeds(0.3, 0.2, 0.1)) == pytest.approx((0.3, 0.0, 0.1))


@pytest.mark.parametrize("kin", [MecanumKinematics(0.1275, 0.236, 0.2605), DifferentialKinematics(0.10, 0.52)],
                         ids=["mecanum", "differential"])
def test_scaling_to_the_wheel_limit_keeps_the_direction(kin):
    vx, vy, wz = 1.0, (0.5 if kin.holonomic else 0.0), 2.0
    sx, sy, sw = kin.scale_to_limit(vx, vy, wz, 5.0)
    assert max(abs(w) for w in kin.wheel_speeds(sx, sy, sw)) == pytest.approx(5.0)
    assert sw / sx == pytest.approx(wz / vx)


def test_the_table_builds_each_model_from_a_wheel_section_and_refuses_an_unknown_kind():
    assert set(KINEMATICS) == set(WHEEL_KEYS) == set(WHEEL_ORDER) == {"mecanum", "differential"}
    mec = kinematics_for("mecanum", {"radius": 0.1275, "width": 0.09, "half_wheelbase": 0.236, "half_track": 0.2605})
    assert isinstance(mec, MecanumKinematics) and mec.k == pytest.approx(0.4965)
    diff = kinematics_for("differential", {"radius": 0.1, "separation": 0.52})
    assert isinstance(diff, DifferentialKinematics) and diff.wheel_positions() == [(0.0, 0.26), (0.0, -0.26)]
    with pytest.raises(ValueError, match="unknown base kind 'ackermann', allowed: differential, mecanum"):
        kinematics_for("ackermann", {"radius": 0.1})
    with pytest.raises(ValueError, match="must be positive"):
        DifferentialKinematics(0.1, -0.5)
    assert math.isclose(diff.r, 0.1)
