"""Dashboard server command set (port 29999): one text line in, one text line out, as PolyScope 5.

:class:`Dashboard` answers with the strings a real e-Series controller uses (the ones ur_rtde's DashboardClient
checks, e.g. ``Protective stop releasing``, ``Stopped``, ``Starting program``); anything it does not know is answered
``could not understand: '<line>'`` and logged as refused.
"""
from typing import Callable, Tuple

from .arm import (ROBOT_MODE_NAMES, RUNTIME_PAUSED, RUNTIME_PLAYING, SAFETY_MODE_NAMES, ArmCore)


class Dashboard:
    """Stateless translator from dashboard lines to :class:`ArmCore` calls."""

    def __init__(self, arm: ArmCore, polyscope_version: str, robot_model: str,
                 refuse: Callable[[str], None]) -> None:
        self.arm = arm
        self.polyscope_version = polyscope_version
        self.robot_model = robot_model
        self.refuse = refuse
        self.popup_text = ""

    def program_name(self) -> str:
        prog = self.arm.program
        return "<unnamed>" if prog is None else prog.name

    def answer(self, line: str) -> Tuple[str, bool]:
        """Reply to one command line; the bool is False when the server closes the connection (``quit``)."""
        arm = self.arm
        cmd = " ".join(line.split())
        low = cmd.lower()
        if low == "quit":
            return "Disconnected", False
        if low == "polyscopeversion":
            return "URSoftware %s (Jun 15 2022)" % self.polyscope_version, True
        if low == "version":
            return "Version information: %s" % self.polyscope_version, True
        if low == "get serial number":
            return arm.serial_number, True
        if low == "get robot model":
            return self.robot_model, True
        if low == "robotmode":
            return "Robotmode: %s" % ROBOT_MODE_NAMES.get(arm.robot_mode, "UNKNOWN"), True
        if low == "safetymode":
            return "Safetymode: %s" % SAFETY_MODE_NAMES.get(arm.safety_mode, "UNDEFINED_SAFETY_MODE"), True
        if low == "safetystatus":
            return "Safetystatus: %s" % SAFETY_MODE_NAMES.get(arm.safety_mode, "UNDEFINED_SAFETY_MODE"), True
        if low == "programstate":
            state = {RUNTIME_PLAYING: "PLAYING", RUNTIME_PAUSED: "PAUSED"}.get(arm.runtime_state, "STOPPED")
            return "%s %s" % (state, self.program_name()), True
        if low == "running":
            return "Program running: %s" % ("true" if arm.runtime_state == RUNTIME_PLAYING else "false"), True
        if low == "is in remote control":
            return "true" if arm.remote_control else "false", True
        if low == "power on":
            arm.power_on()
            return "Powering on", True
        if low == "power off":
            arm.power_off()
            return "Powering off", True
        if low == "brake release":
            arm.brake_release()
            return "Brake releasing", True
        if low == "unlock protective stop":
            return arm.unlock_protective_stop(), True
        if low == "close safety popup":
            arm.close_safety_popup()
            return "closing safety popup", True
        if low == "restart safety":
            arm.close_safety_popup()
            arm.power_off()
            return "Restarting safety", True
        if low == "stop":
            # PolyScope answers "Stopped" also when nothing runs (ur_rtde relies on it when it replaces a
            # control script it finds running: stopScript, then dashboard stop).
            arm.stop_program()
            return "Stopped", True
        if low == "pause":
            return ("Pausing program" if arm.pause_program() else "Failed to execute: pause"), True
        if low == "play":
            return ("Starting program" if arm.play_program() else "Failed to execute: play"), True
        if low.startswith("popup "):
            self.popup_text = cmd[6:]
            return "showing popup", True
        if low == "close popup":
            self.popup_text = ""
            return "closing popup", True
        if low == "get loaded program":
            return "No program loaded", True
        if low.startswith("load "):
            return "File not found: %s" % cmd[5:], True
        if low == "isprogramsaved":
            return "false %s" % self.program_name(), True
        if low.startswith("addtolog "):
            return "Added log message", True
        if low == "get operational mode":
            return "NONE", True
        if low == "shutdown":
            # The stand-in is stopped through its Python API, never by a client.
            return "Shutting down", True
        self.refuse("dashboard: could not understand %r" % line[:200])
        return "could not understand: '%s'" % line, True
