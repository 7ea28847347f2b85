#!/usr/bin/env python3
"""rostest: the /pemkre/* services -- a taping run with operator validation (each task naming the skill of the
shipped robot that realizes it), queries, KPIs, the skill matching of a process (/pemkre/match), bad input."""
import json
import unittest

import rospy
import rostest
from locem_bridge.srv import (PemkreMatchProcess, PemkreNextAction, PemkreQuery, PemkreSetTaskStatus,
                              PemkreStartProcess, PemkreUpdateWorld)

from rostest_support import rosservice_call

PKG = "locem_bridge"
TAPING = "https://locem-bridge.example.org/ont/plasterboard#TapingProcess"
SCAN = {"stamp": 1.0,
        "walls": [{"id": "wall_1", "p0": [0.0, 3.0], "p1": [4.8, 3.0], "height": 2.5, "thickness": 0.0125,
                   "normal": [0.0, -1.0, 0.0]}],
        "joints": [{"id": "wall_1_joint_%d" % i, "wall": "wall_1", "kind": "vertical", "start": [1.2 * i, 3.0, 0.0],
                    "end": [1.2 * i, 3.0, 2.5], "width": 0.05} for i in (1, 2)],
        "areas": []}


def local(iri):
    return iri.rsplit("/", 1)[-1].rsplit("#", 1)[-1]


class PemkreServicesTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("pemkre_services_test", anonymous=True)
        for name in ("start_process", "next_action", "set_task_status", "query", "update_world", "match"):
            rospy.wait_for_service("/pemkre/" + name, timeout=60)
        cls.start = staticmethod(rospy.ServiceProxy("/pemkre/start_process", PemkreStartProcess))
        cls.next = staticmethod(rospy.ServiceProxy("/pemkre/next_action", PemkreNextAction))
        cls.status = staticmethod(rospy.ServiceProxy("/pemkre/set_task_status", PemkreSetTaskStatus))
        cls.query = staticmethod(rospy.ServiceProxy("/pemkre/query", PemkreQuery))
        cls.world = staticmethod(rospy.ServiceProxy("/pemkre/update_world", PemkreUpdateWorld))
        cls.match = staticmethod(rospy.ServiceProxy("/pemkre/match", PemkreMatchProcess))

    def test_a_taping_run_with_operator_validation(self):
        w = self.world(json.dumps(SCAN))
        self.assertTrue(w.success, w.message)
        self.assertGreater(w.changed, 10)
        reply = rosservice_call("/pemkre/start_process",
                                "{process: '%s', options: '{\"validateLines\": true}', abort_running: true}" % TAPING)
        self.assertTrue(reply["success"], reply)
        self.assertEqual(reply["code"], "OK")
        seen = []
        for _ in range(20):
            a = self.next("")
            self.assertTrue(a.success, a.message)
            if a.status != "action":
                seen.append((a.status, a.message))
                break
            params = {}
            for line in a.parameters.splitlines():
                s, p, o = line.rstrip(" .").split(" ", 2)
                self.assertEqual(s, "<%s>" % a.task)      # N-Triples about the task
                params[local(p.strip("<>"))] = local(o.strip("<>"))
            seen.append((a.action_type, params))
            # the shipped robot realizes every taping task with the tree of its action type
            self.assertEqual((a.skill, a.skill_kind), (a.action_type, "composite"))
            self.assertTrue(self.status(a.task, "in_progress", "", "").success)
            detail = ""
            if a.action_type == "VALIDATE_TAPE_LINE":
                detail = "valid" if params["line"] == "wall_1_joint_1" else "invalid"
            r = self.status(a.task, "succeeded", detail, "")
            self.assertTrue(r.success, r.message)
        self.assertEqual([s[0] for s in seen], ["GET_TOOL", "VALIDATE_TAPE_LINE", "TAPE_LINE", "VALIDATE_TAPE_LINE",
                                                "MANUAL_TAPING", "GO_HOME", "ended"])
        self.assertEqual(seen[1][1], {"line": "wall_1_joint_1"})
        self.assertEqual(seen[4][1], {"line": "wall_1_joint_2"})
        self.assertEqual(seen[-1][1], "completed")
        # a predefined query with a value bound, through the rosservice CLI (an N-Triples literal)
        reply = rosservice_call("/pemkre/query", "{name: feature_status, binding_names: [feature], binding_values: "
                                "['<https://locem-bridge.example.org/site/wall_1_joint_2>']}")
        self.assertTrue(reply["success"], reply)
        rows = json.loads(reply["results"])["results"]["bindings"]
        self.assertEqual([(local(r["property"]["value"]), local(r["state"]["value"])) for r in rows],
                         [("tapingStatus", "processedManually")])
        kpi = self.query("kpi_by_task_type", [], [])
        self.assertTrue(kpi.success, kpi.message)
        by_type = {r["actionType"]["value"]: r for r in json.loads(kpi.results)["results"]["bindings"]}
        self.assertEqual(by_type["VALIDATE_TAPE_LINE"]["count"]["value"], "2")
        self.assertEqual(by_type["MANUAL_TAPING"]["manualFallbacks"]["value"], "1")

    def test_c_the_skill_matching_of_a_process_explains_each_task(self):
        reply = rosservice_call("/pemkre/match", "{process: '%s'}" % TAPING)
        self.assertTrue(reply["success"], reply)
        self.assertRegex(reply["message"], r"^\d+ task node\(s\), all matched$")
        m = json.loads(reply["match"])
        self.assertTrue(m["ok"])
        self.assertEqual(m["process"], TAPING)
        self.assertTrue(m["robot"].startswith("https://locem-bridge.example.org/robot/"), m["robot"])
        by_type = {n["action_type"]: n for n in m["nodes"]}
        self.assertLessEqual({"SCAN", "GET_TOOL", "VALIDATE_TAPE_LINE", "TAPE_LINE", "MANUAL_TAPING", "GO_HOME"},
                             set(by_type))
        get_tool = by_type["GET_TOOL"]
        self.assertEqual((get_tool["realization"]["name"], get_tool["realization"]["skill_kind"]),
                         ("GET_TOOL", "composite"))
        self.assertTrue(get_tool["realization"]["involves_operator"])
        # the tool-changer template is a candidate this robot cannot run, and the answer says why
        tmpl = [r for r in get_tool["rejected"] if r["kind"] == "template"]
        self.assertEqual([r["name"] for r in tmpl], ["tmpl_getToolAutomatically"])
        self.assertIn("cap_ChangeToolAutomatically", tmpl[0]["reason"])
        r = self.match("https://example.org/Nope")
        self.assertFalse(r.success)
        self.assertEqual(r.code, "UNKNOWN_PROCESS")
        self.assertIn("TapingProcess", r.message)

    def test_b_bad_input_is_refused_with_a_code_and_the_node_keeps_serving(self):
        cases = [
            (lambda: self.start("not an iri", "", True, ""), "MALFORMED_IRI", "absolute IRI"),
            (lambda: self.start("https://example.org/Nope", "", True, ""), "UNKNOWN_PROCESS", "TapingProcess"),
            (lambda: self.start(TAPING, "{validateLines: yes", True, ""), "INVALID_PARAMETER", "JSON"),
            (lambda: self.start(TAPING, '{"speed": 2}', True, ""), "INVALID_PARAMETER", "validateLines"),
            (lambda: self.status("https://example.org/task_1", "succeeded", "", ""), "UNKNOWN_TASK", "task_1"),
            (lambda: self.status("https://example.org/task_1", "done", "", ""), "INVALID_STATUS", "in_progress"),
            (lambda: self.query("nope", [], []), "UNKNOWN_QUERY", "pending_joint_lines"),
            (lambda: self.query("feature_by_id", ["id"], ['"x" . <a> <b> <c']), "INVALID_PARAMETER", "N-Triples"),
            (lambda: self.query("feature_by_id", ["feature"], ['"x"']), "INVALID_PARAMETER", "accepts id"),
            (lambda: self.world('{"joints": [{"id": "9bad"}]}'), "WORLD_UPDATE", "joints[0].id"),
            # 10000 levels of JSON: a clear refusal naming the argument and the depth, not an INTERNAL_ERROR
            (lambda: self.start(TAPING, '{"validateLines": %s}' % ("[" * 10000 + "]" * 10000), True, ""),
             "INVALID_PARAMETER", "options nests JSON arrays/objects deeper than the allowed 32 levels"),
            (lambda: self.world('{"walls": %s}' % ("[" * 10000 + "]" * 10000)),
             "INVALID_PARAMETER", "scan nests JSON arrays/objects deeper than the allowed 32 levels"),
        ]
        for call, code, fragment in cases:
            r = call()
            self.assertFalse(r.success, code)
            self.assertEqual(r.code, code, r.message)
            self.assertIn(fragment, r.message)
        # SPARQL metacharacters in a bound value are a value, not query text
        r = self.query("feature_by_id", ["id"], ['"wall_1_joint_1\\" } ; DROP ALL ; {"'])
        self.assertTrue(r.success, r.message)
        self.assertEqual(json.loads(r.results)["results"]["bindings"], [])
        r = self.query("feature_by_id", ["id"], ['"wall_1_joint_1"'])
        self.assertTrue(r.success and json.loads(r.results)["results"]["bindings"], r.message)


if __name__ == "__main__":
    rostest.rosrun(PKG, "pemkre_services", PemkreServicesTest)
