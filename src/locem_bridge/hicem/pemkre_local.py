"""In-process PEMKRE client: drives a PEMKRE process engine object directly (no ROS), e.g. for a single-process
run or integration tests. Duck-typed on the engine's methods (``start_process(iri, options)``,
``next_action()`` returning the :class:`~locem_bridge.common.next_action.NextAction` record, ``set_task_status``,
``update_world``), so HICEM does not import the semantic layer; any engine error becomes :class:`PemkreCallError`.
"""
from typing import Any, Dict, Optional

from ..common.next_action import NextAction
from .errors import PemkreCallError
from .interfaces import PemkreClient, status_request_id


class EngineClient(PemkreClient):
    def __init__(self, engine: Any) -> None:
        self.engine = engine

    def _call(self, what: str, fn: Any, *args: Any) -> Any:
        try:
            return fn(*args)
        except PemkreCallError:
            raise
        except Exception as exc:  # the engine's own error hierarchy, whatever it is
            raise PemkreCallError("PEMKRE %s: %s: %s" % (what, type(exc).__name__, exc))

    def start_process(self, process_iri: str, options: Optional[Dict[str, Any]] = None) -> str:
        # as the ROS client: a new start replaces a process left running by a stop before its first task
        return str(self._call("start_process", lambda: self.engine.start_process(process_iri, options or {},
                                                                                 abort_running=True)))

    def next_action(self) -> NextAction:
        return self._call("next_action", self.engine.next_action)

    def set_task_status(self, task: str, status: str, detail: str = "") -> None:
        # with the ROS client's request id: a report repeated after HICEM's own restart is applied once
        self._call("set_task_status", lambda: self.engine.set_task_status(
            task, status, detail, request_id=status_request_id(task, status)))

    def report_world(self, update: Dict[str, Any]) -> None:
        self._call("update_world", self.engine.update_world, update)
