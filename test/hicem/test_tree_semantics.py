"""BT.CPP 4 semantics of the control and decorator nodes, checked by ticking against scripted fake leaves."""
from py_trees.common import Status

from hicem_fakes import build, halts, ticks

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


def leaf(label, script):
    return '<Scripted id="%s" script="%s"/>' % (label, script)


def run(tree, n):
    return [tree.tick() for _ in range(n)]


def test_sequence_resumes_at_running_child_and_restarts_after_failure():
    t, ctx = build("<Sequence>%s%s%s</Sequence>" % (leaf("a", "S"), leaf("b", "R;S"), leaf("c", "F;S")))
    assert run(t, 2) == [R, F]
    assert ticks(ctx.events) == ["a", "b", "b", "c"]  # 'a' not re-ticked while b was running
    assert t.tick() == S  # restarts from the first child after the failure (scripts: a S, b S, c S now)
    assert ticks(ctx.events)[4:] == ["a", "b", "c"]


def test_sequence_with_memory_retries_the_failed_child_only():
    t, ctx = build("<SequenceWithMemory>%s%s</SequenceWithMemory>" % (leaf("a", "S"), leaf("b", "F;S")))
    assert run(t, 2) == [F, S]
    assert ticks(ctx.events) == ["a", "b", "b"]


def test_reactive_sequence_guard_failure_halts_running_action():
    t, ctx = build("<ReactiveSequence>%s%s</ReactiveSequence>" % (leaf("guard", "S;S;F"), leaf("act", "R")))
    assert run(t, 3) == [R, R, F]
    assert ticks(ctx.events) == ["guard", "act", "guard", "act", "guard"]
    assert halts(ctx.events) == ["act"]


def test_reactive_sequence_halts_a_previously_running_sibling():
    # first child RUNNING on tick 1, SUCCESS on tick 2 while the second becomes RUNNING: only one may run
    t, ctx = build("<ReactiveSequence>%s%s</ReactiveSequence>" % (leaf("a", "R;S"), leaf("b", "R")))
    assert run(t, 2) == [R, R]
    assert ticks(ctx.events) == ["a", "a", "b"]


def test_fallback_resumes_at_running_child():
    t, ctx = build("<Fallback>%s%s%s</Fallback>" % (leaf("a", "F"), leaf("b", "R;S"), leaf("c", "S")))
    assert run(t, 2) == [R, S]
    assert ticks(ctx.events) == ["a", "b", "b"]


def test_fallback_all_fail():
    t, ctx = build("<Fallback>%s%s</Fallback>" % (leaf("a", "F"), leaf("b", "F")))
    assert t.tick() == F
    assert ticks(ctx.events) == ["a", "b"]


def test_reactive_fallback_success_of_higher_priority_halts_running_child():
    t, ctx = build("<ReactiveFallback>%s%s</ReactiveFallback>" % (leaf("cond", "F;S"), leaf("act", "R")))
    assert run(t, 2) == [R, S]
    assert ticks(ctx.events) == ["cond", "act", "cond"]
    assert halts(ctx.events) == ["act"]


def test_parallel_success_count_halts_the_rest():
    t, ctx = build('<Parallel success_count="2" failure_count="1">%s%s%s</Parallel>' % (
        leaf("a", "S"), leaf("b", "R;S"), leaf("c", "R")))
    assert run(t, 2) == [R, S]
    assert ticks(ctx.events) == ["a", "b", "c", "b", "c"]  # a finished: not ticked again
    assert halts(ctx.events) == ["c"]


def test_parallel_default_needs_all_and_fails_on_first_failure():
    t, ctx = build("<Parallel>%s%s</Parallel>" % (leaf("a", "R;F"), leaf("b", "R")))
    assert run(t, 2) == [R, F]
    assert halts(ctx.events) == ["b"]


def test_parallel_failure_count_two_tolerates_one_failure():
    t, ctx = build('<Parallel success_count="1" failure_count="2">%s%s%s</Parallel>' % (
        leaf("a", "F"), leaf("b", "R;S"), leaf("c", "R")))
    assert run(t, 2) == [R, S]


