"""Interval arithmetic behind the job benchmark's split of time by layer."""
import pytest

from locem_bridge.job.timeline import (TimelineError, activity_intervals, clip, intersect, merge, phase_spans,
                                       spans_from_events, split_window, subtract, total)


def test_merge_joins_overlapping_and_touching_intervals_and_keeps_gaps():
    assert merge([(5, 6), (0, 2), (1, 3), (3, 4)]) == [(0, 4), (5, 6)]
    assert merge([(0, 1), (1.5, 2)], gap=0.5) == [(0, 2)]
    assert merge([]) == []


def test_total_counts_overlaps_once():
    assert total([(0, 10), (2, 5), (8, 12)]) == 12


def test_clip_subtract_and_intersect():
    assert clip([(0, 4), (6, 10)], 2, 8) == [(2, 4), (6, 8)]
    assert subtract([(0, 10)], [(2, 3), (5, 7), (9, 12)]) == [(0, 2), (3, 5), (7, 9)]
    assert subtract([(0, 1)], [(0, 1)]) == []
    assert intersect([(0, 4), (6, 10)], [(3, 7)]) == [(3, 4), (6, 7)]


def test_split_gives_each_instant_to_the_first_layer_covering_it_and_adds_up_to_the_window():
    # a LOCEM command 2..8 during which a device moved 3..6; a PEMKRE call 8..9 overlapping nothing
    parts = split_window((0, 10), [("device", [(3, 6)]), ("locem", [(2, 8)]), ("pemkre", [(8, 9), (2.5, 3)])],
                         rest="hicem")
    assert parts == {"device": 3, "locem": 3, "pemkre": 1, "hicem": 3}
    assert sum(parts.values()) == 10


def test_split_ignores_what_lies_outside_the_window():
    parts = split_window((10, 20), [("device", [(0, 12), (19, 30)])])
    assert parts == {"device": 3, "rest": 7}


def test_split_refuses_a_layer_named_like_the_remainder():
    with pytest.raises(TimelineError, match="unique"):
        split_window((0, 1), [("rest", [])])


def test_an_interval_ending_before_it_starts_is_refused_with_its_values():
    with pytest.raises(TimelineError, match=r"\(5.0, 4.0\) ends before it starts"):
        merge([(5, 4)])
    with pytest.raises(TimelineError, match="pair of numbers"):
        total([("a", "b")])


def test_spans_pair_events_by_key_and_unfinished_ones_run_to_the_end():
    events = [(4.0, "b", "start"), (1.0, "a", "start"), (2.0, "a", "event"), (3.0, "a", "end"),
              (9.0, "a", "end")]  # a second end of 'a' changes nothing
    assert spans_from_events(events, end=10.0) == {"a": (1.0, 3.0), "b": (4.0, 10.0)}
    assert spans_from_events(events) == {"a": (1.0, 3.0), "b": (4.0, 4.0)}
    with pytest.raises(TimelineError, match="start, event or end"):
        spans_from_events([(0, "a", "begin")])


def test_activity_from_samples_does_not_count_a_gap_in_the_samples():
    samples = [(0.0, False), (0.1, True), (0.2, True), (0.3, False), (5.0, True)]
    # 0.0-0.2 moving; the sample at 5.0 after a 4.7 s silence covers only max_period back
    assert activity_intervals(samples, max_period=0.25) == [(0.0, 0.2), (4.75, 5.0)]


def test_phase_spans_last_until_the_next_change_and_the_last_until_the_end():
    snaps = [(0, {"phase": "asking"}), (1, {"phase": "running"}), (1.5, {"phase": "running"}),
             (4, {"phase": "ended"})]
    spans = phase_spans(snaps, end=6, keys=("phase",))
    assert [(s["phase"], s["start"], s["end"]) for s in spans] == [("asking", 0, 1), ("running", 1, 4),
                                                                   ("ended", 4, 6)]
