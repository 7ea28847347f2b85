"""Device backends behind LOCEM: UR arm over RTDE, compressor and tool changer over Modbus TCP, mobile base over CAN
(CiA 402).

Layout (one concept per module):

* :mod:`.errors`      one exception hierarchy; every error carries the LOCEM code it maps to;
* :mod:`.config`      the robot YAML as the bridges read it (addresses, ports, CAN ids, tools, named poses);
* :mod:`.interfaces`  the whole interface of each device kind (arm, compressor, base, scanner, tool changer) with its
  optional capability groups; the command sets use nothing else of a backend;
* :mod:`.backends`    the name -> backend table, imported lazily (no device library is loaded until used);
* :mod:`.ur_arm` + :mod:`.ur_worker`  ur_rtde in a supervised child process;
* :mod:`.modbus_compressor`  pymodbus client with polling, retries and the valve-closed-on-return rule;
* :mod:`.modbus_tool_changer`  the same pattern for the tool changer (a coupled tool stays locked on return);
* :mod:`.cia402_base` + :mod:`locem_bridge.common.base_kinematics` + :mod:`locem_bridge.common.can_bus`  the wheel drives
  (mecanum: four, differential: two) through canopen's ``BaseNode402``;
* :mod:`.cia402_lift`  the lift carrying the arm: one CiA 402 drive in profile position mode on the base's bus;
* :mod:`.sim_scanner`  the SCAN source of the simulated worksite (perception stand-in on the site YAML);
* :mod:`.geometry`    frames map -> base_footprint -> UR base, the wall-facing TCP frame (rotations:
  :mod:`locem_bridge.common.geometry`);
* :mod:`.commands_*`  LOCEM declarations (``SPECS``, listed in :mod:`locem_bridge.locem.catalogue`) and the
  command sets that bind them to a backend; :mod:`.commands_wall` composes the plasterboard commands;
* :mod:`.robot`       builds every configured backend and command set from one robot YAML.

Nothing here imports ROS; :mod:`locem_bridge.ros.locem_devices` publishes the bridges' state.
"""
