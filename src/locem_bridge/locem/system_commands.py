"""The system commands every LOCEM offers, whatever the robot: HELP, STATUS, STOP, WAIT, and the skill methods
SUSPEND, RESUME, HALT, RESET.

The skill methods act on the state machine of a running command (``id=``; without it, on every command whose
state allows the method): OPC UA ``ProgramStateMachineType``, :mod:`locem_bridge.common.program_state`. What
Suspend does on each device is in the API reference (``docs/api.md``, "Suspend and resume"). They are never BUSY.

``WAIT`` is a cancelable, pausable long-running command that touches no device: it is how the action and
procedure semantics are exercised without hardware. ``hold=`` lets it occupy a resource, so the resource
policy (``BUSY``, ``STOP``) can be shown on a machine without devices.
"""

import functools
from typing import Any, Dict, List

from ..common.program_state import Method, ProgramState
from .dispatcher import Dispatcher
from .errors import InvalidArgument
from .execution import CommandContext
from .registry import Arg, CommandSpec

STANDARD_RESOURCES = ("base", "arm", "compressor", "tool")
"""Resources of a mobile manipulator as LOCEM schedules them (one running command each)."""

MAX_WAIT_S = 3600.0
PROGRESS_STEPS = 20
"""A WAIT followed by an action client reports its progress in at most this many steps ..."""
PROGRESS_MIN_STEP_S = 0.05
"""... of at least this many seconds each."""

HELP = CommandSpec(
    "HELP", "List every command, or show one command's signature, units and ranges.",
    args=(Arg.command("name", "command to describe; all commands when omitted", default=""),),
    timeout=1.0, inline=True, query=True,
    result=(("commands", "all commands: name, usage, summary (without a name)"),
            ("command", "the described command: args with type, unit, range, default; interfaces; resources")),
)
STATUS = CommandSpec(
    "STATUS", "Report running commands, occupied resources and the health of every backend.",
    timeout=1.0, inline=True, query=True,
    result=(("running", "commands running now: id, command, state, progress, elapsed_s, resources"),
            ("resources", "occupied resource -> command id"),
            ("health", "per backend: link state, device state, last error"),
            ("uptime_s", "seconds since LOCEM started")),
)
STOP = CommandSpec(
    "STOP", "Stop every running command and every device now; always accepted, never BUSY.",
    timeout=5.0, preemptive=True, inline=True,
    result=(("stopped", "ids of the commands that were cancelled"),
            ("still_running", "ids whose handlers had not returned when STOP answered"),
            ("hook_errors", "device stops that failed")), capability="sk:cap_StopAll")
WAIT = CommandSpec(
    "WAIT", "Wait for a time; cancelable and pausable (pause time does not count).",
    args=(Arg.number("seconds", "s", 0.0, MAX_WAIT_S, "time to wait"),
          Arg.choice("hold", ("none",) + STANDARD_RESOURCES, "resource to occupy while waiting",
                     default="none", keyword_only=True)),
    timeout=MAX_WAIT_S + 5.0, pausable=True,
    claims=lambda values: frozenset() if values["hold"] == "none" else frozenset({values["hold"]}),
    deadline=lambda values: float(values["seconds"]) + 5.0,
    result=(("waited_s", "seconds waited, pauses excluded"),), capability="sk:cap_Wait")

MAX_ID = 2 ** 31 - 1


def _method_spec(name: str, summary: str, result: str) -> CommandSpec:
    return CommandSpec(
        name, summary,
        args=(Arg.integer("id", 0, MAX_ID, "the command id (STATUS lists them; /locem/status carries them); 0: every "
                          "command whose state allows it", default=0),
              Arg.word("cause", "who asks or why, recorded with the transition", default="", keyword_only=True)),
        timeout=5.0, preemptive=True, inline=True,
        result=(("ids", result), ("states", "command id -> its skill state after the call")),
        capability="")


SUSPEND = _method_spec("SUSPEND", "Suspend a running command: its devices come to rest where they are, the tool "
                       "process pauses; RESUME goes on from there.", "the commands suspended")
RESUME = _method_spec("RESUME", "Resume a suspended command from where its devices stopped.", "the commands resumed")
HALT = _method_spec("HALT", "Halt a running or suspended command: it ends ABORTED 'halted', its devices safe.",
                    "the commands halted")
RESET = _method_spec("RESET", "Reset a halted (or failed) command's skill instance to Ready.", "the commands reset")

SKILL_METHODS = (SUSPEND, RESUME, HALT, RESET)
"""The methods of every skill's state machine, not skills themselves (the resource model leaves them out)."""
SPECS = (HELP, STATUS, STOP, WAIT) + SKILL_METHODS


