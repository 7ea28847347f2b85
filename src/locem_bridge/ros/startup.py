"""What every node does with a bad configuration file at start-up: one line, no traceback, and no endless respawn.

Decorate a node's ``main`` with :func:`config_guard`. When loading its files raises a
:class:`~locem_bridge.common.config_errors.ConfigError` (robot, site, HICEM parameters, Turtle, tree XML), the node prints
one line on stderr (roslaunch shows a node's stderr on its console even with ``output="log"``)::

    [locem] configuration error: /path/robot.yaml: robot.compresor: unknown key (allowed: arm, base, ...)

and exits with status 2 at once (no thread is waited for, so within a second or two).

roslaunch restarts a ``respawn="true"`` node whatever its exit status, for ever, and a bad file does not heal by
restarting. So the node counts its failures on the same line within one launch: in a file next to its roslaunch
log (``__log:=`` gives ``<ROS log dir>/<run id>/<node>-N.log``, the same path on every respawn of one launch; a
new launch has a new run id and starts from zero). After :data:`GIVE_UP_AFTER` failures in a row with the same
line it prints the line once more with ``giving up`` and stays down: it leaves the ROS master (``rosnode list``
no longer shows it) and waits, doing nothing, until the launch ends (SIGINT/SIGTERM, exit 0), so roslaunch has
nothing to restart. Fix the file and start the launch again. A node started without roslaunch (``rosrun``,
``python -m``) has no ``__log:=`` and simply exits 2 every time.
"""

import functools
import os
import re
import signal
import sys
import threading
import time
from typing import Any, Callable, List, Optional, Tuple

from locem_bridge.common.config_errors import ConfigError

GIVE_UP_AFTER = 3          # failures in a row, same line, same launch
EXIT_CONFIG = 2            # exit status of a node refusing its configuration
MARK = "configuration error: "
LINE = re.compile(r"^\[(?P<node>[^\]]+)\] " + re.escape(MARK) + r"(?P<line>.+)$")


def message(node: str, line: str) -> str:
    """The one line a node prints for a configuration error (``main_job`` recognises it with :data:`LINE`)."""
    return "[%s] %s%s" % (node, MARK, line)


def _log_arg(argv: List[str]) -> Optional[str]:
    for arg in argv:
        if arg.startswith("__log:="):
            return arg[len("__log:="):]
    return None


def count_failure(argv: List[str], line: str) -> Tuple[int, Optional[str]]:
    """Record one configuration failure with ``line`` for the node of ``argv``; returns (failures in a row with
    this line in this launch, the counter file), (1, None) outside roslaunch."""
    log = _log_arg(argv)
    if not log or not os.path.isdir(os.path.dirname(log)):
        return 1, None
    path = (log[:-len(".log")] if log.endswith(".log") else log) + ".config_failures"
    count = 0
    try:
        with open(path, encoding="utf-8") as handle:
            stored, _, previous = handle.read().partition("\n")
        if previous.rstrip("\n") == line:
            count = int(stored)
    except (OSError, ValueError):
        count = 0
    count += 1
    try:
        with open(path, "w", encoding="utf-8") as handle:
            handle.write("%d\n%s\n" % (count, line))
    except OSError:
        return count, None
    return count, path


def _leave_master() -> None:
    """Unregister from the ROS master when ``init_node`` already ran (bounded: a gone master must not hold us)."""
    try:
        import rospy
        if not rospy.core.is_initialized():
            return
        worker = threading.Thread(target=rospy.signal_shutdown, args=("configuration error",), daemon=True)
        worker.start()
        worker.join(2.0)
    except Exception:      # best effort on the way out
        pass


def _stay_down() -> None:
    """Wait, doing nothing, until the launch ends the process (SIGINT or SIGTERM: exit 0)."""
    def leave(*_: Any) -> None:
        os._exit(0)
    signal.signal(signal.SIGINT, leave)
    signal.signal(signal.SIGTERM, leave)
    while True:
        time.sleep(3600.0)


def fail(node: str, error: ConfigError, argv: Optional[List[str]] = None) -> None:
    """Print the one line for ``error`` and exit (status 2), or stay down after repeated failures."""
    line = error.one_line()
    count, _ = count_failure(list(sys.argv if argv is None else argv), line)
    if count >= GIVE_UP_AFTER:
        sys.stderr.write(message(node, "%s (giving up after %d failures; fix the file and restart the launch)"
                                 % (line, count)) + "\n")
        sys.stderr.flush()
        _leave_master()
        _stay_down()
    sys.stderr.write(message(node, line) + "\n")
    sys.stderr.flush()
    sys.stdout.flush()
    _leave_master()
    os._exit(EXIT_CONFIG)        # threads a half-started node left running must not delay the exit


def config_guard(node: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorator for a node's ``main``: a :class:`ConfigError` becomes the one line and exit (see module doc)."""
    def wrap(main: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(main)
        def guarded(*args: Any, **kwargs: Any) -> Any:
            try:
                return main(*args, **kwargs)
            except ConfigError as error:
                fail(node, error)
        return guarded
    return wrap
