"""HICEM ROS node: adapts the ROS-free HICEM core (:mod:`locem_bridge.hicem`) to ROS.

Interfaces (relative to the node, ``/hicem/...`` when the node is named ``hicem`` in the root namespace):

- services ``~start_process`` (``HicemStartProcess``: process IRI + JSON options), ``~stop`` (``HicemStop``),
  ``~operator_reply`` (``HicemOperatorReply``);
- the running action's skill methods (OPC UA Part 10 program state machine, issue 18): services ``~suspend``,
  ``~resume``, ``~halt``, ``~reset`` (``SkillControl``: request ``cause``; reply ``success``, ``code`` ``OK`` or
  ``INVALID_ARGUMENT`` when the skill state does not allow the method -- nothing changed then --, ``message``,
  ``state`` and ``allowed``, the methods accepted now, comma-separated) and topic ``~skill_state``
  (``SkillTransition``, latched: the last transition, then every one with its cause); see
  :mod:`locem_bridge.hicem.controller` for what each method does;
- topics ``~state`` (``HicemState``, latched, on every change; ``phase`` ``suspending`` / ``suspended`` while
  the action is) and ``~prompts`` (``HicemPrompt`` events);
- it uses LOCEM's action ``<locem>/command_action`` for every command and its ``<locem>/command`` service for a
  periodic ``STATUS`` (LOCEM's heartbeat), listens to ``diagnostics`` and ``<locem>/status``, and talks to
  PEMKRE through ``<pemkre>/*`` services (``~pemkre: ros``) or an engine embedded in this process
  (``~pemkre: embedded``, store at ``~pemkre_store``, the package's Turtle plus ``~extra_ontology_dirs``, tasks
  matched to the skills of the robot YAML ``~robot`` when it is set, the one HICEM reads its facts from; for
  single-process runs and tests).

Parameters: ``~params_file`` (HICEM parameters YAML; default ``config/hicem/plasterboard.yaml`` of the package),
``~trees_dir``, ``~extra_trees_dirs`` (an integrator's tree folders loaded beside it, separated by ``:`` or ``,``;
their trees may use the shipped subtrees), ``~hdict_path`` (HDICT SQLite file; default ``$ROS_HOME/hicem_hdict.sqlite``), ``~locem_ns``
(default ``locem``, resolved in the node's namespace), ``~pemkre``, ``~pemkre_ns``, ``~pemkre_store``,
``~status_period`` (s between STATUS polls), ``~pemkre_call_deadline`` (s one PEMKRE call is sent again while
PEMKRE is away, default 10), ``~pemkre_wait`` (s the process waits for an away PEMKRE before it fails, default
600), ``~locem_wait`` (s a LOCEM command waits for an away LOCEM action server before it fails, default 10),
``~diagnostics_topic`` (default ``diagnostics``: ``/diagnostics`` in the root namespace, the robot's own in a robot namespace), ``~resume`` (``auto``: continue an interrupted process found in
the HDICT at start-up; ``never``).
Lifecycle: start → (resume) → serve until shutdown → the running tree is halted, the HDICT closed.
"""
import json
import os
from typing import Any, Dict, Optional

import rospkg
import rospy

from locem_bridge.common.folders import split_folders
from locem_bridge.common.program_state import Method, Transition
from locem_bridge.hicem.config import load_params
from locem_bridge.hicem.errors import ControllerError, HicemError, OperatorError, SkillMethodRefused
from locem_bridge.hicem.executive import create_executive
from locem_bridge.hicem.xml_loader import TreeLibrary
from locem_bridge.job.call_log import instrument_from_env
from locem_bridge.msg import HicemPrompt, HicemState, SkillTransition
from locem_bridge.srv import (HicemOperatorReply, HicemOperatorReplyResponse, HicemStartProcess,
                              HicemStartProcessResponse, HicemStop, HicemStopResponse, SkillControl,
                              SkillControlResponse)

from .hicem_locem import LocemHealthFeed, RosLocemClient
from .hicem_pemkre import RosPemkreClient
from .params import package_share, param
from .startup import config_guard


