"""The job tracker: progress lines from HICEM state, per-process records, operator interventions."""
from locem_bridge.job.tracker import JobStep, JobTracker

TAPING = JobStep("taping", "urn:p#Taping", {"validateLines": True})
SPRAYING = JobStep("spraying", "urn:p#Spraying")


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def tracker():
    lines, clock = [], Clock()
    return JobTracker([TAPING, SPRAYING], {"joints": 3, "areas": 2}, say=lines.append, clock=clock), lines, clock


def state(process, phase, action="", task="", detail=""):
    return {"process": process, "phase": phase, "action_type": action, "task": task, "detail": detail}


def test_progress_counts_joints_and_areas_once_per_task():
    t, lines, clock = tracker()
    t.begin(0)
    for s in [state("urn:p#Taping", "asking"), state("urn:p#Taping", "running", "SCAN", "t1"),
              state("urn:p#Taping", "running", "SCAN", "t1"),          # same task again: no new line
              state("urn:p#Taping", "running", "VALIDATE_TAPE_LINE", "t2"),
              state("urn:p#Taping", "running", "TAPE_LINE", "t3"),
              state("urn:p#Taping", "running", "VALIDATE_TAPE_LINE", "t4"),
              state("urn:p#Spraying", "running", "SPRAY_AREA", "x")]:  # another process: ignored
        t.on_state(s)
    assert lines == ["[1/2 taping] starting taping", "[1/2 taping] SCAN",
                     "[1/2 taping] VALIDATE_TAPE_LINE, joint 1 of 3", "[1/2 taping] TAPE_LINE, joint 1 of 3",
                     "[1/2 taping] VALIDATE_TAPE_LINE, joint 2 of 3"]
    assert t.finished is None
    # joint 2 rejected -> manual, joint 3 validated and taped: the taping of joint 3 is "joint 3", not the
    # second TAPE_LINE seen
    for s in [state("urn:p#Taping", "running", "MANUAL_TAPING", "t5"),
              state("urn:p#Taping", "running", "VALIDATE_TAPE_LINE", "t6"),
              state("urn:p#Taping", "running", "TAPE_LINE", "t7")]:
        t.on_state(s)
    assert lines[-3:] == ["[1/2 taping] MANUAL_TAPING, joint 2 of 3", "[1/2 taping] VALIDATE_TAPE_LINE, joint 3 of 3",
                          "[1/2 taping] TAPE_LINE, joint 3 of 3"]
    clock.t += 42.5
    t.on_state(state("urn:p#Taping", "ended", detail="completed"))
    assert t.finished["phase"] == "ended"
    record = t.end()
    assert (record.name, record.status, record.duration_s) == ("taping", "succeeded", 42.5)
    assert lines[-1] == "[1/2 taping] taping succeeded in 42.5 s"


def test_failed_process_keeps_its_reason_and_interventions_are_counted_by_kind():
    t, lines, _ = tracker()
    t.begin(1)
    t.on_prompt({"event": "opened", "kind": "mount_tool", "text": "Mount the spray_gun"})
    t.on_prompt({"event": "answered", "kind": "mount_tool", "answer": "done"})
    t.on_prompt({"event": "cancelled", "kind": "validate_line"})
    t.on_state(state("urn:p#Spraying", "running", "SPRAY_AREA", "a1"))
    t.on_state(state("urn:p#Spraying", "failed", "SPRAY_AREA", "a1", "compressor link lost"))
    record = t.end()
    assert (record.status, record.detail) == ("failed", "compressor link lost")
    assert t.interventions == {"mount_tool": 1} and t.total_interventions == 1
    assert "[2/2 spraying] operator: Mount the spray_gun" in lines
    assert "[2/2 spraying] SPRAY_AREA, area 1 of 2" in lines
    assert lines[-1].endswith("spraying failed in 0.0 s: compressor link lost")


def test_a_process_that_never_reported_is_recorded_with_the_given_status():
    t, _, _ = tracker()
    t.begin(0)
    record = t.end(status="timeout", detail="no end state within 600 s")
    assert (record.status, record.detail) == ("timeout", "no end state within 600 s")


def test_an_area_worked_again_after_recover_keeps_its_number():
    t, lines, clock = tracker()
    t.begin(1)
    for s in [state("urn:p#Spraying", "running", "SPRAY_AREA", "s1"),
              state("urn:p#Spraying", "running", "SPRAY_AREA", "s2"),
              state("urn:p#Spraying", "running", "RECOVER", "s3"),
              state("urn:p#Spraying", "running", "SPRAY_AREA", "s4")]:
        t.on_state(s)
    assert lines[-4:] == ["[2/2 spraying] SPRAY_AREA, area 1 of 2", "[2/2 spraying] SPRAY_AREA, area 2 of 2",
                          "[2/2 spraying] RECOVER", "[2/2 spraying] SPRAY_AREA, area 2 of 2"]


