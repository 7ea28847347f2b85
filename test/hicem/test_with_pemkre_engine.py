"""HICEM with the real PEMKRE process engine (in process, shipped ontologies) and the LOCEM test double: the
taping process of the paper runs end to end, the operator's 'invalid' sends a line to manual taping, and
PEMKRE's world state ends with every joint processed or manual."""
import pytest

pemkre = pytest.importorskip("locem_bridge.pemkre")

from hicem_doubles import AutoOperator, Heartbeats, LocemDouble, SITE  # noqa: E402
from hicem_rig import params  # noqa: E402
from locem_bridge.hicem.executive import create_executive  # noqa: E402
from locem_bridge.hicem.pemkre_local import EngineClient  # noqa: E402


@pytest.fixture
def engine(tmp_path):
    store = pemkre.OxigraphStore(str(tmp_path / "pemkre_db"))
    yield pemkre.ProcessEngine(store)
    store.close()


def run(tmp_path, engine, options, reject=()):
    locem = LocemDouble()
    ex = create_executive(EngineClient(engine), locem, str(tmp_path / "hdict.sqlite"), params=params())
    op = AutoOperator(ex.controller, {"mount_tool": "done", "validate_line": "valid", "manual_taping": "done"},
                      reject=list(reject))
    ex.operator.add_listener(op)
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    try:
        phase = ex.controller.run_process(str(pemkre.PLB.TapingProcess), options)
        return phase, locem, ex.controller.state(), op
    finally:
        beats.stop()
        ex.close()


def test_taping_process_with_validation_and_one_rejected_line(tmp_path, engine):
    phase, locem, state, op = run(tmp_path, engine, {"validateLines": True}, reject=["wall_1_joint_2"])
    assert phase == "ended", state
    tapes = [c for c in locem.sent if c.startswith("APPLY_TAPE ")]
    # every joint but the rejected one, the 2 m horizontal one in two pieces (1.2 m at most from one pose)
    assert len(tapes) == len(SITE["joints"]) and not any(c.startswith("APPLY_TAPE 2.4") for c in tapes)
    assert op.asked.count("validate_line") == len(SITE["joints"]) and op.asked.count("manual_taping") == 1
    assert locem.sent[0] == "SCAN" and locem.sent[-2].startswith("GOTO") and locem.sent[-1] == "HOME"
    assert locem.running() == []


def test_taping_process_without_validation(tmp_path, engine):
    phase, locem, state, op = run(tmp_path, engine, {"validateLines": False})
    assert phase == "ended", state
    assert "validate_line" not in op.asked
    # one piece per joint, two for the 2 m horizontal one (1.2 m at most from one pose)
    assert len([c for c in locem.sent if c.startswith("APPLY_TAPE ")]) == len(SITE["joints"]) + 1