def _pemkre_client(kind: str) -> Any:
    if kind == "ros":
        return RosPemkreClient(rospy.resolve_name(param("pemkre_ns", "pemkre")),
                               deadline_s=param("pemkre_call_deadline", 10.0))
    if kind == "embedded":
        from locem_bridge.hicem.pemkre_local import EngineClient
        from locem_bridge.pemkre import ProcessEngine
        from locem_bridge.pemkre.store_factory import open_store
        store_path = os.path.expanduser(param("pemkre_store", os.path.join(rospkg.get_ros_home(),
                                                                            "hicem_pemkre_store")))
        # the package's Turtle plus an integrator's folders, as the PEMKRE node loads them
        from locem_bridge.common.folders import folder_files
        from locem_bridge.pemkre.ontology import default_ontology_dir
        files = folder_files([default_ontology_dir()] +
                             split_folders(param("extra_ontology_dirs", "")), ".ttl", "ontology folder")
        store = open_store("rocksdb", store_path)
        site_file = param("site", "")
        if site_file:  # the store holds this site's data or none (as the PEMKRE node checks its store)
            from locem_bridge.pemkre.store_factory import claim_site_or_close
            from locem_bridge.sim.config import load_site
            try:
                site = load_site(site_file)["site"]["name"]
            except Exception:
                store.close()
                raise
            claim_site_or_close(store, site, store_path, site_file)
        try:
            engine = ProcessEngine(store, files)
            # matched to the skills of ~robot (its resource model from the same tree folders HICEM runs), as the
            # node; only when ~robot is set: a test node with its own trees and no robot runs unmatched, as before
            from locem_bridge.pemkre.robot_model import match_robot
            match_robot(engine, param("robot", ""), [param("trees_dir", os.path.join(package_share(), "trees"))] +
                        split_folders(param("extra_trees_dirs", "")), files)
        except Exception:
            store.close()
            raise
        return EngineClient(engine)
    raise HicemError("~pemkre must be 'ros' or 'embedded', got %r" % kind)


