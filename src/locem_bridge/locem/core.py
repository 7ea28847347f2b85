"""Composition root of the LOCEM core: registry + dispatcher + system commands + procedure queue.

ROS adapters, tests and benchmarks all build LOCEM the same way::

    core = LocemCore()          # system commands only
    core.dispatcher.execute("HELP")
    core.close()

Bridges add their commands with ``core.install(command_set)`` before serving.
"""

from typing import Any, Dict, Iterable, Optional, Protocol

from .dispatcher import DEFAULT_MAX_RUNNING, Dispatcher
from .procedures import ProcedureManager
from .registry import CommandRegistry, CommandSpec
from .system_commands import SystemCommands


class CommandSet(Protocol):
    """What a bridge hands to LOCEM: declarations, bound handlers, a device stop and a health report."""

    name: str

    def specs(self) -> Iterable[CommandSpec]: ...

    def handlers(self) -> Dict[str, Any]: ...

    def stop(self) -> None: ...

    def health(self) -> Dict[str, Any]: ...


class LocemCore:
    """Owns the dispatcher and the procedure queue; ``close()`` stops everything."""

    def __init__(self, grace: float = 1.0, stop_timeout: float = 2.0,
                 registry: Optional[CommandRegistry] = None, max_running: int = DEFAULT_MAX_RUNNING) -> None:
        self.registry = registry or CommandRegistry()
        self.dispatcher = Dispatcher(self.registry, grace=grace, stop_timeout=stop_timeout, max_running=max_running)
        self.system = SystemCommands(self.dispatcher)
        self.procedures = ProcedureManager(self.dispatcher)

    def install(self, command_set: CommandSet) -> None:
        for spec in command_set.specs():
            self.registry.declare(spec)
        for name, handler in command_set.handlers().items():
            self.registry.bind(name, handler)
        self.dispatcher.add_stop_hook(command_set.name, command_set.stop)
        self.dispatcher.add_health_source(command_set.name, command_set.health)

    def close(self) -> None:
        self.procedures.close()
        self.dispatcher.close()
