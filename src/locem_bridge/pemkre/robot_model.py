"""The robot's resource model for PEMKRE's matching, generated once per set of inputs.

:func:`match_robot` is what the PEMKRE node and HICEM's embedded engine do at start: generate the robot's resource
model (``locem_bridge.skills.build_resource_model``: robot file + LOCEM registry + tree folders) and load it into
the engine's store -- unless the store already holds the one built from the same inputs (:func:`resource_model_key`),
so a respawned node is back at once. Core code (no ROS); the generator is imported only when it runs.
"""
import hashlib
import os
from typing import Sequence

from ..common.paths import PYTHON_ROOT
from .engine import ProcessEngine


def resource_model_key(robot_file: str, tree_dirs: Sequence[str], ontology_files: Sequence[str]) -> str:
    """A fingerprint of everything the robot's resource model is built from: the robot file, the tree files, the
    ontology files (contents) and the package's sources (size and mtime). Equal keys: the model is the same."""
    h = hashlib.sha256()
    files = [robot_file] + list(ontology_files)
    for d in tree_dirs:
        files += sorted(os.path.join(d, f) for f in os.listdir(d) if f.endswith(".xml"))
    for path in files:
        try:
            with open(path, "rb") as fh:
                h.update(path.encode() + b"\0" + fh.read() + b"\0")
        except OSError:             # the generator says what is wrong with it, naming the file
            h.update(path.encode() + b"\0missing\0")
    root = os.path.join(PYTHON_ROOT, "locem_bridge")
    for base, dirs, names in sorted(os.walk(root)):
        dirs.sort()
        for name in sorted(n for n in names if n.endswith(".py")):
            st = os.stat(os.path.join(base, name))
            h.update(("%s %d %d\n" % (os.path.join(base, name), st.st_size, st.st_mtime_ns)).encode())
    return h.hexdigest()


def match_robot(engine: ProcessEngine, robot_file: str, tree_dirs: Sequence[str],
                ontology_files: Sequence[str]) -> bool:
    """Match the engine's processes to the skills of ``robot_file`` (no robot file: no matching, False).

    The resource model is generated (skills.build_resource_model) unless the store holds the one built from the same
    inputs (a respawned node starts at once). One place for the PEMKRE node and HICEM's embedded engine; a bad
    robot file or tree raises ``FILE: KEY: PROBLEM`` before anything is loaded.
    """
    if not robot_file:
        return False
    key = resource_model_key(robot_file, tree_dirs, ontology_files)
    if not engine.resume_resource_model(key):
        from ..skills import build_resource_model

        model = build_resource_model(robot_file, list(tree_dirs), ontology_files=list(ontology_files)).to_graph()
        engine.load_resource_model(model, key=key)
    return True
