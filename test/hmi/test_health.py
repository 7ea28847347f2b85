"""The operator page's health line, one reading of the shared levels: from HICEM's real health monitor (an
executive in the same process) and from /diagnostics entries plus HICEM's liveness (the ROS adapter)."""
from locem_bridge.common.health import ERROR, OK, STALE, WARN
from locem_bridge.hicem.health import HealthMonitor, ModuleSpec
from locem_bridge.hmi import DiagnosticsHealth, health_summary


class Clock:
    t = 0.0

    def __call__(self):
        return self.t


def test_health_from_the_real_health_monitor():
    clock = Clock()
    hem = HealthMonitor([ModuleSpec("locem", crucial=True, heartbeat_timeout_s=1.0), ModuleSpec("pemkre")],
                        clock=clock)
    assert health_summary({})["status"] == "unknown"
    hem.heartbeat("locem")
    ok = health_summary(hem.snapshot())
    assert ok["status"] == "ok" and "locem" in ok["detail"] and "pemkre" in ok["detail"]
    hem.report("pemkre", "WARN", "slow SPARQL")
    degraded = health_summary(hem.snapshot())
    assert degraded == {"status": "degraded", "detail": "pemkre reports WARN: slow SPARQL"}
    clock.t = 5.0                                                  # locem silent past its heartbeat timeout
    fault = health_summary(hem.snapshot())
    assert fault["status"] == "fault" and "locem silent" in fault["detail"] and "pemkre" not in fault["detail"]



def test_health_from_diagnostics_and_hicem_liveness():
    clock = Clock()
    board = DiagnosticsHealth(fresh_s=10.0, clock=clock)
    assert board.summary("/hicem", False, None) == {"status": "fault",
                                                     "detail": "HICEM is not running (no /hicem/stop service)"}
    assert board.summary("/hicem", True, None) == {"status": "unknown", "detail": "no /hicem/state received yet"}
    running = {"phase": "running"}
    assert board.summary("/hicem", True, running) == {"status": "ok", "detail": "HICEM up"}
    board.note("locem: arm", OK, "link up, device ok")
    assert board.summary("/hicem", True, running) == {"status": "ok", "detail": "HICEM up, 1 diagnostics OK"}
    board.note("locem: compressor", WARN, "link up, device unknown")
    board.note("pemkre", STALE, "no answer")
    assert board.summary("/hicem", True, running) == {
        "status": "degraded", "detail": "locem: compressor WARN: link up, device unknown; pemkre STALE: no answer"}
    board.note("locem: arm", bytes([ERROR]), "link up, device safety stop: protective stop")   # as rospy gives it
    assert board.summary("/hicem", True, running) == {
        "status": "fault", "detail": "locem: arm ERROR: link up, device safety stop: protective stop"}
    waiting = {"phase": "waiting_for_health", "detail": "locem silent for 1.20 s"}
    assert board.summary("/hicem", True, waiting) == {"status": "fault", "detail": "locem silent for 1.20 s"}
    clock.t = 10.5                                                 # every entry older than fresh_s
    assert board.summary("/hicem", True, running)["status"] == "ok"


def test_a_diagnostics_level_outside_ok_to_stale_counts_as_a_fault():
    board = DiagnosticsHealth(clock=Clock())
    board.note("odd", 7, "level seven")
    assert board.summary("hicem", True, {"phase": "idle"}) == {"status": "fault", "detail": "odd ERROR: level seven"}
