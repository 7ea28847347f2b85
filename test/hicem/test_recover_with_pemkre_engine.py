"""HICEM with the real PEMKRE engine (shipped ontologies and trees) and the LOCEM test double: a SPRAY_AREA
command fails in the middle of an area (the compressor link dropped), PEMKRE's failure transition sends HICEM to
RECOVER (STATUS until the compressor is up again, arm back), the loop sprays the same area again, and the
spraying process ends with every area sprayed; the failure stays in the execution log and the KPIs. A SAND_AREA
ends in a protective stop: RECOVER asks the operator, whose reset is sent as RESET_ARM, and the area is sanded
on from its failed section; an operator who cannot clear the stop fails the process with that answer."""
import copy
import time

import pytest
from rdflib import URIRef

pemkre = pytest.importorskip("locem_bridge.pemkre")

from hicem_doubles import SITE, AutoOperator, Heartbeats, LocemDouble  # noqa: E402
from hicem_rig import params  # noqa: E402
from locem_bridge.hicem.executive import create_executive  # noqa: E402
from locem_bridge.hicem.errors import LocemCallError  # noqa: E402
from locem_bridge.hicem.interfaces import LocemReply  # noqa: E402
from locem_bridge.hicem.pemkre_local import EngineClient  # noqa: E402
from locem_bridge.pemkre import PLB, PPR, compute_kpis  # noqa: E402
from locem_bridge.pemkre.vocab import SITE as SITE_NS  # noqa: E402

LINK_DOWN = "compressor link is down (no answer for 0.61 s): connection closed"


def _two_area_site():
    """Two 2.4 m areas side by side, inside what the spray gun reaches (wall_2 0.6 m further away than in the
    doubles' site, the areas 0.1..2.0 m high): the plan leaves nothing manual, LOCEM's refusals decide."""
    site = copy.deepcopy(SITE)
    site["walls"][0]["p1"] = [5.4, 3.0]
    site["walls"][1].update(p0=[5.4, 3.0], p1=[5.4, 0.0])
    site["joints"][2].update(start=[5.4, 2.5, 1.2], end=[5.4, 0.5, 1.2])
    site["areas"] = [{"id": "wall_1_area_%d" % i, "wall": "wall_1", "origin": [2.4 * (i - 1), 3.0, 0.1],
                      "u": [1.0, 0.0, 0.0], "width": 2.4, "height": 1.9} for i in (1, 2)]
    return site


class LinkDropLocem(LocemDouble):
    """The double, with the compressor link dropping during the n-th SPRAY_AREA command (it fails as LOCEM's
    spraying does on a lost link) and STATUS reporting the compressor down ``down_polls`` times afterwards."""

    def __init__(self, fail_at: int, down_polls: int, **kw) -> None:
        super().__init__(**kw)
        self.fail_at, self.down_polls, self.sprays = fail_at, down_polls, 0

    def send(self, command: str):
        if command.startswith("SPRAY_AREA "):
            self.sprays += 1
            if self.sprays == self.fail_at:
                self.fail_next["SPRAY_AREA"] = LocemReply(False, "HARDWARE_ERROR", LINK_DOWN)
                down = {k: dict(v) for k, v in self.health.items()}
                down["compressor"] = {"link": "down", "device": "unknown", "last_error": LINK_DOWN}
                self.health_script = [down] * self.down_polls
        return super().send(command)


@pytest.fixture
def engine(tmp_path):
    store = pemkre.OxigraphStore(str(tmp_path / "pemkre_db"))
    yield pemkre.ProcessEngine(store)
    store.close()


# RECOVER reads STATUS every poll_s of wall time here: a short poll keeps the suite fast
FAST = {"recover__poll_s": 0.05}


def _run(tmp_path, engine, locem, process=PLB.SprayingProcess, answers=None, **overrides):
    ex = create_executive(EngineClient(engine), locem, str(tmp_path / "hdict.sqlite"),
                          params=params(**dict(FAST, **overrides)))
    operator = AutoOperator(ex.controller, dict({"mount_tool": "done"}, **(answers or {})))
    ex.operator.add_listener(operator)
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health, alive=getattr(locem, "alive", None))
    try:
        phase = ex.controller.run_process(str(process), {})
        _run.asked = operator.asked
        marks = {a["id"]: ex.data_handler.feature(a["id"]).get("status") for a in locem.site["areas"]}
        return phase, ex.controller.state(), marks
    finally:
        beats.stop()
        ex.close()


