"""The skill layer's one description: a robot's resource model, generated from the robot file, its LOCEM command
registry and the action trees (ROS-free).

::

    from locem_bridge.skills import build_resource_model
    model = build_resource_model("config/robots/rbkairos_ur10e.yaml", ["trees"])
    model.skill("GET_TOOL", "composite").capability     # .../plasterboard#cap_GetTool
    graph = model.to_graph()                             # rdflib Graph in the sk: vocabulary (ontologies/skill.ttl)

``python -m locem_bridge.skills export --robot FILE [--trees DIR ...] --out robot.ttl`` writes it for Protégé.
"""
from .build import ALL_DEVICES, build_resource_model, default_tree_dirs
from .errors import SkillModelError
from .model import BASIC, COMPOSITE, Device, Frame, ResourceModel, Skill, SkillParameter, Tool

__all__ = ["ALL_DEVICES", "BASIC", "COMPOSITE", "Device", "Frame", "ResourceModel", "Skill", "SkillModelError",
           "SkillParameter", "Tool", "build_resource_model", "default_tree_dirs"]
