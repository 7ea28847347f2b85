"""Check every file a run reads before anything starts (``tools/main.sh``'s pre-flight), ROS-free.

:func:`check_files` loads each given file with the same loader its node uses (site and robot YAML through the
one robot/site validation, the robot file together with the launch's overrides; HICEM parameters; every tree
XML of the trees folder; every Turtle file of the ontology folder, parsed; with a robot, trees and ontologies, the
robot's resource model generated from them as the PEMKRE node does) and raises the first
:class:`~locem_bridge.common.config_errors.ConfigError`, whose ``str`` is the one line ``FILE: KEY: PROBLEM (allowed:
...)``. It takes a second or two; the process model's structure (checked when PEMKRE compiles it) is left
to the PEMKRE node, which fails with the same kind of line.
"""
import os
from typing import Any, Mapping, Optional, Sequence

from .common.config_errors import ConfigError
from .common.folders import folder_files


def check_files(site: Optional[str] = None, robot: Optional[str] = None,
                robot_overrides: Optional[Mapping[str, Any]] = None, params_file: Optional[str] = None,
                trees_dir: Optional[str] = None, ontology_dir: Optional[str] = None,
                extra_trees_dirs: Sequence[str] = (), extra_ontology_dirs: Sequence[str] = (),
                job: Optional[str] = None) -> None:
    """Load each file that is given; raise the first :class:`ConfigError` (``None`` skips a file).

    ``extra_trees_dirs`` / ``extra_ontology_dirs``: an integrator's folders, loaded together with ``trees_dir`` /
    ``ontology_dir`` as the nodes load them (a tree ID or an ontology IRI defined twice names both files).
    ``job``: the job YAML; each step's ``process`` must be an abstract process of the loaded Turtle."""
    if site:
        from .sim.config import load_site
        load_site(site)
    if robot:
        from .robot_file import load_robot
        load_robot(robot, robot_overrides or None)
    params = None
    if params_file:
        from .hicem.config import load_params
        params = load_params(params_file, robot)
    if trees_dir:
        from .hicem.xml_loader import TreeLibrary
        TreeLibrary(params.node_registry() if params is not None else None).load_directories(
            [trees_dir] + list(extra_trees_dirs))
    processes = None
    if ontology_dir:
        from .pemkre.ontology import load_files
        files = folder_files([ontology_dir] + list(extra_ontology_dirs), ".ttl", "ontology folder")
        for folder in [ontology_dir] + list(extra_ontology_dirs):
            if not folder_files([folder], ".ttl", "ontology folder"):
                raise ConfigError("holds no Turtle files (*.ttl)", file=os.path.abspath(folder))
        from rdflib.namespace import RDF
        from .pemkre.vocab import PROC
        processes = {str(p) for p in load_files(files).schema.subjects(RDF.type, PROC.AbstractProcess)}
    if job:
        from .job.steps import load_steps
        for i, step in enumerate(load_steps(job)):
            if processes is not None and step.iri not in processes:
                raise ConfigError("process <%s> is not an abstract process of the loaded Turtle" % step.iri,
                                  file=job, key="steps[%d].process" % i, allowed=sorted(processes))
    if robot and trees_dir and ontology_dir:    # skills naming absent devices, unknown units or capabilities, ...
        from .skills import build_resource_model
        build_resource_model(robot, [trees_dir] + list(extra_trees_dirs), robot_overrides or None,
                             ontology_files=files)
