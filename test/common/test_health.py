"""One grading of a device's health: /diagnostics, HICEM's module ``locem/<device>``, HICEM's device checks and
the health monitor read the same levels, so a faulted arm with its link up is ERROR everywhere."""
import pytest

from locem_bridge.common.health import ERROR, LEVEL_NAMES, LEVELS, OK, STALE, WARN, grade, level_of, problems
from locem_bridge.hicem.errors import HealthError
from locem_bridge.hicem.health import HealthMonitor, ModuleSpec
from locem_bridge.hicem.nodes.generic import devices_not_ready

RECORDS = [  # (what, record, level, problems)
    ("ready arm", {"link": "up", "device": "ok", "last_error": ""}, OK, []),
    ("no device key", {"link": "up"}, OK, []),
    ("safety stop, link up", {"link": "up", "device": "safety stop: protective stop (safety mode 3)",
                              "last_error": "protective stop latched"}, ERROR,
     ["device safety stop: protective stop (safety mode 3)"]),
    ("faulted compressor, link up", {"link": "up", "device": "fault: overpressure"}, ERROR,
     ["device fault: overpressure"]),
    ("latched fault", {"link": "up", "device": "ok", "fault": "heartbeat lost"}, ERROR, ["fault heartbeat lost"]),
    ("link down", {"link": "down", "device": "closed"}, ERROR, ["link down", "device closed"]),
    ("LOCEM could not ask", {"link": "unknown", "last_error": "health query failed"}, ERROR, ["link unknown"]),
    ("state not known yet", {"link": "up", "device": "unknown"}, WARN, ["device unknown"]),
    ("program stopped", {"link": "up", "device": "robot mode 7, program stopped"}, WARN,
     ["device robot mode 7, program stopped"]),
]


@pytest.mark.parametrize("what, record, level, why", RECORDS, ids=[r[0] for r in RECORDS])
def test_one_grade_for_every_device_state(what, record, level, why):
    assert grade(record) == level
    assert problems(record) == why
    assert (grade(record) == OK) == (not problems(record))           # ready exactly when OK


@pytest.mark.parametrize("what, record, level, why", RECORDS, ids=[r[0] for r in RECORDS])
def test_hicem_sees_the_grade_of_diagnostics(what, record, level, why):
    """The HEM module ``locem/arm`` fed the graded record is faulty exactly when /diagnostics says ERROR, and the
    tree's device check (CheckDevicesUp, WaitForDevices check=ready) passes exactly when the grade is OK."""
    hem = HealthMonitor([ModuleSpec("locem/arm", crucial=True)])
    hem.report("locem/arm", grade(record), "from STATUS")
    assert hem.snapshot()["locem/arm"]["level"] == LEVEL_NAMES[level]
    assert bool(hem.faults()) == (level == ERROR)
    down = devices_not_ready({"health": {"arm": record}}, ["arm"])
    assert down == ([] if level == OK else ["arm: %s%s" % (", ".join(why), " (%s)" % record["last_error"]
                                                         if record.get("last_error") else "")])
    links = devices_not_ready({"health": {"arm": record}}, ["arm"], links_only=True)
    assert bool(links) == (record.get("link") != "up")


def test_levels_are_those_of_diagnostic_msgs_and_read_by_name_or_number():
    assert LEVELS == {"OK": 0, "WARN": 1, "ERROR": 2, "STALE": 3}
    assert [level_of(x) for x in ("ok", "Warn", "ERROR", "stale", 0, 3, b"\x02")] == [OK, WARN, ERROR, STALE, 0, 3,
                                                                                     ERROR]
    for bad in ("FATAL", 4, True, None, -1):
        with pytest.raises(ValueError, match="allowed: OK, WARN, ERROR, STALE or 0..3"):
            level_of(bad)
    with pytest.raises(HealthError, match="unknown health level 'FATAL'"):
        HealthMonitor().report("locem", "FATAL")
