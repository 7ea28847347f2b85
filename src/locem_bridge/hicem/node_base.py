"""Base classes shared by every HICEM tree node, and the context that carries the injected handles.

Lifecycle (py_trees, driven by the BT.CPP-semantics controls in :mod:`.controls`):
``initialise()`` when a node is ticked while not RUNNING, ``update()`` on every tick, ``terminate(status)`` when
it finishes or is halted (``INVALID`` = halted from above: cancel whatever was started). Leaves implement
``on_start()`` / ``on_tick()`` / ``on_halt()`` instead; any :class:`HicemError` (bad port value, data missing,
LOCEM refused) becomes ``FAILURE`` with the reason recorded in :attr:`NodeContext.failures`, so the controller
can tell PEMKRE *why* an action failed.

Node classes declare ``PORTS`` (a tuple of :class:`~.ports.PortSpec`), ``KIND`` (Action, Condition, Control,
Decorator) and ``DESCRIPTION``; the XML loader validates trees against these declarations and the Groot2
catalogue is generated from them.
"""
import logging
import threading
import time
from typing import Any, Callable, List, Optional, Sequence, Set, Tuple

import py_trees
from py_trees.common import Status

from .errors import HicemError
from .ports import PortBinding, PortSpec

LOG = logging.getLogger("locem_bridge.hicem")


class NodeContext:
    """Handles a tree's nodes may use, injected once per tree instance by whoever builds the tree.

    ``locem``: a :class:`~.interfaces.LocemClient`; ``store``: the :class:`~.datastore.DataManager` (HDM);
    ``health``: the :class:`~.health.HealthMonitor` (HEM); ``operator``: the :class:`~.operator.OperatorDesk`;
    ``data_handler``: the :class:`~.datahandler.DataHandler` (HDH); ``clock``: monotonic seconds (tests inject
    a fake). Any handle may be None when a tree does not need it; a node that needs a missing handle fails with
    a message naming it.
    """

    def __init__(self, locem: Any = None, store: Any = None, health: Any = None, operator: Any = None,
                 data_handler: Any = None, clock: Callable[[], float] = time.monotonic,
                 log: Optional[logging.Logger] = None) -> None:
        self.locem = locem
        self.store = store
        self.health = health
        self.operator = operator
        self.data_handler = data_handler
        self.clock = clock
        self.log = log or LOG
        self.failures: List[Tuple[str, str]] = []
        self._lock = threading.Lock()
        self.active_commands: Set[Any] = set()
        self.commands_sent: List[str] = []

    def require(self, handle: str, node: str) -> Any:
        h = getattr(self, handle)
        if h is None:
            raise HicemError("%s needs the '%s' handle, but the tree was built without one" % (node, handle))
        return h

    def report_failure(self, node: str, reason: str) -> None:
        with self._lock:
            self.failures.append((node, reason))
        self.log.info("node %s failed: %s", node, reason)

    def last_failure(self) -> Optional[Tuple[str, str]]:
        with self._lock:
            return self.failures[-1] if self.failures else None

    def track(self, handle: Any) -> None:
        with self._lock:
            self.active_commands.add(handle)

    def untrack(self, handle: Any) -> None:
        with self._lock:
            self.active_commands.discard(handle)

    def outstanding(self) -> List[Any]:
        with self._lock:
            return list(self.active_commands)


class Ported:
    """Mixin giving a node its declared ports, its port binding and the context."""
    NODE_ID = ""
    KIND = "Action"
    PORTS: Tuple[PortSpec, ...] = ()
    DESCRIPTION = ""
    MIN_CHILDREN = 0
    MAX_CHILDREN: Optional[int] = 0

    ports: PortBinding
    ctx: NodeContext

    @classmethod
    def node_id(cls) -> str:
        return cls.NODE_ID or cls.__name__

    @classmethod
    def port_specs(cls) -> "dict":
        return {p.name: p for p in cls.PORTS}

    @classmethod
    def validate_literals(cls, literals: "dict") -> Optional[str]:
        """Cross-port checks on literal values at load time; return an error text or None."""
        return None


class Leaf(Ported, py_trees.behaviour.Behaviour):
    """An Action or Condition node. Subclasses override :meth:`on_tick` (and maybe on_start / on_halt)."""

    def __init__(self, name: str, ports: PortBinding, ctx: NodeContext) -> None:
        py_trees.behaviour.Behaviour.__init__(self, name)
        self.ports = ports
        self.ctx = ctx
        self._started = False

    # -- py_trees hooks -------------------------------------------------------------------------------------
    def initialise(self) -> None:
        self._started = False

    def update(self) -> Status:
        n_failures = len(self.ctx.failures)
        try:
            if not self._started:
                self._started = True
                st = self.on_start()
                if st is None:
                    st = self.on_tick()
            else:
                st = self.on_tick()
            if st == Status.FAILURE and len(self.ctx.failures) == n_failures:
                # a plain FAILURE (e.g. a false condition): still say which node, so a failed action has a reason
                self.ctx.report_failure(self.name, "%s '%s' returned FAILURE" % (
                    "condition" if self.KIND == "Condition" else "action", self.name))
            return st
        except HicemError as exc:
            return self.fail(str(exc))
        except Exception as exc:  # a bug in a node must not leave the robot running: fail the action
            LOG.exception("node %s raised", self.name)
            return self.fail("internal error %s: %s" % (type(exc).__name__, exc))

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID and self.status == Status.RUNNING:
            try:
                self.on_halt()
            except Exception:  # halting must always complete
                LOG.exception("node %s failed to halt cleanly", self.name)
        self._started = False

    # -- for subclasses -------------------------------------------------------------------------------------
    def on_start(self) -> Optional[Status]:
        """Called on the first tick of a round; return a status to finish at once, None to go on to on_tick."""
        return None

    def on_tick(self) -> Status:
        return Status.SUCCESS

    def on_halt(self) -> None:
        """Called when the node is halted while RUNNING (cancel what was started)."""

    def fail(self, reason: str) -> Status:
        self.feedback_message = reason
        self.ctx.report_failure(self.name, reason)
        return Status.FAILURE

    def get(self, port: str) -> Any:
        return self.ports.get(port)

    def set(self, port: str, value: Any) -> None:
        self.ports.set(port, value)


class ConditionLeaf(Leaf):
    KIND = "Condition"


def status_name(status: Status) -> str:
    return {Status.SUCCESS: "SUCCESS", Status.FAILURE: "FAILURE", Status.RUNNING: "RUNNING",
            Status.INVALID: "IDLE"}[status]


def all_nodes(root: py_trees.behaviour.Behaviour) -> Sequence[py_trees.behaviour.Behaviour]:
    return list(root.iterate())