def test_parallel_fails_when_success_becomes_impossible():
    t, ctx = build('<Parallel success_count="2" failure_count="3">%s%s%s</Parallel>' % (
        leaf("a", "F"), leaf("b", "F"), leaf("c", "R")))
    assert t.tick() == F
    assert halts(ctx.events) == ["c"]


def test_inverter_force_success_force_failure():
    for dec, script, expect in (("Inverter", "S", F), ("Inverter", "F", S), ("Inverter", "R", R),
                                ("ForceSuccess", "F", S), ("ForceSuccess", "R", R),
                                ("ForceFailure", "S", F), ("ForceFailure", "R", R)):
        t, _ = build("<%s>%s</%s>" % (dec, leaf("x", script), dec))
        assert t.tick() == expect, (dec, script)


def test_retry_until_successful_loops_within_the_tick():
    t, ctx = build('<RetryUntilSuccessful num_attempts="3">%s</RetryUntilSuccessful>' % leaf("x", "F;F;S"))
    assert t.tick() == S
    assert ticks(ctx.events) == ["x", "x", "x"]


def test_retry_until_successful_gives_up_after_num_attempts():
    t, ctx = build('<RetryUntilSuccessful num_attempts="2">%s</RetryUntilSuccessful>' % leaf("x", "F;F;S"))
    assert t.tick() == F
    assert ticks(ctx.events) == ["x", "x"]


def test_retry_forever_returns_running_between_attempts():
    t, ctx = build('<RetryUntilSuccessful num_attempts="-1">%s</RetryUntilSuccessful>' % leaf("x", "F;F;S"))
    assert run(t, 3) == [R, R, S]


def test_retry_keeps_count_across_running_ticks():
    t, ctx = build('<RetryUntilSuccessful num_attempts="2">%s</RetryUntilSuccessful>' % leaf("x", "R;F;R;F;S"))
    assert run(t, 3) == [R, R, F]


def test_repeat_runs_num_cycles_and_stops_on_failure():
    t, ctx = build('<Repeat num_cycles="3">%s</Repeat>' % leaf("x", "S"))
    assert t.tick() == S
    assert ticks(ctx.events) == ["x", "x", "x"]
    t, ctx = build('<Repeat num_cycles="3">%s</Repeat>' % leaf("x", "S;F"))
    assert t.tick() == F
    t, ctx = build('<Repeat num_cycles="2">%s</Repeat>' % leaf("x", "R;S;S"))
    assert run(t, 2) == [R, S]


def test_timeout_fails_and_halts_child_after_msec():
    now = [0.0]
    t, ctx = build('<Timeout msec="100">%s</Timeout>' % leaf("x", "R"), clock=lambda: now[0])
    assert t.tick() == R
    now[0] = 0.05
    assert t.tick() == R
    now[0] = 0.1
    assert t.tick() == F
    assert halts(ctx.events) == ["x"]
    assert "timed out after 100 ms" in ctx.last_failure()[1]


def test_timeout_passes_child_result_in_time():
    now = [0.0]
    t, _ = build('<Timeout msec="100">%s</Timeout>' % leaf("x", "R;S"), clock=lambda: now[0])
    assert run(t, 2) == [R, S]


def test_sleep_and_always_nodes():
    now = [0.0]
    t, _ = build('<Sequence><AlwaysSuccess/><Sleep msec="50"/></Sequence>', clock=lambda: now[0])
    assert t.tick() == R
    now[0] = 0.06
    assert t.tick() == S
    t, _ = build("<AlwaysFailure/>")
    assert t.tick() == F


def test_halting_the_tree_reaches_nested_running_leaf():
    t, ctx = build("<Sequence><Fallback>%s%s</Fallback></Sequence>" % (leaf("a", "F"), leaf("b", "R")))
    assert t.tick() == R
    t.halt()
    assert halts(ctx.events) == ["b"]
    assert t.root.status == Status.INVALID


SUB = ('<BehaviorTree ID="Sub"><Sequence>'
       '<SetBlackboard output_key="{out}" value="{inp}"/>'
       '<SetBlackboard output_key="_private" value="p"/>'
       '<SetBlackboard output_key="{shared}" value="from_sub"/></Sequence></BehaviorTree>')