class SystemCommands:
    """Binds the system handlers to a dispatcher (they need its registry and its state)."""

    def __init__(self, dispatcher: Dispatcher) -> None:
        self._dispatcher = dispatcher
        registry = dispatcher.registry
        for spec in SPECS:
            registry.declare(spec)
        registry.bind("HELP", self.help)
        registry.bind("STATUS", self.status)
        registry.bind("STOP", self.stop)
        registry.bind("WAIT", self.wait)
        for method in (Method.SUSPEND, Method.RESUME, Method.HALT, Method.RESET):
            registry.bind(method.value.upper(), functools.partial(self.skill_method, method))

    def help(self, ctx: CommandContext, name: str) -> Dict[str, Any]:
        registry = self._dispatcher.registry
        if name:  # a declared name: an unknown one is refused when the command is bound, on every interface
            spec = registry.lookup(name)
            return {"message": describe(spec, registry.handler(spec.name) is not None), "command": spec.describe()}
        lines: List[str] = []
        commands = []
        for spec in registry.specs():
            served = registry.handler(spec.name) is not None
            lines.append("%-44s %s%s" % (spec.usage, spec.summary, "" if served else "  [not served here]"))
            commands.append({"name": spec.name, "usage": spec.usage, "summary": spec.summary,
                             "category": spec.category, "served": served})
        text = "%d commands (HELP NAME for units and ranges):\n%s" % (len(commands), "\n".join(lines))
        return {"message": text, "commands": commands}

    def status(self, ctx: CommandContext) -> Dict[str, Any]:
        report = self._dispatcher.status(exclude=ctx.id)
        resources = report["resources"]
        busy = ", ".join("%s: %d" % item for item in sorted(resources.items())) if resources else "all resources idle"
        report["message"] = "%d running; %s" % (len(report["running"]), busy)
        return report

    def stop(self, ctx: CommandContext) -> Dict[str, Any]:
        outcome = self._dispatcher.stop_all("stopped by STOP")
        outcome["message"] = "stopped %d command(s)%s" % (
            len(outcome["stopped"]),
            "; still finishing: %s" % outcome["still_running"] if outcome["still_running"] else "")
        return outcome

    def skill_method(self, method: Method, ctx: CommandContext, id: int, cause: str) -> Dict[str, Any]:
        dispatcher = self._dispatcher
        cause = cause or "%s command" % method.value.upper()
        if id:
            execution = dispatcher.control(id, method, cause)
            return {"message": "%s: %s" % (execution.bound.name, execution.program.value), "ids": [id],
                    "states": {str(id): execution.program.value}}
        wanted = _FROM[method]
        targets = [e for e in dispatcher.running() if e.id != ctx.id and e.program in wanted
                   and (method is not Method.SUSPEND or e.bound.spec.pausable) and not e.bound.spec.query]
        if not targets:
            raise InvalidArgument("%s: no running command is %s%s; name one with id=N (STATUS lists them)"
                                  % (method.value.upper(), " or ".join(s.value for s in wanted),
                                     " and suspendable" if method is Method.SUSPEND else ""), argument="id")
        for execution in targets:
            dispatcher.control(execution.id, method, cause)
        return {"message": "%s: %s" % (method.value.lower(), ", ".join("%s %d" % (e.bound.name, e.id)
                                                                       for e in targets)),
                "ids": [e.id for e in targets], "states": {str(e.id): e.program.value for e in targets}}

    def wait(self, ctx: CommandContext, seconds: float, hold: str) -> Dict[str, Any]:
        # one sleep on the execution's event (woken at once by cancel, STOP, pause); only a caller that follows
        # progress (an action goal) gets it, in at most PROGRESS_STEPS steps of at least PROGRESS_MIN_STEP_S
        if not ctx.follows_progress or seconds <= 0.0:
            ctx.sleep(seconds)
            return {"waited_s": round(seconds, 6)}
        step = max(seconds / PROGRESS_STEPS, PROGRESS_MIN_STEP_S)
        waited = 0.0
        while waited < seconds:
            chunk = min(step, seconds - waited)
            ctx.sleep(chunk)
            waited += chunk
            ctx.report(waited / seconds, "waited %.2f of %.2f s" % (waited, seconds))
        return {"waited_s": round(waited, 6)}


_FROM = {Method.SUSPEND: (ProgramState.RUNNING,), Method.RESUME: (ProgramState.SUSPENDED,),
         Method.HALT: (ProgramState.RUNNING, ProgramState.SUSPENDED), Method.RESET: (ProgramState.HALTED,)}


def describe(spec: CommandSpec, served: bool = True) -> str:
    """Multi-line human description of one command (used by ``HELP NAME`` and the API documentation)."""
    lines = ["%s -- %s" % (spec.usage, spec.summary)]
    for arg in spec.args:
        default = "" if arg.required else " (default %s)" % (arg.default if arg.default != "" else '""')
        lines.append("  %-10s %s; %s%s" % (arg.name, arg.doc, arg.allowed(), default))
    lines.append("  interfaces: %s" % ", ".join(sorted(i.value for i in spec.interfaces)))
    lines.append("  resources: %s" % (", ".join(sorted(spec.resources)) or
                                      ("chosen by arguments" if spec.claims else "none")))
    lines.append("  timeout: %.6g s%s" % (spec.timeout, " (computed from arguments)" if spec.deadline else ""))
    if spec.result:
        lines.append("  result: " + "; ".join("%s = %s" % item for item in spec.result))
    if not served:
        lines.append("  not served by this LOCEM (no backend configured)")
    return "\n".join(lines)
