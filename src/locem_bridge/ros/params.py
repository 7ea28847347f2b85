"""The ROS adapters' one way to read a parameter and to find the package's folder.

- :func:`param`: a node's parameter (private ``~name`` by default). Unset, or an empty string (what a launch file
  passes for an argument left at its default), means ``default``. A ``bool``, ``int``, ``float`` or ``str``
  default types the value: it is converted to that type, and a value that is not one raises ValueError naming the
  parameter, the value and the type wanted (the nodes turn it into one fatal line).
- :func:`as_list`: a list parameter given as a YAML list or as one comma-separated text.
- :func:`package_share`: the package folder holding ``config/``, ``trees/``, ``ontologies/``, ``launch/``: ROS's
  ``locem_bridge`` package path, or the source checkout this file lives in outside a sourced workspace.

rospy is imported on first use, so a command-line tool may find the package folder without loading ROS.
"""
from typing import Any, List

from locem_bridge.common.paths import checkout_root

_TRUE = ("true", "1", "yes", "on")
_FALSE = ("false", "0", "no", "off")
_KIND = {bool: "true or false", int: "an integer", float: "a number", str: "a text"}


def typed(name: str, value: Any, default: Any) -> Any:
    """``value`` converted to the type of ``default`` (bool, int, float, str; any other default: as it is)."""
    kind = type(default)
    if kind not in _KIND or isinstance(value, kind) and not (kind is int and isinstance(value, bool)):
        return value
    try:
        if kind is bool:
            text = str(value).strip().lower()
            if text in _TRUE or text in _FALSE:
                return text in _TRUE
            raise ValueError(text)
        if kind in (int, float) and isinstance(value, bool):
            raise ValueError(value)
        if kind is int and isinstance(value, float):
            if not value.is_integer():
                raise ValueError(value)
            return int(value)
        return kind(value)
    except (TypeError, ValueError):
        raise ValueError("%s must be %s, got %r" % (name, _KIND[kind], value))


def param(name: str, default: Any = None, private: bool = True) -> Any:
    """The parameter ``~name`` (``name`` in the node's namespace when not ``private``); see the module docstring."""
    import rospy
    key = ("~" + name) if private else name
    value = rospy.get_param(key, default)
    if value is None or value == "":
        return default
    return typed(key, value, default)


def as_list(value: Any) -> List[str]:
    """``["a", "b"]`` for ``"a, b"`` or ``["a", "b"]``; ``[]`` for None or an empty text."""
    if isinstance(value, str):
        return [v.strip() for v in value.split(",") if v.strip()]
    return [str(v) for v in (value or [])]


def package_share() -> str:
    """The package folder (see the module docstring)."""
    try:
        import rospkg
        return str(rospkg.RosPack().get_path("locem_bridge"))
    except Exception:  # noqa: BLE001 - no ROS package path (rospkg missing or the package not found): the checkout
        return checkout_root()
