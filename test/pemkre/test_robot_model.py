"""The PEMKRE node's robot matching (pemkre/robot_model.match_robot, called by ros/pemkre_node and HICEM's embedded
engine): the resource model is generated from the robot
file and the tree folders, kept in the store with a fingerprint of those inputs, and a restarted node on the same
store resumes it without generating it again -- unless an input changed. A bad robot file is refused with its name.
(``main`` itself runs in every whole-job rostest suite through plasterboard.launch.)"""
import os
import shutil

import pytest

from locem_bridge.common.config_errors import ConfigError
from locem_bridge.pemkre import PLB, JournaledStore, ProcessEngine
from locem_bridge.pemkre.ontology import default_ontology_files
from locem_bridge.pemkre.robot_model import match_robot, resource_model_key

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ROBOT = os.path.join(ROOT, "config", "robots", "rbkairos_ur10e.yaml")
TREES = os.path.join(ROOT, "trees")


def test_the_model_is_kept_with_its_inputs_fingerprint_and_resumed_or_rebuilt(tmp_path):
    files = default_ontology_files()
    trees = str(tmp_path / "trees")
    shutil.copytree(TREES, trees)
    path = str(tmp_path / "db")
    store = JournaledStore(path)
    try:
        e = ProcessEngine(store, files)
        assert not match_robot(e, "", [trees], files) and not e.matching        # no robot: no matching
        assert match_robot(e, ROBOT, [trees], files) and e.matching
        key = resource_model_key(ROBOT, [trees], files)
    finally:
        store.close()
    store = JournaledStore(path)
    try:
        e = ProcessEngine(store, files)
        assert e.resume_resource_model(key)                  # what a respawned node finds: the same inputs
        with open(os.path.join(trees, "GO_HOME.xml"), "a") as fh:
            fh.write("\n<!-- edited -->\n")
        changed = resource_model_key(ROBOT, [trees], files)
        assert changed != key and not e.resume_resource_model(changed)
        assert match_robot(e, ROBOT, [trees], files)         # rebuilt from the edited folder, stored anew
        assert e.resume_resource_model(changed)
        assert e.match_process(str(PLB.TapingProcess)).ok
    finally:
        store.close()


def test_a_bad_robot_file_is_refused_naming_it(tmp_path):
    bad = tmp_path / "robot.yaml"
    bad.write_text("robot: {name: x, arm: 3}\n")
    store = JournaledStore(str(tmp_path / "db"))
    try:
        e = ProcessEngine(store)
        with pytest.raises(ConfigError) as info:
            match_robot(e, str(bad), [TREES], default_ontology_files())
        assert str(bad) in str(info.value) and not e.matching
    finally:
        store.close()
