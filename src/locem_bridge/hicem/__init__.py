"""HICEM: the executive (ROS-free). Behavior trees loaded from BT.CPP 4 XML and ticked by py_trees (with
BT.CPP semantics), the node library, the data store, the data handler, the health monitor and the high-level
controller loop. The data crossing to PEMKRE and LOCEM is in docs/contracts.md; the trees in trees/README.md.

The paper's modules (Fig. 3 of "A Flexible Mobile Manipulator Architecture: a Case Study on Plasterboard Wall
Preparation") and where each one is:

=====  ===========================  ==========================================================================
paper  name in the paper            module and class
=====  ===========================  ==========================================================================
HDH    HICEM Data Handler           :class:`.datahandler.DataHandler` (its ROS adapter: ``ros/hicem_locem``
                                    :class:`LocemHealthFeed`, started by ``ros/hicem_node``)
HDM    HICEM Data Manager           :class:`.datastore.DataManager`; its volatile database
                                    :class:`.datastore.MemoryStore`
HDICT  HICEM Dictionary             :class:`.datastore.SqliteStore` (non-volatile, SQLite)
HHLC   HICEM High Level Controller  :class:`.controller.HighLevelController` (its ROS adapter: ``ros/hicem_node``);
                                    its Behavior Tree Engine: :class:`.xml_loader.TreeLibrary` with
                                    :mod:`.controls` and the node library :mod:`.nodes`
HEM    HICEM Environment Monitor    :class:`.health.HealthMonitor` (called the health monitor here)
=====  ===========================  ==========================================================================

:mod:`.executive` assembles them from the HICEM parameters (``config/hicem/plasterboard.yaml``, :mod:`.config`).

Main entry points: :func:`locem_bridge.hicem.executive.create_executive`,
:class:`locem_bridge.hicem.xml_loader.TreeLibrary`, :class:`locem_bridge.hicem.controller.HighLevelController`.
"""
from .errors import (ConfigError, ControllerError, DataStoreError, HealthError, HicemError, LocemCallError,
                     OperatorError, PemkreCallError, PortError, ScanFormatError, TreeLoadError)

__all__ = ["ConfigError", "ControllerError", "DataStoreError", "HealthError", "HicemError", "LocemCallError",
           "OperatorError", "PemkreCallError", "PortError", "ScanFormatError", "TreeLoadError"]
