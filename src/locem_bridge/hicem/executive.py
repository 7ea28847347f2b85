"""Assembly of a complete HICEM from files: parameters, trees, HDICT, HEM, HDH, operator desk, HHLC.

``create_executive(pemkre, locem, hdict_path=...)`` is what the ROS node (and tests, and the benchmark) call;
every handle can also be built by hand for finer control.
Lifecycle: create → (optionally ``resume_in_background()``) → ``controller.start_process(iri)`` … →
``close()`` stops the watchdog and closes the HDICT.
"""
import time
from typing import Any, Callable, Optional

from .config import DEFAULT_PARAMS_FILE, DEFAULT_TREES_DIR, HicemParams, load_params
from .controller import HighLevelController
from .datahandler import DataHandler
from .datastore import DataManager, MemoryStore, SqliteStore
from .health import HealthMonitor
from .operator import OperatorDesk
from .xml_loader import TreeLibrary


class Executive:
    def __init__(self, params: HicemParams, library: TreeLibrary, store: DataManager, health: HealthMonitor,
                 operator: OperatorDesk, data_handler: DataHandler, controller: HighLevelController) -> None:
        self.params = params
        self.library = library
        self.store = store
        self.health = health
        self.operator = operator
        self.data_handler = data_handler
        self.controller = controller

    def close(self) -> None:
        self.controller.stop("shutdown")
        self.controller.join(5.0)
        self.health.stop_watchdog()
        self.store.close()


def create_executive(pemkre: Any, locem: Any, hdict_path: Optional[str] = None,
                     params_file: str = DEFAULT_PARAMS_FILE, trees_dir: str = DEFAULT_TREES_DIR,
                     params: Optional[HicemParams] = None, library: Optional[TreeLibrary] = None,
                     clock: Callable[[], float] = time.monotonic, start_watchdog: bool = True,
                     robot_file: Optional[str] = None) -> Executive:
    """Build every HICEM part. ``hdict_path`` None keeps everything in memory (no crash recovery); ``robot_file``:
    the robot file whose facts the trees read (None: the shipped robot; ignored when ``params`` is given)."""
    params = params or load_params(params_file, robot_file)
    if library is None:
        library = TreeLibrary(params.node_registry())
        library.load_directory(trees_dir)
    persistent = SqliteStore(hdict_path, synchronous=params.hdict_synchronous) if hdict_path else None
    store = DataManager(MemoryStore(), persistent, params.persistent_collections, params.prune_rules)
    health = HealthMonitor(params.modules, clock=clock, store=store)
    operator = OperatorDesk()
    hdh = DataHandler(store, pemkre, health)
    operator.add_listener(hdh.record_operator_event)
    ctrl = HighLevelController(pemkre, locem, library, store, params, health=health, operator=operator,
                               data_handler=hdh, clock=clock)
    if start_watchdog:
        health.start_watchdog(params.watchdog_period_s)
    return Executive(params, library, store, health, operator, hdh, ctrl)
