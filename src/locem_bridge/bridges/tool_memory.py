"""LOCEM's memory of the tool on the flange, on disk: what a LOCEM started after a power loss knows is mounted.

Without a tool changer nothing tells LOCEM which tool a person mounted but MOUNT_TOOL itself; the tool stays on
the arm when the power goes. The LOCEM node (``~tool_file``) writes the tool's name here at every mount and reads
it at start when the ROS master has no ``~active_tool`` (the master went down too). ROS-free.

The file is one JSON object ``{"tool": name}``, written whole (a new file synced to the disk, renamed over the
old one), so it is never half written.
"""
import json

from locem_bridge.common.files import write_whole


def write_tool_file(path: str, tool: str) -> None:
    """Keep ``tool`` as the mounted tool in ``path`` (OSError when the disk refuses)."""
    write_whole(path, json.dumps({"tool": tool}))


def read_tool_file(path: str) -> str:
    """The tool kept in ``path``; '' when there is none (no file yet, or one that cannot be read: LOCEM then
    starts with no tool, as without the file, and MOUNT_TOOL tells it again)."""
    try:
        with open(path, encoding="utf-8") as handle:
            doc = json.load(handle)
    except (OSError, ValueError):
        return ""
    tool = doc.get("tool") if isinstance(doc, dict) else None
    return tool if isinstance(tool, str) else ""
