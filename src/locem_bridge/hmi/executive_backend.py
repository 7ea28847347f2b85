"""An :class:`~locem_bridge.hmi.backend.HmiBackend` over a HICEM executive in the same process (no ROS).

For ROS-free runs (a main job without a ROS master, tests of the HMI with the real executive) this adapter
hands the HMI HICEM's own objects: the high-level controller (start, stop, state, operator replies, the running
action's skill methods), its operator desk (prompts) and its health monitor; the planned manual work its tasks
report is collected from the controller's state listener (:class:`~locem_bridge.hmi.manual_work.ManualWorkLog`:
every state, not only the polled ones). What HICEM does not know -- the processes to offer, KPIs, wall
pictures, progress -- comes from injected callables. Lifecycle: construct with the executive's parts; nothing
to close (it owns nothing).
"""
from typing import Any, Callable, Dict, List, Optional, Sequence

from ..hicem.errors import HicemError
from .errors import BackendRefused
from .hicem_view import snapshot_from_hicem
from .manual_work import ManualWorkLog

KpiSource = Callable[[], Dict[str, List[Dict[str, Any]]]]
PictureSource = Callable[[], Dict[str, Any]]
ProgressSource = Callable[[], Optional[Dict[str, Any]]]
MatchSource = Callable[[str], Any]


class ExecutiveBackend:
    """HmiBackend over ``controller`` (HighLevelController), ``operator`` (OperatorDesk), ``health``
    (HealthMonitor, optional). ``processes`` lists what may be started (``{"iri", "name", "description"}``);
    ``match`` (optional) answers the page's skill matching of a process (``ProcessMatch.to_dict()`` of PEMKRE)."""

    def __init__(self, controller: Any, operator: Any, health: Any = None,
                 processes: Sequence[Dict[str, Any]] = (), kpis: Optional[KpiSource] = None,
                 pictures: Optional[PictureSource] = None, progress: Optional[ProgressSource] = None,
                 stop_reason: str = "STOP pressed on the operator HMI", match: Optional[MatchSource] = None) -> None:
        self.controller = controller
        self.operator = operator
        self.health = health
        self.processes = [dict(p) for p in processes]
        self._kpis = kpis
        self._pictures = pictures
        self._progress = progress
        self.stop_reason = stop_reason
        # the page offers skill matching only when something can answer it (None: the server answers 404)
        self.match_process: Optional[MatchSource] = (
            (lambda iri: self._refused(match, iri)) if match is not None else None)
        self.manual = ManualWorkLog()
        listen = getattr(controller, "add_state_listener", None)
        self._manual_listening = listen is not None
        if listen is not None:
            listen(self.manual.update)

    @classmethod
    def for_executive(cls, executive: Any, **kw: Any) -> "ExecutiveBackend":
        """From a :class:`locem_bridge.hicem.executive.Executive` (controller, operator and health taken from it)."""
        return cls(executive.controller, executive.operator, executive.health, **kw)

    def list_processes(self) -> List[Dict[str, Any]]:
        return [dict(p) for p in self.processes]

    def start_process(self, iri: str) -> Any:
        try:
            self.controller.start_process(iri)
        except HicemError as err:
            raise BackendRefused(str(err))
        return None

    def stop(self) -> None:
        self.controller.stop(self.stop_reason)

    def snapshot(self) -> Dict[str, Any]:
        modules = self.health.snapshot() if self.health is not None else None
        progress = self._progress() if self._progress is not None else None
        state = self.controller.state()
        if not self._manual_listening:          # a controller without state listeners: the polled states
            self.manual.update(state)
        return snapshot_from_hicem(state, modules, progress)

    def manual_work(self) -> List[Dict[str, Any]]:
        """The planned manual work HICEM's tasks reported so far (:meth:`ManualWorkLog.items`)."""
        return self.manual.items()

    def skill_method(self, method: str, cause: str = "") -> Dict[str, Any]:
        """Suspend / Resume / Halt / Reset on the controller's running action; BackendRefused with its refusal."""
        try:
            state = self.controller.skill_method(method, cause or "%s pressed on the operator HMI" % method)
        except HicemError as err:
            raise BackendRefused(str(err))
        st = self.controller.state()
        return {"state": state.value, "allowed": list(st.get("allowed") or []),
                "message": str(st.get("skill_detail", "") or "")}

    def prompts(self) -> List[Dict[str, Any]]:
        return [p.as_dict() for p in self.operator.open_prompts()]

    def reply(self, prompt_id: str, answer: str) -> None:
        try:
            self.controller.operator_reply(prompt_id, answer)
        except HicemError as err:
            raise BackendRefused(str(err))

    def kpis(self) -> Dict[str, List[Dict[str, Any]]]:
        return self._kpis() if self._kpis is not None else {}

    def wall_pictures(self) -> Dict[str, Any]:
        return self._pictures() if self._pictures is not None else {}

    @staticmethod
    def _refused(match: MatchSource, iri: str) -> Any:
        """``match(iri)`` (e.g. ``lambda iri: engine.match_process(iri).to_dict()``); whatever it raises (PEMKRE's
        refusals: no resource model, unknown process) is shown to the operator as a refusal naming the error."""
        try:
            return match(iri)
        except Exception as err:  # noqa: BLE001 - PEMKRE's error classes are not imported into the HMI core
            raise BackendRefused("%s: %s" % (type(err).__name__, err))
