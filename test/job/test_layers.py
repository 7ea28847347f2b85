"""Split of a job's time by layer, from recordings shaped like what the stack publishes."""
from locem_bridge.job.layers import LAYERS, JobRecording, analyse, locem_commands, process_windows

TAPING = ("taping", "urn:p#Taping")
SPRAYING = ("spraying", "urn:p#Spraying")


def st(process, phase, action="", task=""):
    return {"process": process, "phase": phase, "action_type": action, "task": task}


def samples(t0, t1, moving, period=0.02):
    n = int(round((t1 - t0) / period))
    return [(t0 + i * period, moving(t0 + i * period)) for i in range(n + 1)]


def taping_recording(end_phase="ended", pemkre_calls=()):
    """One taping process 10..30: PEMKRE phases, one TAPE_LINE whose LOCEM command runs 13..23 with the arm
    moving 15..21, an operator prompt 24..26 inside the running tree, HICEM's STATUS polls all along."""
    p = TAPING[1]
    states = [(5.0, st("", "idle")), (10.0, st(p, "starting")), (11.0, st(p, "asking")),
              (12.0, st(p, "starting", "TAPE_LINE", "t1")), (12.5, st(p, "running", "TAPE_LINE", "t1")),
              (27.0, st(p, "reporting", "TAPE_LINE", "t1")), (28.0, st(p, "asking"))]
    if end_phase:
        states.append((30.0, st(p, end_phase)))
    locem = [(13.0, 1, "MOVE_L", "action", "running"), (20.0, 1, "MOVE_L", "action", "running"),
             (23.0, 1, "MOVE_L", "action", "succeeded")]
    for k in range(40):  # heartbeat polls through the service: not the job's commands
        t = 8.0 + 0.5 * k
        locem += [(t, 100 + k, "STATUS", "service", "running"), (t + 0.01, 100 + k, "STATUS", "service",
                                                                 "succeeded")]
    locem.append((15.0, 0, "HEALTH", "health", "health"))
    return JobRecording(steps=[TAPING, SPRAYING], start=0.0, end=40.0, hicem_states=states,
                        prompts=[(24.0, "q1", "opened"), (26.0, "q1", "answered")], locem_events=locem,
                        arm_samples=samples(8.0, 32.0, lambda t: 15.0 < t <= 21.0),
                        base_samples=samples(8.0, 32.0, lambda t: False, 0.05),
                        pemkre_calls=list(pemkre_calls), sample_gap=0.1)


def test_each_second_of_a_process_goes_to_exactly_one_layer():
    out = analyse(taping_recording())
    (proc,) = out["processes"]
    assert (proc["name"], proc["status"], proc["wall_s"]) == ("taping", "ended", 20.0)
    layers = proc["layers"]
    assert set(layers) == set(LAYERS)
    assert abs(sum(layers.values()) - 20.0) < 1e-9
    assert abs(layers["device"] - 6.0) < 1e-6               # arm moving 15..21
    assert abs(layers["locem_handling"] - 4.0) < 1e-6       # command 13..23 minus the motion
    # without the call log PEMKRE is HICEM's starting/asking/reporting phases: 10..12.5 and 27..30
    assert out["pemkre_source"] == "hicem_phases"
    assert abs(layers["pemkre"] - 5.5) < 1e-6
    assert abs(layers["operator"] - 2.0) < 1e-6
    assert abs(layers["hicem"] - 2.5) < 1e-6                # 12.5..13, 23..24, 26..27: ticking and gaps
    assert out["startup_s"] == 10.0 and out["teardown_s"] == 10.0 and out["job_s"] == 20.0


def test_the_call_log_replaces_the_phase_estimate_and_the_rest_is_hicem():
    calls = [{"call": "start_process", "t0": 10.1, "t1": 10.6, "ok": True},
             {"call": "next_action", "t0": 11.2, "t1": 11.9, "ok": True},
             {"call": "set_task_status", "t0": 12.1, "t1": 12.3, "ok": True},
             {"call": "set_task_status", "t0": 27.2, "t1": 27.6, "ok": False},
             {"call": "next_action", "t0": 28.1, "t1": 29.9, "ok": True}]
    out = analyse(taping_recording(pemkre_calls=calls))
    layers = out["processes"][0]["layers"]
    assert out["pemkre_source"] == "call_log"
    assert abs(layers["pemkre"] - 3.6) < 1e-6
    assert abs(layers["hicem"] - (20.0 - 6.0 - 4.0 - 3.6 - 2.0)) < 1e-6
    table = out["pemkre_call_table"]
    assert table["next_action"]["count"] == 2 and abs(table["next_action"]["max_s"] - 1.8) < 1e-9
    assert table["set_task_status"]["failed"] == 1


def test_heartbeat_polls_and_health_events_are_not_job_commands():
    commands = locem_commands(taping_recording())
    assert [(c["name"], c["start"], c["end"], c["final"]) for c in commands.values()] == [
        ("MOVE_L", 13.0, 23.0, "succeeded")]
    table = analyse(taping_recording())["commands"]
    assert set(table) == {"MOVE_L"} and abs(table["MOVE_L"]["device_s"] - 6.0) < 1e-6


def test_a_job_that_stopped_midway_is_split_up_to_where_it_got():
    rec = taping_recording(end_phase=None)       # taping never ended; spraying never started
    (proc,) = process_windows(rec)
    assert proc["status"] == "unfinished" and proc["end"] == 40.0
    out = analyse(rec)
    assert [p["name"] for p in out["processes"]] == ["taping"]
    assert abs(sum(out["processes"][0]["layers"].values()) - 30.0) < 1e-9
    failed = analyse(taping_recording(end_phase="failed"))
    assert failed["processes"][0]["status"] == "failed"


def test_a_latched_end_state_of_an_earlier_run_does_not_open_a_process():
    rec = taping_recording()
    rec.hicem_states.insert(0, (1.0, st(TAPING[1], "ended")))
    assert process_windows(rec)[0]["start"] == 10.0


def test_nothing_ran():
    out = analyse(JobRecording(steps=[TAPING], start=0.0, end=12.0))
    assert out["processes"] == [] and out["startup_s"] == 12.0 and out["job_s"] == 0.0
    assert all(v == 0.0 for v in out["layers"].values())


def test_actions_are_counted_per_task_with_their_device_time():
    actions = analyse(taping_recording())["actions"]
    assert set(actions) == {"TAPE_LINE"}
    assert actions["TAPE_LINE"]["count"] == 1
    assert abs(actions["TAPE_LINE"]["wall_s"] - 16.0) < 1e-6    # 12..28
    assert abs(actions["TAPE_LINE"]["device_s"] - 6.0) < 1e-6


def test_actions_name_the_skills_pemkre_matched_their_tasks_to():
    rec = taping_recording()
    p = TAPING[1]
    rec.hicem_states[3:6] = [(t, dict(s, skill="TAPE_LINE")) for t, s in rec.hicem_states[3:6]]
    rec.hicem_states.insert(6, (27.5, dict(st(p, "running", "CHANGE_TOOL", "t2"), skill="CHANGE_TOOL")))
    actions = analyse(rec)["actions"]
    assert actions["TAPE_LINE"]["skills"] == ["TAPE_LINE"] and actions["CHANGE_TOOL"]["skills"] == ["CHANGE_TOOL"]
    assert analyse(taping_recording())["actions"]["TAPE_LINE"]["skills"] == []     # no matching: none named
