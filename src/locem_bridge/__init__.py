"""locem_bridge: semantic process control for mobile manipulators.

Three layers, after the PEMKRE / HICEM / LOCEM architecture:

* :mod:`locem_bridge.pemkre` -- semantic layer (ontologies, process engine, KPIs)
* :mod:`locem_bridge.hicem`  -- executive (behavior trees, data store, health monitor)
* :mod:`locem_bridge.locem`  -- low level (one generic command-string interface)
* :mod:`locem_bridge.bridges` -- device backends (RTDE arm, Modbus compressor, CAN base)
* :mod:`locem_bridge.sim`    -- PyBullet worksite and protocol-level device stand-ins
* :mod:`locem_bridge.ros`    -- the only subpackage that imports rospy / generated messages
"""

__version__ = "0.1.0"
