"""The operator HMI (ROS-free): a small web server with the operator's page, and an automatic operator.

- :mod:`.backend` -- :class:`HmiBackend`, the Protocol the HMI needs from the executive (HICEM + PEMKRE); the ROS
  adapter ``locem_bridge.ros.operator_hmi`` implements it, tests implement it in process.
- :mod:`.server` -- :class:`HmiServer`: standard-library HTTP server (127.0.0.1, configurable port) serving the
  page (HTML/CSS/JS shipped in ``static/``, no external resources), the JSON API and Server-Sent Events.
- :mod:`.hub` -- :class:`StateHub`: polls the backend in one thread and pushes only changes.
- :mod:`.auto_operator` -- :class:`AutoOperator` / :class:`AutoOperatorPolicy`: answers prompts from
  configuration (tool mounted -> done after N s; line valid, except listed line ids -> invalid).
- :mod:`.hicem_view` -- pure functions: HICEM state -> HMI snapshot; wall pictures in a folder.
- :mod:`.health` -- the page's health line from HICEM's health monitor or from ``/diagnostics`` (levels of
  :mod:`locem_bridge.common.health`).
- :mod:`.pictures` -- :class:`SimPictures`: the simulated worksite's wall pictures, asked for at most every
  period and not again while nothing moves.
- :mod:`.pemkre_view` -- pure functions: processes from the ontologies, KPI/query rows from PEMKRE answers,
  taping progress.
- :mod:`.sim_hands` -- the simulated operator's hands: simulator operations an answer implies (mount the tool,
  tape a joint by hand) in the simulated worksite.
- :mod:`.executive_backend` -- :class:`ExecutiveBackend`: the backend over a HICEM executive in the same process.
- :mod:`.manual_work` -- :class:`ManualWorkLog`: the planned manual work (parts of areas and joints left for a
  person) named in HICEM's task reports, collected for the page's Manual work panel.
- :mod:`.errors` -- :class:`HmiError` and its subclasses.

JSON API
--------
All JSON bodies are UTF-8 objects. POSTs need ``Content-Type: application/json`` (body at most 64 KiB).

==========================================  ===================================================================
``GET  /``                                  the operator page
``GET  /api``                               list of endpoints
``GET  /api/state``                         ``{"version": n, "server_id": str, "snapshot": S, "prompts": [P],
                                            "processes": [R], "walls": [W], "kpis": K, "manual": [MW],
                                            "events": [E], "backend_error": str}`` (version grows on every
                                            change)
``GET  /api/events``                        ``text/event-stream``; an ``event: state`` whose ``data`` is the
                                            /api/state document, sent at connect and on every change; ``: ping``
                                            comments keep the stream alive; the stream ends after 5 min (the
                                            browser reconnects by itself)
``GET  /api/processes``                     ``{"processes": [R]}``
``POST /api/processes/start``               ``{"iri": str}`` -> ``{"ok": true, "started": iri, "result": ...}``
``POST /api/stop``                          ``{}`` (or no body, or anything) -> ``{"ok": true}`` (plus
                                            ``"ignored": [fields]`` when the body had some); never refused for
                                            its body (only Host/Origin checks apply)
``GET  /api/prompts``                       ``{"prompts": [P]}`` (open prompts only)
``POST /api/prompts/<id>/reply``            ``{"answer": str}`` -> ``{"ok": true, "prompt": id, "answer": str}``
``GET  /api/kpis``                          ``{"kpis": K}``
``GET  /api/walls``                         ``{"walls": [W]}``
``GET  /api/walls/<wall_id>.png``           ``image/png``, the wall's current picture
``GET  /api/manual``                        ``{"manual": [MW]}``: the planned manual work reported so far in this
                                            job (the backend's optional ``manual_work``; ``[]`` without it)
``GET  /api/match?process=<iri>``           ``{"match": M}``: PEMKRE's skill matching of an offered process
                                            (the backend's optional ``match_process``)
``POST /api/skill/<method>``                ``{"cause": str}`` (optional, or no body) -> ``{"ok": true,
                                            "method": str, "state": str, "allowed": [str], "message": str}``:
                                            ``suspend``, ``resume``, ``halt`` or ``reset`` HICEM's running action
                                            (the page's Pause, Resume, Abort, Reset; the backend's optional
                                            ``skill_method``); refused (409) when its skill state does not allow it
==========================================  ===================================================================

Shapes: S = ``{"process", "phase", "action", "skill", "tree", "node", "detail", "skill_state", "skill_detail": str,
"allowed": [str] (the skill methods accepted now: Suspend, Resume, Halt, Reset), "health": {"status": "ok" |
"degraded" | "fault" | "unknown", "detail": str}, "progress": {"done": int, "total": int, "text": str} | null}``;
P = ``{"id", "kind", "text": str, "choices": [str], "context": {...}}``; R = ``{"iri", "name", "description"}``;
W = ``{"id": wall_id, "version": token, "url": "/api/walls/<id>.png?v=<token>" | ""}`` (empty url: the picture
is not written yet); K = ``{table_name: [flat row objects]}``; E = ``{"time", "level", "text"}``;
MW = ``{"kind": "area" | "joint", "work": "spray" | "sand" | "tape", "feature": id, "part": int, "along": [a, b]
(m), "height": [c, d] (m) | null, "reason": str, "text": str, "task": IRI, "process": IRI}`` (see
:mod:`.manual_work`);
M = ``{"process", "robot", "robot_name", "ok", "tasks": [{"node", "task", "action_type", "task_type",
"capability", "ok", "chosen": {"kind": basic | composite | template, "name", "steps": [{"index", "name", "kind",
"capability", "arguments"}], "operator"} | null, "rejected": [{"name", "kind", "reason"}], "problem"}]}``.

Errors are ``{"error": {"status": int, "code": str, "message": str}}`` with: 400 ``malformed_json``,
``bad_body``, ``missing_body``, ``missing_field``, ``unknown_field`` (naming the fields), ``answer_not_allowed``,
``incomplete_body`` (fewer bytes than ``Content-Length`` within a few seconds); 403
``forbidden_host`` (loopback server asked for another Host), ``forbidden_origin`` (a request from a page served
elsewhere: another ``Origin``, or ``Sec-Fetch-Site`` cross-site/same-site on ``/api``); 404 ``not_found``
(unknown endpoint; the message lists the endpoints), ``unknown_process``, ``unknown_wall``,
``picture_not_ready``, ``no_matching`` (the backend offers no skill matching), ``unknown_skill_method``,
``no_skill_control`` (the backend offers no skill methods); 405 ``method_not_allowed``; 409
``prompt_not_open`` (answered, withdrawn or never asked; the message lists the open prompts), ``refused`` (the
backend declined, with its reason); 411/413/415 for body framing, size and type; 502 ``backend_error`` /
``bad_picture`` / ``bad_match``; 503 ``backend_unavailable``, ``too_many_streams`` (in all, or per client address). The server
keeps serving after any of them.

Run it against the robot with ``rosrun locem_bridge operator_hmi`` (default http://127.0.0.1:8088/, ``_mode:=web``:
the person answers; ``_mode:=auto``: the automatic operator answers and the page shows the job; ``_mode:=both``:
either answers; see ``locem_bridge.ros.operator_hmi``).
"""
from .auto_operator import (DEFAULT_CONFIG, AutoOperator, AutoOperatorConfig, AutoOperatorPolicy,  # noqa: F401
                            PromptRule)
from .backend import HmiBackend, normalize_prompt, normalize_snapshot  # noqa: F401
from .errors import (AutoOperatorConfigError, BackendRefused, BackendUnavailable, HmiError,  # noqa: F401
                     RequestError, ServerStartError)
from .executive_backend import ExecutiveBackend  # noqa: F401
from .health import DiagnosticsHealth, health_summary  # noqa: F401
from .hicem_view import snapshot_from_hicem, wall_pictures_in  # noqa: F401
from .manual_work import ManualWorkLog  # noqa: F401
from .pictures import SimPictures  # noqa: F401
from .hub import StateHub  # noqa: F401
from .server import HmiServer  # noqa: F401

__all__ = ["AutoOperator", "AutoOperatorConfig", "AutoOperatorConfigError", "AutoOperatorPolicy",
           "BackendRefused", "BackendUnavailable", "DEFAULT_CONFIG", "DiagnosticsHealth",
           "ExecutiveBackend", "HmiBackend", "HmiError", "HmiServer", "ManualWorkLog", "PromptRule", "RequestError",
           "ServerStartError", "SimPictures", "StateHub", "health_summary", "normalize_prompt",
           "normalize_snapshot", "snapshot_from_hicem", "wall_pictures_in"]