def test_a_spray_area_that_fails_once_is_recovered_and_every_area_ends_sprayed(tmp_path, engine):
    # 2 areas of 2.4 m: 4 sections each; the link drops on the 6th spray command (area 2, section 2)
    locem = LinkDropLocem(fail_at=6, down_polls=2, site=_two_area_site())
    phase, state, marks = _run(tmp_path, engine, locem)
    assert phase == "ended", state
    for a in ("wall_1_area_1", "wall_1_area_2"):
        assert engine.store.value(SITE_NS[a], PPR.sprayingStatus) == PPR.processed
        assert marks[a] == "sprayed"
    sp = engine.current_process()
    log = [(str(r["actionType"]), str(r["status"]), str(r.get("detail") or ""))
           for r in engine.query("task_log", {"process": URIRef(sp)}).rows]
    assert [x[:2] for x in log] == [("SCAN", "succeeded"), ("GET_TOOL", "succeeded"), ("SPRAY_AREA", "succeeded"),
                                    ("SPRAY_AREA", "failed"), ("RECOVER", "succeeded"), ("SPRAY_AREA", "succeeded"),
                                    ("GO_HOME", "succeeded")]
    assert LINK_DOWN in log[3][2] and log[4][2] == "recovered"       # the half-sprayed area is reported
    # LOCEM saw: area 1 (4 sections), area 2 up to the failure (2), RECOVER, area 2 again from the failed
    # section on (3): its finished first section is not sprayed a second time
    sprays = [c for c in locem.sent if c.startswith("SPRAY_AREA ")]
    assert len(sprays) == 4 + 2 + 3
    assert sprays[6] == sprays[5] and sprays[4] not in sprays[6:] and len(set(sprays[6:])) == 3
    i_fail = [i for i, c in enumerate(locem.sent) if c.startswith("SPRAY_AREA ")][5]
    after = locem.sent[i_fail + 1:]
    # RECOVER: STATUS while the compressor is down (2), up (links), up (ready), then the arm retracts
    assert after[:5] == ["STATUS", "STATUS", "STATUS", "STATUS", "WALL_READY"]
    assert locem.running() == []
    k = compute_kpis(engine, sp)
    by_type = {r["actionType"]: r for r in k["task_types"]}
    assert by_type["SPRAY_AREA"]["failed"] == 1 and by_type["SPRAY_AREA"]["succeeded"] == 2
    assert k["processes"][0]["status"] == "ended" and k["processes"][0]["outcome"] == "completed"


def test_a_compressor_that_never_comes_back_fails_the_process_after_recover(tmp_path, engine):
    locem = LinkDropLocem(fail_at=1, down_polls=10 ** 6, site=_two_area_site())
    phase, state, marks = _run(tmp_path, engine, locem, recover__links_timeout_s=0.5)
    assert phase == "failed"
    assert "RECOVER" in state["detail"] and "compressor: link down" in state["detail"]
    assert "after 0.5 s" in state["detail"]
    assert 5 <= locem.sent.count("STATUS") <= 12 and "WALL_READY" not in locem.sent[locem.sent.index("STATUS"):]
    assert engine.store.value(SITE_NS.wall_1_area_1, PPR.sprayingStatus) == PPR.unprocessed
    assert marks["wall_1_area_1"] != "sprayed"
    assert locem.running() == []


# ------------------------------------------------------------------------------- protective stop while sanding --
PROTECTIVE_STOP = ("arm protective stop (safety mode 3); the motion was stopped by the controller; remove the cause "
                   "and send RESET_ARM")


class ProtectiveStopLocem(LocemDouble):
    """The double with the arm hitting something during the n-th SAND_AREA: that command fails as LOCEM's sanding
    does on a protective stop, STATUS reports the latched stop and every motion is refused until RESET_ARM."""

    MOTIONS = ("WALL_READY", "GOTO", "SAND_AREA", "SPRAY_AREA", "MOVE_HOME")

    def __init__(self, stop_at: int, **kw) -> None:
        super().__init__(**kw)
        self.stop_at, self.sands = stop_at, 0

    def send(self, command: str):
        name = command.split()[0]
        latched = self.health["arm"]["device"] != "ok"
        if name == "RESET_ARM":
            self.health["arm"] = {"link": "up", "device": "ok", "last_error": ""}
        elif name in self.MOTIONS and latched:
            self.fail_next[name] = LocemReply(False, "HARDWARE_ERROR", "arm protective stop (safety mode 3) is "
                                              "latched; remove the cause and send RESET_ARM")
        elif name == "SAND_AREA":
            self.sands += 1
            if self.sands == self.stop_at:
                self.fail_next["SAND_AREA"] = LocemReply(False, "HARDWARE_ERROR", PROTECTIVE_STOP)
                self.health["arm"] = {"link": "up", "device": "safety stop: protective stop (safety mode 3)",
                                      "safety_mode": "PROTECTIVE_STOP", "last_error": "latched"}
        return super().send(command)


