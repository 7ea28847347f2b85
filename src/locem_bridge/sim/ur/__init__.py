"""UR e-Series controller stand-in: dashboard (29999), script (30003) and RTDE (30004) servers in Python.

The REAL ur_rtde clients (RTDEControlInterface, RTDEReceiveInterface, RTDEIOInterface, DashboardClient) connect
to it with default flags. The uploaded ur_rtde control script is not interpreted: once its text has arrived the
runtime state becomes PLAYING and the register command protocol is served in Python (see :mod:`.arm`), with UR
motion semantics (:mod:`.motion`) and pinocchio kinematics (:mod:`.kinematics`).

API for the world (PyBullet) and for tests::

    from locem_bridge.sim.ur import UrControllerStandIn

    ur = UrControllerStandIn("127.0.0.2", time_scale=5.0, model="ur10e")  # or a URDF path; nothing bound yet
    ur.start()                     # binds 127.0.0.2:29999/30003/30004, starts I/O + 500 Hz control threads
    ur.get_joint_positions()       # actual q (rad), list of 6
    ur.get_joint_velocities()      # actual qd (rad/s of motion time)
    ur.get_tcp_pose()              # [x, y, z, rx, ry, rz] in the UR base frame, TCP offset applied
    ur.get_tcp_offset()            # current TCP offset (set by the client's setTcp)
    ur.get_standard_digital_outputs()   # [bool] * 8   (RTDEIOInterface.setStandardDigitalOut)
    ur.get_configurable_digital_outputs()  # [bool] * 8
    ur.get_tool_digital_outputs()       # [bool] * 2   (RTDEIOInterface.setToolDigitalOut)
    ur.set_standard_digital_input(i, v) / ur.set_tool_digital_input(i, v)
    ur.get_state()                 # robot/safety/runtime modes, program, moving, motion_time, last_error
    ur.add_step_listener(fn)       # fn(ArmSnapshot) after every control cycle, on the control thread
    ur.inject_protective_stop("collision with wall_1")   # e.g. from the world's collision check
    ur.inject_emergency_stop(); ur.release_emergency_stop()
    ur.set_joint_positions(q)      # teleport while idle (scene setup)
    ur.set_contact_provider(fn, stiffness=20000.0)  # fn(tcp_pose) -> None | (depth m, outward normal), base frame
    ur.set_contact_planes([{"point": [..], "normal": [..]}])   # the same with flat surfaces (works through a pipe)
    ur.get_tcp_force()             # actual_TCP_force as streamed (contact force on the tool minus the FT zero)
    ur.get_force_mode()            # parameters of the active force mode and its TCP offset, or None
    ur.refused                     # log of refused bad input (malformed packages, garbage lines, ...)
    ur.stop()                      # closes sockets, joins threads; start() again to restart

Threads and the GIL: ur_rtde's Python bindings keep the GIL while a client call blocks in C++ (the connection
handshake, waiting for a move), so a stand-in in the SAME interpreter as a ur_rtde client starves. Run clients and
stand-in in different processes: :class:`~locem_bridge.sim.ur.process.StandInProcess` starts one in a child process
and proxies the API above over a pipe (``python -m locem_bridge.sim.ur --address ...`` runs one from a shell).
In-process users (the world) should keep listeners short and ``sys.setswitchinterval(0.0005)`` helps the 500 Hz
control thread get the GIL on time next to other busy threads (the child process sets it).

``ArmSnapshot`` fields: motion_time, q, qd (numpy copies), tcp_pose, tcp_speed (tuples), standard_digital_out,
configurable_digital_out, tool_digital_out (bit masks), robot_mode, safety_mode, runtime_state, moving.

Time scale: motion time advances ``time_scale`` times faster than the wall clock (1.0 = hardware-like; the speed
slider of RTDEIOInterface scales it further) while the RTDE streams keep their wall-clock rate (500 Hz for the
reported 5.11 controller). Velocities are per second of motion time.

Safety, as on a real UR: an injected protective stop stops the arm, sets the protective bits of
safety_status_bits and pauses the program, so a waiting client call returns False; only the dashboard's
``unlock protective stop`` (accepted 5 s of motion time after the stop) clears it and resumes the control program.
An emergency stop powers the arm off and stops the program; recover with release_emergency_stop(), then dashboard
``close safety popup``, ``power on``, ``brake release``, and the client's ``reuploadScript()``/``reconnect()``.

Model: ``ur10e`` by default (e-Series DH geometry on example-robot-data's UR10 URDF, see
:func:`e_series_urdf_xml`), or ``ur5e``, ``ur10``, ``ur5``, ``ur3``, or any URDF path (the world passes its own URDF
so that PyBullet and the stand-in agree).

Path moves (ur_rtde ``moveL(path)`` / ``moveJ(path)`` / ``movePath``): the client re-uploads the control script
with the waypoints injected into ``exec_move_path`` (:mod:`.script_path` reads them) and sends command 45; the path
runs with UR blend semantics (:mod:`.blended`: straight segments, circular blends within each waypoint's radius, per
waypoint speed and acceleration, stops where the radius is 0), after checking every waypoint first.

Force mode (ur_rtde ``forceMode`` 6, ``forceModeStop`` 7, ``zeroFtSensor`` 8, output ``actual_TCP_force``): a
stiff-spring contact with the surfaces of an injected contact provider and admittance control along the selected
translation axes of the task frame, speed-limited (:mod:`.force`; type 2 only).

Known simplifications: a new motion command replaces the current one from the current position (no blending
between separate commands, no velocity continuity), no dynamics (actual = target, zero currents; forces only from
the contact model), force-mode types 1 and 3, compliance about rotation axes, freedrive and contact detection
(moveUntilContact) are not emulated (the program halts with a message naming it), port 30003 does not stream the
realtime state package, URScript other than the ur_rtde control script is accepted but not run.
"""
from .arm import ArmSnapshot
from .controller import UrControllerStandIn
from .errors import ConfigurationError, KinematicsError, ListenError, ScriptRuntimeError, UrStandInError
from .kinematics import ArmKinematics, e_series_urdf_xml

__all__ = ["UrControllerStandIn", "ArmSnapshot", "ArmKinematics", "e_series_urdf_xml", "UrStandInError",
           "ConfigurationError", "KinematicsError", "ListenError", "ScriptRuntimeError"]
