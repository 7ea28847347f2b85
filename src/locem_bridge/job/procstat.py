"""Memory and CPU of a process tree (a ``roslaunch`` and everything it started), sampled from ``/proc``.

ROS-free, Linux only. :class:`ProcessTreeSampler` follows the tree under one root pid: every :meth:`sample`
reads ``/proc/<pid>/stat`` (parent, CPU ticks), ``/proc/<pid>/statm`` (resident pages) and, once per pid,
``/proc/<pid>/cmdline``, and

- sums the resident memory (RSS) of every live process of the tree; the peak of that sum over the run is
  :attr:`peak_rss` (bytes, with the time it was reached);
- groups processes by ROS node: a process whose command line carries ``__name:=NAME`` (how roslaunch starts a
  node; ``__ns:=NS`` is prefixed) is node ``NS/NAME``; ``rosmaster`` is ``rosmaster``; the root is its own
  group (``roslaunch``); any other process belongs to the group of its nearest named ancestor (e.g. a device
  stand-in forked by the simulator node counts for that node);
- keeps, per group, a series of ``(time, cumulative CPU seconds)``: a process that exits keeps its last
  reading, so the CPU of the group never goes backwards.

Lifecycle: ``ProcessTreeSampler(root_pid)`` -> :meth:`start` (a daemon thread sampling every ``period``
seconds) or :meth:`sample` by hand -> :meth:`stop` -> :meth:`summary`. Between two samples a process may
start and die unseen; the error of the CPU figures is at most one period of CPU per process.
"""

import os
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Tuple

CLOCK_TICKS = os.sysconf("SC_CLK_TCK")
PAGE_SIZE = os.sysconf("SC_PAGE_SIZE")


class ProcStatError(RuntimeError):
    """The sampler cannot follow the tree (no /proc, a root pid that does not exist, a bad period)."""


@dataclass
class ProcReading:
    """One process at one instant: parent, CPU seconds (user + system), resident bytes, start time (clock ticks
    after boot: with the pid it names the process uniquely, pids being reused)."""

    pid: int
    ppid: int
    cpu_s: float
    rss: int
    start: int = 0


def read_proc(pid: int, proc: str = "/proc") -> Optional[ProcReading]:
    """The reading of ``pid``, or None when the process is gone (or a zombie without memory)."""
    try:
        with open("%s/%d/stat" % (proc, pid), "rb") as handle:
            stat = handle.read().decode("ascii", "replace")
        with open("%s/%d/statm" % (proc, pid), "rb") as handle:
            statm = handle.read().split()
    except (FileNotFoundError, ProcessLookupError, PermissionError):
        return None
    # the command name (field 2) may contain spaces and parentheses: split after the last ')'
    fields = stat.rsplit(")", 1)[1].split()
    ppid = int(fields[1])
    cpu = (int(fields[11]) + int(fields[12])) / CLOCK_TICKS
    return ProcReading(pid, ppid, cpu, int(statm[1]) * PAGE_SIZE if len(statm) > 1 else 0, int(fields[19]))


def same_process(pid: int, start: int, proc: str = "/proc") -> bool:
    """True when ``pid`` still runs and is the process that started at ``start`` (not a reused pid)."""
    reading = read_proc(pid, proc)
    return reading is not None and reading.start == start


def tree_pids(root_pid: int, proc: str = "/proc") -> Dict[int, int]:
    """``{pid: start}`` of ``root_pid`` and all its live descendants."""
    kids = children_map(proc)
    out: Dict[int, int] = {}
    todo = [root_pid]
    while todo:
        pid = todo.pop()
        reading = read_proc(pid, proc)
        if reading is not None:
            out[pid] = reading.start
        todo.extend(kids.get(pid, []))
    return out


def read_cmdline(pid: int, proc: str = "/proc") -> List[str]:
    """Arguments of ``pid`` (empty when gone or a kernel thread)."""
    try:
        with open("%s/%d/cmdline" % (proc, pid), "rb") as handle:
            raw = handle.read()
    except (FileNotFoundError, ProcessLookupError, PermissionError):
        return []
    return [a.decode("utf-8", "replace") for a in raw.split(b"\0") if a]


def node_name(argv: List[str]) -> Optional[str]:
    """The ROS node a command line starts (``__name:=`` with ``__ns:=``), ``rosmaster``, or None."""
    name = ns = None
    for arg in argv:
        if arg.startswith("__name:="):
            name = arg[len("__name:="):]
        elif arg.startswith("__ns:="):
            ns = arg[len("__ns:="):]
    if name:
        ns = (ns or "/").rstrip("/")
        return "%s/%s" % (ns, name) if ns else "/" + name
    if any(os.path.basename(a) == "rosmaster" for a in argv[:2]):
        return "rosmaster"
    return None


def children_map(proc: str = "/proc") -> Dict[int, List[int]]:
    """``{ppid: [pid, ...]}`` for every process on the machine."""
    out: Dict[int, List[int]] = {}
    for entry in os.listdir(proc):
        if not entry.isdigit():
            continue
        try:
            with open("%s/%s/stat" % (proc, entry), "rb") as handle:
                ppid = int(handle.read().rsplit(b")", 1)[1].split()[1])
        except (FileNotFoundError, ProcessLookupError, PermissionError, IndexError, ValueError):
            continue
        out.setdefault(ppid, []).append(int(entry))
    return out


