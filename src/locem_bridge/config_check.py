"""Check every file a run reads before anything starts (``tools/main.sh``'s pre-flight), ROS-free.

:func:`check_files` loads each given file with the same loader its node uses (site and robot YAML through the
one robot/site validation, the robot file together with the launch's overrides; HICEM parameters; every tree
XML of the trees folder; every Turtle file of the ontology folder, parsed) and raises the first
:class:`~locem_bridge.common.config_errors.ConfigError`, whose ``str`` is the one line ``FILE: KEY: PROBLEM (allowed:
...)``. It takes well under a second; the process model's structure (checked when PEMKRE compiles it) is left
to the PEMKRE node, which fails with the same kind of line.
"""
import os
from typing import Any, Mapping, Optional

from .common.config_errors import ConfigError


def check_files(site: Optional[str] = None, robot: Optional[str] = None,
                robot_overrides: Optional[Mapping[str, Any]] = None, params_file: Optional[str] = None,
                trees_dir: Optional[str] = None, ontology_dir: Optional[str] = None) -> None:
    """Load each file that is given; raise the first :class:`ConfigError` (``None`` skips a file)."""
    if site:
        from .sim.config import load_site
        load_site(site)
    if robot:
        from .robot_file import load_robot
        load_robot(robot, robot_overrides or None)
    params = None
    if params_file:
        from .hicem.config import load_params
        params = load_params(params_file)
    if trees_dir:
        from .hicem.xml_loader import TreeLibrary
        if not os.path.isdir(trees_dir):
            raise ConfigError("trees folder does not exist", file=trees_dir)
        TreeLibrary(params.node_registry() if params is not None else None).load_directory(trees_dir)
    if ontology_dir:
        from .pemkre.ontology import load_files
        if not os.path.isdir(ontology_dir):
            raise ConfigError("ontology folder does not exist", file=ontology_dir)
        files = sorted(os.path.join(ontology_dir, f) for f in os.listdir(ontology_dir) if f.endswith(".ttl"))
        if not files:
            raise ConfigError("holds no Turtle files (*.ttl)", file=ontology_dir)
        load_files(files)
