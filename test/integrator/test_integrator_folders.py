"""An integrator's use case from folders of its own, beside the package's (issue 17, part 5), without ROS.

``use_case/`` holds what an integrator writes: Turtle (its own task type, parameter and process over the scanned
world), a tree XML (shipped nodes, LOCEM commands and the shipped subtrees, no include) and a job YAML.
- The real PEMKRE engine loads the shipped Turtle plus that folder and the robot's resource model generated from
  the shipped trees plus that folder (PEMKRE matches the use case's task to the use case's tree), HICEM the
  shipped trees plus that folder, and the spot-taping process runs against the LOCEM test double's scanned site:
  one joint per wall, each taped from its middle outwards in pieces, the other joints untouched. A resource model
  generated without the use case's tree folder offers no skill for its task: start_process refuses, saying why.
- ``tools/main.sh``'s pre-flight (``python -m locem_bridge.ros.main_job``) refuses, in one line naming what is
  wrong and before anything starts: a folder that does not exist, a Turtle file declaring a shipped ontology IRI
  (both files named), a BehaviorTree ID defined twice (both files and lines), a job naming a process the loaded
  Turtle does not have, an unknown robot name (the names there listed).
The whole use case on the simulated site, measured on the world's tape record: test_use_case_on_the_site.py.
"""
import os
import re
import shutil
import subprocess
import sys
import time

import pytest

from hicem_doubles import AutoOperator, Heartbeats, LocemDouble
from hicem_rig import params
from locem_bridge.common.config_errors import ConfigError
from locem_bridge.common.folders import folder_files, split_folders
from locem_bridge.hicem.errors import TreeLoadError
from locem_bridge.hicem.executive import create_executive
from locem_bridge.hicem.pemkre_local import EngineClient
from locem_bridge.hicem.xml_loader import TreeLibrary
from locem_bridge.pemkre import OxigraphStore, ProcessEngine
from locem_bridge.pemkre.errors import OntologyError, UnmatchableProcessError
from locem_bridge.pemkre.ontology import load_files
from locem_bridge.pemkre.vocab import PPR, SITE as SITE_NS
from locem_bridge.skills import build_resource_model

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
USE_CASE = os.path.join(REPO, "test", "integrator", "use_case")
SHIPPED_TREES = os.path.join(REPO, "trees")
SHIPPED_TURTLE = os.path.join(REPO, "ontologies")
PROCESS = "https://integrator.example.org/ont/spot-taping#SpotTapingProcess"
ROBOT = os.path.join(REPO, "config", "robots", "rbkairos_ur10e.yaml")
TURTLE = folder_files([SHIPPED_TURTLE, USE_CASE], ".ttl", "ontology folder")


def _floats(command):
    return [float(w) for w in command.split()[1:] if "=" not in w]


def _resource_model(tree_dirs):
    """The shipped robot's resource model generated from these tree folders and the Turtle of both folders (as the
    PEMKRE node and the pre-flight generate it)."""
    return build_resource_model(ROBOT, tree_dirs, ontology_files=TURTLE).to_graph()


def test_the_use_case_runs_beside_the_shipped_files(tmp_path):
    store = OxigraphStore(str(tmp_path / "pemkre_db"))
    engine = ProcessEngine(store, TURTLE, resource_model=_resource_model([SHIPPED_TREES, USE_CASE]))
    # PEMKRE matches the integrator's task type to the integrator's tree: the composite skill SPOT_TAPE_JOINT
    # realizes spot:cap_TapeJointInPieces
    tape = [n for n in engine.match_process(PROCESS).nodes if n.node.endswith("#tape")][0]
    assert (tape.capability, tape.realization.name, tape.realization.skill_kind) == \
        ("https://integrator.example.org/ont/spot-taping#cap_TapeJointInPieces", "SPOT_TAPE_JOINT", "composite")
    library = TreeLibrary(params().node_registry())
    library.load_directories([SHIPPED_TREES, USE_CASE])
    locem = LocemDouble()
    ex = create_executive(EngineClient(engine), locem, str(tmp_path / "hdict.sqlite"), params=params(),
                          library=library)
    ex.operator.add_listener(AutoOperator(ex.controller, {"mount_tool": "done"}))
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    try:
        phase = ex.controller.run_process(PROCESS, {})
    finally:
        beats.stop()
        ex.close()
    try:
        assert phase == "ended", ex.controller.state()
        tapes = [c for c in locem.sent if c.startswith("APPLY_TAPE ")]
        # the first joint of each wall (scan order): wall_1_joint_1 (vertical, x 1.2) and wall_2_joint_1
        # (horizontal, z 1.2), never wall_1_joint_2 (x 2.4)
        assert locem.sent[0] == "SCAN" and locem.sent[-1] == "HOME", locem.sent
        assert len(tapes) == 4, tapes
        vertical, horizontal = [_floats(c) for c in tapes[:2]], [_floats(c) for c in tapes[2:]]
        assert all(abs(p[0] - 1.2) < 1e-6 and abs(p[3] - 1.2) < 1e-6 for p in vertical), tapes
        # from its middle outwards: both pieces start at mid height of the reachable band, one up, one down
        mid = vertical[0][2]
        assert abs(vertical[1][2] - mid) < 1e-6 and vertical[0][5] > mid > vertical[1][5], tapes
        assert all(abs(p[2] - 1.2) < 1e-6 and abs(p[0] - 4.8) < 1e-6 for p in horizontal), tapes
        assert not any(abs(_floats(c)[0] - 2.4) < 1e-6 for c in tapes), tapes
        # each piece from its own base pose (the horizontal joint's pieces: two approach poses along the wall)
        gotos = [c for c in locem.sent if c.startswith("GOTO ")]
        assert len({c for c in gotos}) >= 3, gotos
        # PEMKRE's world: the two sample joints taped (the shipped effect), the third still waiting
        for joint, status in (("wall_1_joint_1", PPR.processed), ("wall_2_joint_1", PPR.processed),
                              ("wall_1_joint_2", PPR.unprocessed)):
            assert engine.store.value(SITE_NS[joint], PPR.tapingStatus) == status, joint
    finally:
        store.close()