def _sprayed_site():
    site = _two_area_site()
    for a in site["areas"]:
        a["finish"] = "sprayed"
    return site


def _task_log(engine):
    sp = engine.current_process()
    return [(str(r["actionType"]), str(r["status"]), str(r.get("detail") or ""))
            for r in engine.query("task_log", {"process": URIRef(sp)}).rows]


def test_a_protective_stop_while_sanding_is_reset_by_the_operator_and_the_area_sanded_on(tmp_path, engine):
    # 2 areas of 4 sections; the arm stops on the 7th SAND_AREA (area 2, section 3)
    locem = ProtectiveStopLocem(stop_at=7, site=_sprayed_site())
    phase, state, marks = _run(tmp_path, engine, locem, PLB.SandingProcess, {"safety_stop": "reset"})
    assert phase == "ended", state
    for a in ("wall_1_area_1", "wall_1_area_2"):
        assert engine.store.value(SITE_NS[a], PPR.sandingStatus) == PPR.processed
        assert marks[a] == "sanded"
    log = _task_log(engine)
    assert [x[:2] for x in log] == [("SCAN", "succeeded"), ("GET_TOOL", "succeeded"), ("SAND_AREA", "succeeded"),
                                    ("SAND_AREA", "failed"), ("RECOVER", "succeeded"), ("SAND_AREA", "succeeded"),
                                    ("GO_HOME", "succeeded")]
    assert "protective stop" in log[3][2] and log[4][2] == "recovered"
    assert _run.asked.count("safety_stop") == 1
    # after the stop: STATUS (links up, the stop seen), the operator's reset, STATUS (ready), the arm retracts
    i_stop = [i for i, c in enumerate(locem.sent) if c.startswith("SAND_AREA ")][6]
    assert locem.sent[i_stop + 1:i_stop + 5] == ["STATUS", "RESET_ARM", "STATUS", "WALL_READY"]
    # area 2 goes on at its failed (3rd) section: sections 1 and 2 are not sanded twice
    sands = [c for c in locem.sent if c.startswith("SAND_AREA ")]
    assert len(sands) == 4 + 3 + 2 and sands[7] == sands[6] and sands[8] not in sands[4:7]
    assert not set(sands[7:]) & set(sands[4:6])
    assert locem.running() == []


def test_a_protective_stop_the_operator_cannot_clear_fails_the_process_with_that_answer(tmp_path, engine):
    locem = ProtectiveStopLocem(stop_at=2, site=_sprayed_site())
    phase, state, marks = _run(tmp_path, engine, locem, PLB.SandingProcess, {"safety_stop": "cannot_clear"})
    assert phase == "failed"
    assert "RECOVER" in state["detail"] and "operator answered cannot_clear" in state["detail"], state
    log = _task_log(engine)
    steps = [x[:2] for x in log]         # (the query repeats the failing task's row with the process's detail)
    assert steps[:4] == [("SCAN", "succeeded"), ("GET_TOOL", "succeeded"), ("SAND_AREA", "failed"),
                         ("RECOVER", "failed")] and set(steps[4:]) <= {("RECOVER", "failed")}, log
    assert "operator answered cannot_clear to: protective stop (safety mode 3): check the arm" in log[3][2]
    assert "RESET_ARM" not in locem.sent
    assert locem.sent[-1] == "STATUS" or locem.sent[-1] == "STOP"      # nothing moved after the stop
    assert engine.store.value(SITE_NS.wall_1_area_1, PPR.sandingStatus) != PPR.processed
    assert locem.running() == []


# --------------------------------------------------------------------------------- unreachable: manual work --
class UnreachableLocem(LocemDouble):
    """The double refusing the n-th SPRAY_AREA as the arm bridge refuses a pose its IK cannot reach."""

    def __init__(self, refuse_at: int, **kw) -> None:
        super().__init__(**kw)
        self.refuse_at, self.sprays = refuse_at, 0

    def send(self, command: str):
        if command.startswith("SPRAY_AREA "):
            self.sprays += 1
            if self.sprays == self.refuse_at:
                self.fail_next["SPRAY_AREA"] = LocemReply(False, "INVALID_ARGUMENT", "pose [0.9, -1.1, 2.4, 0, 3.14, "
                                                          "0] is not reachable by the arm: no IK solution")
        return super().send(command)


