"""Where the package's own files are, found one way.

* :data:`PYTHON_ROOT` -- the folder that holds the ``locem_bridge`` Python package (``src/`` in a checkout). A
  helper process started with ``python -m locem_bridge...`` gets it on its ``PYTHONPATH`` (:func:`child_env`), so
  it imports the same code as its parent whatever the caller's environment holds.
* :func:`checkout_root` -- the folder that holds ``config/``, ``trees/`` and ``ontologies/`` next to ``src/``: the
  default place of the shipped configuration for the ROS-free layers. Under ROS the package's share folder is
  found by ``locem_bridge.ros.params.package_share`` (rospkg first, this folder when ROS does not know the package).
* :func:`shipped_dir` -- one shipped folder, in the checkout or in a catkin install's share folder.
"""
import os
from typing import Dict, Mapping, Optional

#: the folder holding the ``locem_bridge`` package: common/paths.py -> common -> locem_bridge -> its parent
PYTHON_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def checkout_root() -> str:
    """The package folder of a source checkout (parent of ``src/``): where ``config/``, ``trees/`` live."""
    return os.path.dirname(PYTHON_ROOT)


def shipped_dir(name: str) -> str:
    """The shipped folder ``name`` (``config``, ``trees``, ``ontologies``, ``docs``): in the source checkout, else in
    a catkin install's share folder (``<prefix>/share/locem_bridge``, the package beside
    ``<prefix>/lib/python3/dist-packages``); the checkout's path when neither exists (the caller reports it)."""
    candidates = (os.path.join(checkout_root(), name),
                  os.path.join(PYTHON_ROOT, "..", "..", "..", "share", "locem_bridge", name))
    for candidate in candidates:
        if os.path.isdir(candidate):
            return os.path.normpath(candidate)
    return candidates[0]


def child_env(env: Optional[Mapping[str, str]] = None) -> Dict[str, str]:
    """A copy of ``env`` (default: this process's) with :data:`PYTHON_ROOT` first on ``PYTHONPATH``."""
    out = dict(os.environ if env is None else env)
    out["PYTHONPATH"] = PYTHON_ROOT + (os.pathsep + out["PYTHONPATH"] if out.get("PYTHONPATH") else "")
    return out