def test_without_the_integrators_trees_the_resource_model_has_no_skill_for_the_task_and_pemkre_says_so(tmp_path):
    """The resource model must see the tree folders HICEM runs: generated from the shipped trees alone, no skill
    realizes the use case's capability, and start_process refuses the process naming the task and why."""
    store = OxigraphStore(str(tmp_path / "pemkre_db"))
    try:
        engine = ProcessEngine(store, TURTLE, resource_model=_resource_model([SHIPPED_TREES]))
        with pytest.raises(UnmatchableProcessError) as err:
            engine.start_process(PROCESS, {})
        assert "spot-taping#tape" in str(err.value) and "cap_TapeJointInPieces" in str(err.value), str(err.value)
        assert engine.active_process() is None                            # nothing written
    finally:
        store.close()


def _line_of(path, text):
    with open(path, encoding="utf-8") as handle:
        return next(n for n, line in enumerate(handle, 1) if text in line)


def test_tree_folders_load_as_one_set_and_a_tree_id_defined_twice_names_both_files(tmp_path):
    own = tmp_path / "my_trees"
    own.mkdir()
    (own / "MY_GO_HOME.xml").write_text('<root BTCPP_format="4">\n  <BehaviorTree ID="GO_HOME">\n'
                                        '    <SubTree ID="GuardedCommand" command="HOME"/>\n'
                                        '  </BehaviorTree>\n</root>\n')
    library = TreeLibrary(params().node_registry())
    with pytest.raises(TreeLoadError) as err:
        library.load_directories([SHIPPED_TREES, USE_CASE, str(own)])
    line = err.value.one_line()
    assert line == "%s: line 2 'GO_HOME': BehaviorTree ID 'GO_HOME' is defined twice (also in %s:%d)" % (
        own / "MY_GO_HOME.xml", os.path.join(SHIPPED_TREES, "GO_HOME.xml"), _line_of(
            os.path.join(SHIPPED_TREES, "GO_HOME.xml"), '<BehaviorTree ID="GO_HOME">')), line
    assert library.tree_ids() == []                         # nothing of them stays loaded
    with pytest.raises(TreeLoadError) as err:
        library.load_directories([SHIPPED_TREES, str(tmp_path / "nowhere")])
    assert err.value.one_line() == "%s: trees folder does not exist" % (tmp_path / "nowhere")


def test_a_turtle_file_declaring_a_shipped_ontology_iri_names_both_files(tmp_path):
    own = tmp_path / "my_turtle"
    own.mkdir()
    shutil.copy(os.path.join(SHIPPED_TURTLE, "plasterboard.ttl"), str(own / "my_plasterboard.ttl"))
    with pytest.raises(OntologyError) as err:
        load_files(folder_files([SHIPPED_TURTLE, str(own)], ".ttl", "ontology folder"))
    line = err.value.one_line()
    assert line.startswith(str(own / "my_plasterboard.ttl") + ": "), line
    assert "<https://locem-bridge.example.org/ont/plasterboard>" in line, line
    assert os.path.join(SHIPPED_TURTLE, "plasterboard.ttl") in line, line


def test_folder_lists_split_on_colons_and_commas_and_a_folder_named_twice_is_read_once(tmp_path):
    assert split_folders("a:b, c,,") == ["a", "b", "c"] and split_folders(None) == [] and split_folders("") == []
    assert split_folders(["a", " b "]) == ["a", "b"]
    files = folder_files([USE_CASE, USE_CASE + "/"], ".ttl", "ontology folder")
    assert files == [os.path.join(USE_CASE, "spot_taping.ttl")]
    with pytest.raises(ConfigError) as err:
        folder_files([str(tmp_path / "x.ttl")], ".ttl", "ontology folder")
    assert err.value.one_line() == "%s: ontology folder does not exist" % (tmp_path / "x.ttl")


# -- tools/main.sh's pre-flight ------------------------------------------------------------------------------------