def test_subtree_remaps_ports_and_isolates_other_keys():
    t, _ = build('<Sequence><SetBlackboard output_key="{src}" value="hello"/>'
                 '<SubTree ID="Sub" inp="{src}" out="{dst}" shared="{sh}"/></Sequence>', extra=SUB)
    assert t.tick() == S
    bb = t.blackboard
    assert bb.get("dst") == "hello" and bb.get("sh") == "from_sub"
    assert not bb.has("out") and not bb.has("_private")


def test_subtree_same_name_shorthand():
    t, _ = build('<Sequence><SetBlackboard output_key="{inp}" value="v"/>'
                 '<SubTree ID="Sub" inp="{=}" out="{=}"/></Sequence>', extra=SUB)
    assert t.tick() == S
    assert t.blackboard.get("out") == "v" and not t.blackboard.has("shared")


def test_subtree_port_remapped_to_a_field_of_a_parent_entry():
    extra = '<BehaviorTree ID="Sub3"><SetBlackboard output_key="{@got}" value="{pose}"/></BehaviorTree>'
    t, _ = build('<SubTree ID="Sub3" pose="{section.approach}"/>', extra=extra,
                 cfg={"section": {"approach": [1.0, 2.0, 0.5]}})
    assert t.tick() == S
    assert t.blackboard.get("got") == [1.0, 2.0, 0.5]


def test_subtree_literal_port_and_autoremap():
    t, _ = build('<Sequence><SubTree ID="Sub" _autoremap="true" inp="literal"/></Sequence>', extra=SUB)
    assert t.tick() == S
    bb = t.blackboard
    assert bb.get("out") == "literal" and bb.get("shared") == "from_sub"
    assert not bb.has("_private")  # underscore keys stay private even with autoremap
    assert not bb.has("inp")       # a literal port is the subtree's own entry


def test_subtree_without_remap_is_isolated():
    t, _ = build('<Sequence><SetBlackboard output_key="inp" value="x"/><SubTree ID="Sub"/></Sequence>', extra=SUB)
    assert t.tick() == F  # the subtree cannot see 'inp'
    assert "inp" in t.ctx.last_failure()[1]


def test_root_blackboard_access_with_at_prefix():
    extra = ('<BehaviorTree ID="Sub2"><SetBlackboard output_key="{@result}" value="{@cfg.value}"/>'
             '</BehaviorTree>')
    t, _ = build('<SubTree ID="Sub2"/>', extra=extra, cfg={"cfg.value": "42"})
    assert t.tick() == S
    assert t.blackboard.get("result") == "42"


def test_loop_list_writes_each_element_and_runs_child():
    t, ctx = build('<Sequence><LoopList queue="{q}" value="{v}">'
                   '<SetBlackboard output_key="{last}" value="{v}"/></LoopList></Sequence>',
                   cfg={"q": [{"a": 1}, {"a": 2}, {"a": 3}]})
    statuses = run(t, 4)
    assert statuses == [R, R, R, S]
    assert t.blackboard.get("last") == {"a": 3}


def test_loop_list_stops_on_child_failure_and_if_empty():
    t, ctx = build('<LoopList queue="{q}" value="{v}">%s</LoopList>' % leaf("x", "S;F"), cfg={"q": [1, 2, 3]})
    assert run(t, 2) == [R, F]
    t, ctx = build('<LoopList queue="{q}" value="{v}" if_empty="FAILURE">%s</LoopList>' % leaf("x", "S"),
                   cfg={"q": []})
    assert t.tick() == F


def test_typed_ports_convert_literals_defaults_and_blackboard_strings():
    t, _ = build('<Typed i="{n}" fl="1.0;2.5" b="true" j=\'{"k": [1, 2]}\' mode="slow" out="{o}"/>',
                 cfg={"n": "7"})
    assert t.tick() == S
    seen = t.blackboard.get("seen")
    assert seen == {"f": 1.5, "i": 7, "b": True, "fl": [1.0, 2.5], "j": {"k": [1, 2]}, "s": "x", "mode": "slow"}
    assert t.blackboard.get("o") == 1.5


def test_wrong_type_on_blackboard_fails_the_node_with_reason():
    t, ctx = build('<Typed i="{n}"/>', cfg={"n": "seven"})
    assert t.tick() == F
    node, reason = ctx.last_failure()
    assert "port 'i'" in reason and "'seven' is not a valid int" in reason