def test_area_sections_left_for_manual_work_are_collected_from_the_reported_detail():
    t, _lines, _clock = tracker()
    t.begin(1)
    detail = ("sprayed; manual work on wall_1_area_2: section 3 (along 1.2..1.8 m, height 0..2.5 m), section 4 "
              "(along 1.8..2 m, height 0..2.5 m)")
    for s in [state("urn:p#Spraying", "running", "SPRAY_AREA", "a1"),
              state("urn:p#Spraying", "reporting", "SPRAY_AREA", "a1", "sprayed"),
              state("urn:p#Spraying", "running", "SPRAY_AREA", "a2"),
              state("urn:p#Spraying", "reporting", "SPRAY_AREA", "a2", detail),
              state("urn:p#Spraying", "reporting", "SPRAY_AREA", "a2", detail),      # repeated: counted once
              state("urn:p#Spraying", "reporting", "GO_HOME", "h", detail)]:       # not an area task
        t.on_state(s)
    assert t.manual_areas == [
        {"work": "spray", "area": "wall_1_area_2", "section": 3, "along": [1.2, 1.8], "height": [0.0, 2.5]},
        {"work": "spray", "area": "wall_1_area_2", "section": 4, "along": [1.8, 2.0], "height": [0.0, 2.5]}]


def test_a_task_realized_by_another_skill_names_it_in_its_progress_line():
    t, lines, _clock = tracker()
    t.begin(0)
    for s in [dict(state("urn:p#Taping", "running", "GET_TOOL", "t1"), skill="CHANGE_TOOL"),
              dict(state("urn:p#Taping", "running", "TAPE_LINE", "t2"), skill="TAPE_LINE"),
              dict(state("urn:p#Taping", "running", "GO_HOME", "t3"), skill="")]:
        t.on_state(s)
    assert lines[1:] == ["[1/2 taping] GET_TOOL (skill CHANGE_TOOL)", "[1/2 taping] TAPE_LINE, joint 1 of 3",
                         "[1/2 taping] GO_HOME"]


def test_joint_parts_left_for_manual_work_are_collected_from_the_reported_taping_detail():
    from locem_bridge.hicem.nodes.area_work import manual_joint_text
    t, _lines, _clock = tracker()
    t.begin(0)
    detail = "taped; " + manual_joint_text("wall_1_joint_3", [
        {"along": [1.9, 2.4], "reason": "above the tool's reach"}, {"along": [0.0, 0.42], "reason": "near a corner"}])
    for s in [state("urn:p#Taping", "running", "TAPE_LINE", "t1"),
              state("urn:p#Taping", "reporting", "TAPE_LINE", "t1", "taped"),
              state("urn:p#Taping", "running", "TAPE_LINE", "t2"),
              state("urn:p#Taping", "reporting", "TAPE_LINE", "t2", detail),
              state("urn:p#Taping", "reporting", "TAPE_LINE", "t2", detail),              # repeated: counted once
              state("urn:p#Taping", "reporting", "VALIDATE_TAPE_LINE", "t3", detail.replace("3", "4"))]:  # not taping
        t.on_state(s)
    assert t.manual_joints == [
        {"joint": "wall_1_joint_3", "part": 1, "along": [0.0, 0.42], "reason": "near a corner"},
        {"joint": "wall_1_joint_3", "part": 2, "along": [1.9, 2.4], "reason": "above the tool's reach"}]
    assert t.manual_areas == []


def test_the_manual_plan_for_the_worksite_holds_the_area_and_joint_parts_so_far():
    t, _lines, _clock = tracker()
    assert t.manual_plan() == {"areas": [], "joints": []}
    t.begin(0)
    t.on_state(state("urn:p#Taping", "reporting", "TAPE_LINE", "t1",
                     "taped; manual work on wall_1_joint_1: part 1 (along 0..0.3 m; below the tool's reach)"))
    t.end()
    t.begin(1)
    t.on_state(state("urn:p#Spraying", "reporting", "SPRAY_AREA", "a1",
                     "sprayed; manual work on wall_1_area_1: section 3 (along 3.4..4 m, height 0..2.4 m)"))
    assert t.manual_plan() == {
        "areas": [{"work": "spray", "area": "wall_1_area_1", "along": [3.4, 4.0], "height": [0.0, 2.4]}],
        "joints": [{"joint": "wall_1_joint_1", "along": [0.0, 0.3]}]}
