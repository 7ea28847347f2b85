"""The simulated worksite: a PyBullet plasterboard site and protocol-level device stand-ins (RTDE, Modbus, CANopen).

Modules (ROS-free; the ROS node ``sim_worksite`` wraps :class:`locem_bridge.sim.worksite.Worksite`):

* :mod:`.config`        load + validate ``config/sites/*.yaml`` and ``config/robots/*.yaml``
* :mod:`.site`          ground-truth walls, joints, areas (SCAN contract shapes)
* :mod:`.world`         the PyBullet world: room, robot (mecanum or differential base, pedestal or lift, UR arm), tools, collisions
* :mod:`.outcome`       tape per joint, spray thickness map, sanded map, wall pictures
* :mod:`.perception`    SCAN stand-in: visible features with configurable noise
* :mod:`.modbus`        compressor stand-in: pressure model + register map (:mod:`.modbus.compressor`), Modbus TCP
  server for the installed pymodbus (:mod:`.modbus.modbus_server`, 3.16 or 3.6 via :mod:`.modbus.modbus_legacy`)
* :mod:`.can`           base stand-ins: four CiA 402 drives (:mod:`.can.drives`), their heartbeats from a helper
  process (:mod:`.can.heartbeat`)
* :mod:`locem_bridge.common.base_kinematics` (shared with the base bridge) base kinematics, mecanum and differential
* :mod:`.arm_source`    where the world gets the arm state (UR stand-in adapter, scripted arm)
* :mod:`.clock`         sim time with a time scale
* :mod:`.worksite`      composition of everything; ``python3 -m locem_bridge.sim`` runs it
* :mod:`.ur`            UR controller stand-in (dashboard, script, RTDE)
"""
