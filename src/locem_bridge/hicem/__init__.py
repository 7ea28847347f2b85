"""HICEM: the executive (ROS-free). Behavior trees loaded from BT.CPP 4 XML and ticked by py_trees (with
BT.CPP semantics), the node library, the data store (HDM volatile / HDICT SQLite), the data handler (HDH), the
health monitor (HEM) and the high-level controller loop (HHLC). See DESIGN.md and docs/contracts.md.

Main entry points: :func:`locem_bridge.hicem.executive.create_executive`,
:class:`locem_bridge.hicem.xml_loader.TreeLibrary`, :class:`locem_bridge.hicem.controller.HighLevelController`.
"""
from .errors import (ConfigError, ControllerError, DataStoreError, HealthError, HicemError, LocemError,
                     OperatorError, PemkreError, PortError, ScanFormatError, TreeLoadError)

__all__ = ["ConfigError", "ControllerError", "DataStoreError", "HealthError", "HicemError", "LocemError",
           "OperatorError", "PemkreError", "PortError", "ScanFormatError", "TreeLoadError"]