@dataclass
class GroupStats:
    """One ROS node (or the root, or rosmaster): its pids, CPU series and memory peak."""

    name: str
    pids: List[int] = field(default_factory=list)
    series: List[Tuple[float, float]] = field(default_factory=list)  # (time, cumulative CPU s)
    peak_rss: int = 0
    first_seen: float = 0.0
    last_seen: float = 0.0

    @property
    def cpu_s(self) -> float:
        return self.series[-1][1] if self.series else 0.0

    def cpu_at(self, when: float) -> float:
        """Cumulative CPU seconds at ``when`` (the last reading not after it; 0 before the first)."""
        value = 0.0
        for stamp, cpu in self.series:
            if stamp > when:
                break
            value = cpu
        return value


class ProcessTreeSampler:
    """Samples the process tree under ``root_pid`` (see the module doc)."""

    def __init__(self, root_pid: int, period: float = 0.5, root_name: str = "roslaunch", proc: str = "/proc",
                 clock: Callable[[], float] = time.time) -> None:
        if period <= 0:
            raise ProcStatError("period must be > 0 s, got %r" % period)
        if not os.path.isdir(proc):
            raise ProcStatError("%s is not mounted: the sampler needs Linux procfs" % proc)
        if read_proc(root_pid, proc) is None:
            raise ProcStatError("no process with pid %d to sample" % root_pid)
        self.root_pid = root_pid
        self.period = period
        self.root_name = root_name
        self.proc = proc
        self.clock = clock
        self.groups: Dict[str, GroupStats] = {}
        self.peak_rss = 0
        self.peak_rss_at = 0.0
        self.peak_processes = 0
        self.samples = 0
        self.seen: Dict[int, int] = {}  # every pid of the tree ever sampled -> its start time
        self._group_of: Dict[int, str] = {}
        self._last_cpu: Dict[int, float] = {}
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._lock = threading.Lock()

    # -- sampling ---------------------------------------------------------------------------------------------
    def _tree(self) -> List[int]:
        kids = children_map(self.proc)
        out, todo = [], [self.root_pid]
        while todo:
            pid = todo.pop()
            out.append(pid)
            todo.extend(kids.get(pid, []))
        return out

    def _group(self, pid: int, parent_group: Optional[str]) -> str:
        if pid not in self._group_of:
            if pid == self.root_pid:
                self._group_of[pid] = self.root_name
            else:
                self._group_of[pid] = node_name(read_cmdline(pid, self.proc)) or parent_group or self.root_name
        return self._group_of[pid]

    def sample(self) -> int:
        """Read the tree once; returns the number of live processes in it (0 once the root is gone)."""
        now = self.clock()
        pids = self._tree()
        readings = {pid: r for pid, r in ((p, read_proc(p, self.proc)) for p in pids) if r is not None}
        if self.root_pid not in readings:
            return 0
        with self._lock:
            # parents before children, so a child inherits its parent's group
            order: List[int] = []
            seen = set()

            def visit(pid: int) -> None:
                if pid in seen or pid not in readings:
                    return
                seen.add(pid)
                parent = readings[pid].ppid
                if parent in readings and pid != self.root_pid:
                    visit(parent)
                order.append(pid)
            for pid in readings:
                visit(pid)
            rss_total = 0
            group_rss: Dict[str, int] = {}
            for pid in order:
                r = readings[pid]
                parent_group = self._group_of.get(r.ppid) if pid != self.root_pid else None
                name = self._group(pid, parent_group)
                self._last_cpu[pid] = r.cpu_s
                self.seen[pid] = r.start
                rss_total += r.rss
                group_rss[name] = group_rss.get(name, 0) + r.rss
                g = self.groups.get(name)
                if g is None:
                    g = self.groups[name] = GroupStats(name, first_seen=now)
                if pid not in g.pids:
                    g.pids.append(pid)
                g.last_seen = now
            for name, g in self.groups.items():
                if name in group_rss:  # alive: record; a dead group keeps its last reading
                    cpu = sum(self._last_cpu.get(pid, 0.0) for pid in g.pids)
                    g.series.append((now, max(cpu, g.series[-1][1] if g.series else 0.0)))
                g.peak_rss = max(g.peak_rss, group_rss.get(name, 0))
            if rss_total > self.peak_rss:
                self.peak_rss, self.peak_rss_at, self.peak_processes = rss_total, now, len(readings)
            self.samples += 1
        return len(readings)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                if self.sample() == 0:
                    return
            except (OSError, ValueError, IndexError):
                pass  # a process vanished mid-read; the next sample sees the tree again
            self._stop.wait(self.period)

    def start(self) -> "ProcessTreeSampler":
        if self._thread is not None:
            raise ProcStatError("sampler already started")
        self._thread = threading.Thread(target=self._run, name="proc-sampler", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)

    # -- results ----------------------------------------------------------------------------------------------
    def summary(self, window: Optional[Tuple[float, float]] = None) -> Dict[str, Dict[str, float]]:
        """Per group: ``cpu_s``, ``lifetime_s``, ``cpu_pct`` (mean % of one core over its lifetime),
        ``peak_rss`` (bytes), ``pids``; with ``window=(t0, t1)`` also ``window_cpu_s`` and ``window_cpu_pct``."""
        out: Dict[str, Dict[str, float]] = {}
        with self._lock:
            for name, g in self.groups.items():
                life = max(g.last_seen - g.first_seen, 1e-9)
                row = {"cpu_s": g.cpu_s, "lifetime_s": g.last_seen - g.first_seen,
                       "cpu_pct": 100.0 * g.cpu_s / life if g.last_seen > g.first_seen else 0.0,
                       "peak_rss": float(g.peak_rss), "pids": float(len(g.pids))}
                if window is not None:
                    t0, t1 = window
                    used = g.cpu_at(t1) - g.cpu_at(t0)
                    row["window_cpu_s"] = used
                    row["window_cpu_pct"] = 100.0 * used / (t1 - t0) if t1 > t0 else 0.0
                out[name] = row
        return out