def _main_job(tmp_path, *args):
    started = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "locem_bridge.ros.main_job", "--results-dir", str(tmp_path / "r")]
                          + list(args), cwd=str(tmp_path), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                          universal_newlines=True, timeout=120)
    print("main_job answered in %.2f s" % (time.monotonic() - started))
    lines = done.stdout.splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stdout
    assert lines[0].startswith("[main] configuration error: "), done.stdout
    assert not (tmp_path / "r").exists()                     # nothing was launched
    return lines[0][len("[main] configuration error: "):]


def _copy_use_case(tmp_path):
    own = tmp_path / "use_case"
    shutil.copytree(USE_CASE, str(own))
    return own


def test_preflight_refuses_a_missing_folder(tmp_path):
    missing = tmp_path / "my_trees"
    line = _main_job(tmp_path, "--ontologies", USE_CASE, "--trees", str(missing), "--job",
                     os.path.join(USE_CASE, "job.yaml"))
    assert line == "%s: trees folder does not exist" % missing
    line = _main_job(tmp_path, "--ontologies", str(missing), "--trees", USE_CASE)
    assert line == "%s: ontology folder does not exist" % missing


def test_preflight_refuses_a_tree_id_defined_twice(tmp_path):
    own = _copy_use_case(tmp_path)
    (own / "MY_SCAN.xml").write_text('<root BTCPP_format="4">\n  <BehaviorTree ID="SCAN">\n    <AlwaysSuccess/>\n'
                                     '  </BehaviorTree>\n</root>\n')
    line = _main_job(tmp_path, "--ontologies", str(own), "--trees", str(own), "--job", str(own / "job.yaml"))
    assert line.startswith(str(own / "MY_SCAN.xml") + ": line 2 'SCAN': BehaviorTree ID 'SCAN' is defined twice "
                           "(also in "), line
    assert re.search(r"/trees/SCAN\.xml:\d+\)$", line), line       # the package's file (in its share folder)


def test_preflight_refuses_a_turtle_file_with_a_shipped_ontology_iri(tmp_path):
    own = _copy_use_case(tmp_path)
    shutil.copy(os.path.join(SHIPPED_TURTLE, "ppr.ttl"), str(own / "ppr_copy.ttl"))
    line = _main_job(tmp_path, "--ontologies", str(own), "--trees", str(own), "--job", str(own / "job.yaml"))
    assert line.startswith(str(own / "ppr_copy.ttl") + ": ontology IRI <https://locem-bridge.example.org/ont/ppr>")
    assert re.search(r"declared here and in \S*/ontologies/ppr\.ttl;", line), line   # the package's file


def test_preflight_refuses_a_job_whose_process_the_turtle_does_not_have(tmp_path):
    line = _main_job(tmp_path, "--trees", USE_CASE, "--job", os.path.join(USE_CASE, "job.yaml"))   # no --ontologies
    assert line.startswith(os.path.join(USE_CASE, "job.yaml") + ": steps[0].process: process <%s> is not an "
                           "abstract process of the loaded Turtle (allowed: " % PROCESS), line


def test_preflight_refuses_an_unknown_robot_name_listing_the_robots(tmp_path):
    line = _main_job(tmp_path, "--robot", "rbkairos_ur11e")
    assert line.startswith("--robot rbkairos_ur11e: no robot of this name in "), line
    assert re.search(r"\(allowed: .*rbkairos_ur10e", line), line


def test_main_sh_arguments_become_the_launch_arguments(tmp_path):
    from locem_bridge.ros.main_job import arguments, launch_command, preflight
    other = tmp_path / "more_trees"
    args = arguments(["--robot", "diffdrive_ur5e", "--ontologies", USE_CASE, "--trees", USE_CASE, "--trees",
                      str(other), "--job", os.path.join(USE_CASE, "job.yaml")])
    cmd = launch_command(args, 11311)
    robot = [a for a in cmd if a.startswith("robot:=")]
    assert len(robot) == 1 and robot[0].endswith(os.path.join("config", "robots", "diffdrive_ur5e.yaml")), cmd
    assert os.path.isfile(robot[0][len("robot:="):])
    assert "job:=%s" % os.path.join(USE_CASE, "job.yaml") in cmd, cmd
    assert "extra_ontology_dirs:=%s" % USE_CASE in cmd, cmd
    assert "extra_trees_dirs:=%s:%s" % (USE_CASE, other) in cmd, cmd           # one text, ':'-separated
    assert preflight(args) == "%s: trees folder does not exist" % other        # every folder checked
    other.mkdir()
    (other / "EMPTY_CHECK.xml").write_text('<root BTCPP_format="4">\n  <BehaviorTree ID="EMPTY_CHECK">\n'
                                           '    <AlwaysSuccess/>\n  </BehaviorTree>\n</root>\n')
    assert preflight(args) is None                                              # the whole set loads
    robot_file = tmp_path / "robots" / "my_robot.yaml"                          # a path is taken as it is
    assert launch_command(arguments(["--robot", str(robot_file)]), 11311).count("robot:=%s" % robot_file) == 1
