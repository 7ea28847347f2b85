"""HICEM with the real PEMKRE engine (real on-disk store) while PEMKRE is away: calls that find PEMKRE gone
(PemkreUnavailableError, what the ROS client raises after its own deadline) are repeated by the controller, the
process goes on instead of failing, and a report PEMKRE applied before the answer was lost is applied once
(the request id). The outage is played at the client interface around the real engine; the same over ROS with
kill -9 is test/ros/pemkre_crash.test and job_pemkre_kill.test."""
import pytest

pemkre = pytest.importorskip("locem_bridge.pemkre")

from hicem_doubles import SITE, AutoOperator, LocemDouble, run_with_heartbeats  # noqa: E402
from hicem_rig import params  # noqa: E402
from locem_bridge.hicem.executive import create_executive  # noqa: E402
from locem_bridge.hicem.interfaces import PemkreUnavailableError  # noqa: E402
from locem_bridge.hicem.pemkre_local import EngineClient  # noqa: E402


class FlakyPemkre(EngineClient):
    """The engine behind a link that drops: before the call (``before``: nothing reached PEMKRE) or after it
    (``after``: PEMKRE applied the call, its answer was lost), for the calls numbered in ``outages``."""

    def __init__(self, engine, outages):
        super().__init__(engine)
        self.outages = dict(outages)
        self.n = 0
        self.lost = []

    def _flaky(self, name, fn, *args):
        self.n += 1
        mode = self.outages.get(self.n)
        if mode == "before":
            self.lost.append((self.n, name, "before"))
            raise PemkreUnavailableError("PEMKRE %s failed: /pemkre did not answer within 10 s" % name)
        result = fn(*args)
        if mode == "after":
            self.lost.append((self.n, name, "after"))
            raise PemkreUnavailableError("PEMKRE %s failed: /pemkre did not answer within 10 s" % name)
        return result

    def start_process(self, process_iri, options=None):
        return self._flaky("start_process", super().start_process, process_iri, options)

    def next_action(self):
        return self._flaky("next_action", super().next_action)

    def set_task_status(self, task, status, detail=""):
        return self._flaky("set_task_status", super().set_task_status, task, status, detail)


@pytest.fixture
def engine(tmp_path):
    store = pemkre.JournaledStore(str(tmp_path / "pemkre_db"))
    yield pemkre.ProcessEngine(store)
    store.close()


def test_the_process_goes_on_across_pemkre_outages_and_reports_apply_once(tmp_path, engine):
    # every kind of call lost both ways, early and in the middle of the taping
    outages = {1: "before", 3: "after", 4: "before", 6: "after", 9: "after", 10: "before", 14: "after",
               15: "after", 20: "before", 21: "after"}
    client = FlakyPemkre(engine, outages)
    locem = LocemDouble()
    ex = create_executive(client, locem, str(tmp_path / "hdict.sqlite"), params=params())
    ex.controller.pemkre_wait_s = 30.0
    phases = []
    ex.controller.add_state_listener(lambda s: phases.append(s["phase"]))
    op = AutoOperator(ex.controller, {"mount_tool": "done", "validate_line": "valid", "manual_taping": "done"})
    ex.operator.add_listener(op)
    phase = run_with_heartbeats(ex, str(pemkre.PLB.TapingProcess), {"validateLines": True})
    assert phase == "ended", ex.controller.state()
    assert len(client.lost) == len(outages)
    assert "waiting_for_pemkre" in phases
    # one specific process (a lost start answered the same process again), every task once, all succeeded
    log = engine.query("task_log").rows
    assert len({str(r["process"]) for r in log}) == 1
    assert [str(r["status"]) for r in log] == ["succeeded"] * len(log)
    tapes = [r for r in log if str(r["actionType"]) == "TAPE_LINE"]
    assert len(tapes) == len(SITE["joints"])
    # one piece per joint, two for the 2 m horizontal one (1.2 m at most from one pose)
    assert len([c for c in locem.sent if c.startswith("APPLY_TAPE ")]) == len(SITE["joints"]) + 1
    assert engine.check_consistency(full_inference=True) == []


def test_pemkre_away_past_the_wait_fails_the_process_naming_it(tmp_path, engine):
    client = FlakyPemkre(engine, {n: "before" for n in range(2, 400)})
    ex = create_executive(client, LocemDouble(), str(tmp_path / "hdict.sqlite"), params=params())
    ex.controller.pemkre_wait_s = 0.5
    phase = run_with_heartbeats(ex, str(pemkre.PLB.TapingProcess), {"validateLines": True})
    assert phase == "failed"
    detail = ex.controller.state()["detail"]
    assert "PEMKRE next_action" in detail and "did not answer within" in detail, detail