def test_a_section_out_of_reach_is_manual_work_and_the_process_succeeds(tmp_path, engine):
    locem = UnreachableLocem(refuse_at=6, site=_two_area_site())       # area 2, section 2
    phase, state, marks = _run(tmp_path, engine, locem)
    assert phase == "ended", state
    log = _task_log(engine)
    assert [x[:2] for x in log] == [("SCAN", "succeeded"), ("GET_TOOL", "succeeded"), ("SPRAY_AREA", "succeeded"),
                                    ("SPRAY_AREA", "succeeded"), ("GO_HOME", "succeeded")]
    assert log[2][2] == "sprayed"
    assert log[3][2] == ("sprayed; manual work on wall_1_area_2: section 2 (along 0.6..1.2 m, height 0.1..2 m)")
    assert len([c for c in locem.sent if c.startswith("SPRAY_AREA ")]) == 8 and "RECOVER" not in locem.sent
    for a in ("wall_1_area_1", "wall_1_area_2"):
        assert engine.store.value(SITE_NS[a], PPR.sprayingStatus) == PPR.processed


class RespawningLocem(LocemDouble):
    """The double as HICEM sees LOCEM killed during the n-th SPRAY_AREA: the goal ends ABORTED ("went away",
    HICEM's client), then for ``dead_s`` no heartbeat reaches the HEM and every send finds no action server, then
    the respawned LOCEM answers again."""

    def __init__(self, kill_at: int, dead_s: float, **kw) -> None:
        super().__init__(**kw)
        self.kill_at, self.dead_s, self.sprays, self.dead_until = kill_at, dead_s, 0, 0.0

    def alive(self) -> bool:
        return time.monotonic() >= self.dead_until

    def send(self, command: str):
        if not self.alive():
            self.sent.append("(away) " + command)
            raise LocemCallError("LOCEM action server /locem/command_action is not available", "NOT_READY")
        if command.startswith("SPRAY_AREA "):
            self.sprays += 1
            if self.sprays == self.kill_at:
                self.fail_next["SPRAY_AREA"] = LocemReply(False, "ABORTED", "LOCEM went away while running it")
                self.dead_until = time.monotonic() + self.dead_s
        return super().send(command)


def test_recover_rides_through_the_health_fault_of_a_locem_that_respawns(tmp_path, engine):
    """LOCEM killed mid-area: the SPRAY_AREA fails at once (its goal aborted), RECOVER starts while LOCEM is still
    away and the HEM's crucial 'locem' heartbeat times out (1 s) during it; RECOVER is in health.ride_through, so
    the fault does not halt it: it waits for LOCEM and its links, and the area is sprayed on."""
    locem = RespawningLocem(kill_at=6, dead_s=2.5, site=_two_area_site())
    phase, state, marks = _run(tmp_path, engine, locem)
    assert phase == "ended", state
    assert all(m == "sprayed" for m in marks.values()), marks
    log = [(str(r["actionType"]), str(r["status"]), str(r.get("detail") or ""))
           for r in engine.query("task_log", {"process": URIRef(engine.current_process())}).rows]
    assert [x[:2] for x in log] == [("SCAN", "succeeded"), ("GET_TOOL", "succeeded"), ("SPRAY_AREA", "succeeded"),
                                    ("SPRAY_AREA", "failed"), ("RECOVER", "succeeded"), ("SPRAY_AREA", "succeeded"),
                                    ("GO_HOME", "succeeded")], log
    assert any(c.startswith("(away) STATUS") for c in locem.sent)       # RECOVER ran while LOCEM was away
    assert len([c for c in locem.sent if c.startswith("SPRAY_AREA ")]) == 4 + 2 + 3


def test_without_ride_through_the_same_respawn_fails_recover_with_the_health_fault(tmp_path, engine):
    locem = RespawningLocem(kill_at=6, dead_s=2.5, site=_two_area_site())
    phase, state, _marks = _run(tmp_path, engine, locem, health__ride_through=[])
    assert phase == "failed", state
    log = [(str(r["actionType"]), str(r["status"]), str(r.get("detail") or ""))
           for r in engine.query("task_log", {"process": URIRef(engine.current_process())}).rows]
    assert ("RECOVER", "failed") in [x[:2] for x in log]
    assert any("health fault" in d and "locem silent" in d for a, st, d in log if a == "RECOVER"), log