class HicemNode:
    def __init__(self) -> None:
        share = package_share()
        trees_dir = param("trees_dir", os.path.join(share, "trees"))
        # the package's trees plus an integrator's folders, one set (a tree ID defined twice names both files)
        tree_dirs = [trees_dir] + split_folders(param("extra_trees_dirs", ""))
        params_file = param("params_file", os.path.join(share, "config", "hicem", "plasterboard.yaml"))
        hdict = os.path.expanduser(param("hdict_path", os.path.join(rospkg.get_ros_home(), "hicem_hdict.sqlite")))
        locem_ns = rospy.resolve_name(param("locem_ns", "locem"))
        # the files first: a bad one fails the node at once (one line), not after waiting for LOCEM and PEMKRE
        robot_file = param("robot", os.path.join(share, "config", "robots", "rbkairos_ur10e.yaml"))
        params = load_params(params_file, robot_file)
        library = TreeLibrary(params.node_registry())
        library.load_directories(tree_dirs)
        # times each PEMKRE call into $LOCEM_CALL_LOG when set (bench/bench_job.py); otherwise the client itself
        # (before waiting for LOCEM: an embedded PEMKRE refuses a store of another site at once)
        self.pemkre = instrument_from_env(_pemkre_client(param("pemkre", "ros")))
        self.locem = RosLocemClient(locem_ns, wait_s=param("locem_wait", 10.0))
        self.ex = create_executive(self.pemkre, self.locem, hdict,
                                   params_file=params_file, trees_dir=trees_dir, params=params, library=library)
        self.ctrl = self.ex.controller
        self.ctrl.pemkre_wait_s = param("pemkre_wait", 600.0)
        self.state_pub = rospy.Publisher("~state", HicemState, queue_size=20, latch=True)
        self.prompt_pub = rospy.Publisher("~prompts", HicemPrompt, queue_size=50)
        self.skill_pub = rospy.Publisher("~skill_state", SkillTransition, queue_size=50, latch=True)
        self._last_transition: Optional[Transition] = None
        self.ctrl.add_state_listener(self._publish_state)
        self.ctrl.add_transition_listener(self._publish_transition)
        self.ex.operator.add_listener(self._on_prompt)
        self.feed = LocemHealthFeed(self.ex.data_handler, locem_ns, param("status_period", 0.25),
                                    rospy.resolve_name(param("diagnostics_topic", "diagnostics")))
        self.services = [rospy.Service("~start_process", HicemStartProcess, self._start),
                         rospy.Service("~stop", HicemStop, self._stop),
                         rospy.Service("~operator_reply", HicemOperatorReply, self._reply)]
        self.services += [rospy.Service("~%s" % m.value.lower(), SkillControl, self._skill_handler(m))
                          for m in (Method.SUSPEND, Method.RESUME, Method.HALT, Method.RESET)]
        self._publish_state(self.ctrl.state())
        if param("resume", "auto") == "auto" and self.ctrl.resume_in_background():
            rospy.logwarn("hicem: resuming the process interrupted in the previous run (HDICT %s)", hdict)
        rospy.loginfo("hicem: %d trees from %s, HDICT %s, LOCEM %s", len(self.ex.library.tree_ids()),
                      ", ".join(tree_dirs),
                      hdict, locem_ns)

    # -- topics ---------------------------------------------------------------------------------------------
    def _publish_state(self, st: Dict[str, Any]) -> None:
        msg = HicemState()
        msg.header.stamp = rospy.Time.now()
        for f in ("process", "specific_process", "phase", "action_type", "task", "skill", "tree", "node", "path",
                  "detail"):
            setattr(msg, f, str(st.get(f, "")))
        msg.prompts = json.dumps([{"id": p.id, "kind": p.kind, "text": p.text, "choices": list(p.choices)}
                                  for p in self.ex.operator.open_prompts()])
        self.state_pub.publish(msg)

    def _publish_transition(self, tr: Transition) -> None:
        self._last_transition = tr
        msg = SkillTransition()
        msg.header.stamp = rospy.Time.from_sec(tr.stamp)
        msg.instance, msg.skill, msg.number, msg.transition = tr.instance, tr.skill, tr.number, tr.name
        msg.from_state, msg.to_state, msg.method, msg.cause = tr.source.value, tr.target.value, tr.method, tr.cause
        self.skill_pub.publish(msg)

    def _on_prompt(self, event: str, prompt: Any) -> None:
        self.prompt_pub.publish(HicemPrompt(id=prompt.id, event=event, kind=prompt.kind, text=prompt.text,
                                            choices=list(prompt.choices), answer=prompt.answer or ""))
        self._publish_state(self.ctrl.state())

    # -- services -------------------------------------------------------------------------------------------
    def _start(self, req: Any) -> Any:
        try:
            options = json.loads(req.options) if req.options.strip() else None
            if options is not None and not isinstance(options, dict):
                raise ValueError("options must be a JSON object")
        except ValueError as exc:
            return HicemStartProcessResponse(False, "options are not a JSON object: %s" % exc)
        try:
            self.ctrl.start_process(req.process, options)
        except ControllerError as exc:
            return HicemStartProcessResponse(False, str(exc))
        return HicemStartProcessResponse(True, "process %s started" % req.process)

    def _stop(self, req: Any) -> Any:
        if not self.ctrl.running:
            return HicemStopResponse(True, "no process running")
        self.ctrl.stop(req.reason or "stop requested")
        done = self.ctrl.join(10.0)
        return HicemStopResponse(done, "stopped" if done else "stop requested; the tree is still halting")

    def _reply(self, req: Any) -> Any:
        try:
            self.ctrl.operator_reply(req.prompt_id, req.answer)
        except OperatorError as exc:
            return HicemOperatorReplyResponse(False, str(exc))
        return HicemOperatorReplyResponse(True, "answer '%s' given to prompt %s" % (req.answer, req.prompt_id))

    def _skill_handler(self, method: Method) -> Any:
        service = rospy.resolve_name("~%s" % method.value.lower())

        def handle(req: Any) -> Any:
            try:
                state = self.ctrl.skill_method(method, req.cause or "requested over ROS (%s)" % service)
            except SkillMethodRefused as exc:
                return SkillControlResponse(False, "INVALID_ARGUMENT", str(exc), exc.state, ",".join(exc.allowed))
            except HicemError as exc:
                state_now, allowed = self.ctrl.skill_state()
                return SkillControlResponse(False, "ABORTED", str(exc), state_now, ",".join(allowed))
            state_now, allowed = self.ctrl.skill_state()
            tr = self._last_transition
            if method == Method.SUSPEND and state.value != "Suspended":
                message = "Suspend pending: %s" % self.ctrl.state().get("skill_detail", "")
            elif tr is not None:
                message = "%s taken: %s %s is %s (%s)" % (method.value, tr.skill, tr.instance, tr.target.value,
                                                         tr.cause)
            else:
                message = "%s taken" % method.value
            return SkillControlResponse(True, "OK", message, state.value, ",".join(allowed))
        return handle

    def shutdown(self) -> None:
        self.feed.shutdown()
        self.ex.close()
        engine = getattr(self.pemkre, "engine", None)  # embedded PEMKRE: close its store cleanly
        if engine is not None and hasattr(engine.store, "close"):
            engine.store.close()


@config_guard("hicem")
def main() -> None:
    rospy.init_node("hicem")
    node = HicemNode()
    rospy.on_shutdown(node.shutdown)
    rospy.spin()


if __name__ == "__main__":
    main()
