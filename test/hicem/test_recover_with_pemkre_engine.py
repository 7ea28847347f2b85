"""HICEM with the real PEMKRE engine (shipped ontologies and trees) and the LOCEM test double: a SPRAY_AREA
command fails in the middle of an area (the compressor link dropped), PEMKRE's failure transition sends HICEM to
RECOVER (arm back, STATUS until the compressor is up again), the loop sprays the same area again, and the
spraying process ends with every area sprayed; the failure stays in the execution log and the KPIs."""
import copy

import pytest
from rdflib import URIRef

pemkre = pytest.importorskip("locem_bridge.pemkre")

from hicem_doubles import SITE, AutoOperator, Heartbeats, LocemDouble  # noqa: E402
from hicem_rig import params  # noqa: E402
from locem_bridge.hicem.executive import create_executive  # noqa: E402
from locem_bridge.hicem.interfaces import LocemReply  # noqa: E402
from locem_bridge.hicem.pemkre_local import EngineClient  # noqa: E402
from locem_bridge.pemkre import PLB, PPR, compute_kpis  # noqa: E402
from locem_bridge.pemkre.vocab import SITE as SITE_NS  # noqa: E402

LINK_DOWN = "compressor link is down (no answer for 0.61 s): connection closed"


def _two_area_site():
    site = copy.deepcopy(SITE)
    site["areas"] = [{"id": "wall_1_area_%d" % i, "wall": "wall_1", "origin": [2.4 * (i - 1), 3.0, 0.0],
                      "u": [1.0, 0.0, 0.0], "width": 2.4, "height": 2.5} for i in (1, 2)]
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


def _run(tmp_path, engine, locem):
    ex = create_executive(EngineClient(engine), locem, str(tmp_path / "hdict.sqlite"), params=params())
    ex.operator.add_listener(AutoOperator(ex.controller, {"mount_tool": "done"}))
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    try:
        phase = ex.controller.run_process(str(PLB.SprayingProcess), {})
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
    assert after[:6] == ["WALL_READY", "STATUS", "WAIT 1", "STATUS", "WAIT 1", "STATUS"]
    assert locem.running() == []
    k = compute_kpis(engine, sp)
    by_type = {r["actionType"]: r for r in k["task_types"]}
    assert by_type["SPRAY_AREA"]["failed"] == 1 and by_type["SPRAY_AREA"]["succeeded"] == 2
    assert k["processes"][0]["status"] == "ended" and k["processes"][0]["outcome"] == "completed"


def test_a_compressor_that_never_comes_back_fails_the_process_after_recover(tmp_path, engine):
    locem = LinkDropLocem(fail_at=1, down_polls=10 ** 6, site=_two_area_site())
    phase, state, marks = _run(tmp_path, engine, locem)
    assert phase == "failed"
    assert "RECOVER" in state["detail"] and "compressor: link down" in state["detail"]
    attempts = params().raw["recover"]["attempts"]
    assert locem.sent.count("STATUS") == attempts
    assert engine.store.value(SITE_NS.wall_1_area_1, PPR.sprayingStatus) == PPR.unprocessed
    assert marks["wall_1_area_1"] != "sprayed"
    assert locem.running() == []
