"""The simulated worksite's state on disk, so a world killed with its process (a power loss) comes back as it was.

On the real site the wall keeps its tape, compound and sanding through a power loss, the robot stays where it
stood and the tool stays on the flange. The simulated world keeps them in a folder (``state_dir``):

* ``outcome.npz`` -- a **snapshot**: every outcome map (:class:`~locem_bridge.sim.outcome.OutcomeRecorder`: tape
  per joint, thickness, sanded and pass maps, what went into openings, the operator's manual taping, the spray
  passes' ends), the robot's base pose, the arm's joint positions and the mounted tool, with the sequence number of
  the last journal record it includes and the site it belongs to (wall and joint ids with their map shapes);
* ``outcome.journal.N`` -- the **journal**, N the sequence number of its first record: a line naming the site, then
  one JSON line per call that changed the maps since (each TCP segment the world recorded, with the sim time it was
  recorded at, which is also what a spray pass ending there stamps; a joint taped by hand), appended and handed to
  the kernel at once, so a ``kill -9`` loses nothing the world recorded.

Restoring loads the snapshot and replays the journal records after it: the maps come back exactly as they were
(the recorder is deterministic; float values survive JSON unchanged). A snapshot is written every
``snapshot_period_s`` (wall clock), at the first moment after that when the arm rests and no tool process is on
(copying and writing 3-4 MB holds the interpreter some 20 ms, which must not stall the stand-ins while the arm works
at the wall: at time scale 10 that is 0.2 s of a spray lane, or a valve switched that much late); it is copied under the world's lock, which also starts the next journal
file, and written outside it; then the journal files it holds are deleted (a crash between the two leaves records the
snapshot already holds, skipped by their sequence numbers; a torn last line is dropped).
The arm's controller samples (joint positions, the tool's process on or off, sim time) are journaled too while a
tool is mounted, as the controller makes them (:meth:`WorldState.note_sample`), and the world notes after each of its
steps the last sample it turned into map records and where its tool then was (:meth:`WorldState.note_drained`): the
arm's measured TCP (what LOCEM reports as the work done) runs up to a world step ahead of the maps, more on a busy
machine, and what the arm did in that time must not be lost with the process. Restoring hands the samples the maps do
not hold yet back to the world (:attr:`WorldState.pending`), which records them at its first step as it would
have; the arm then starts where the last sample left it.
The robot's base pose, arm joints and tool are journaled too, as a record whenever they changed (looked at every
``robot_period_s``, 0.2 s of wall clock): a tool mounted just before the power went may be missed by that much, a
pose is up to that old, as good as a relocalisation after a restart (LOCEM's localisation is the world's own pose;
the next action moves the arm and base anyway).
The sim clock goes on from the saved sim time. A folder written for another site (snapshot or journal) is refused
naming the folder, the key that differs and both values. What cannot be read back is left out with a warning, never
a node that cannot start: a broken line, a record whose replay fails (as it failed live). A disk that cannot take
the journal any more is logged once; the world goes on without keeping its state. Not kept: a lift's height (the
lift drive starts where its model starts).
"""
from __future__ import annotations

import copy
import io
import json
import logging
import os
import threading
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..common.files import write_whole
from .errors import SimConfigError
from .outcome import OutcomeRecorder

log = logging.getLogger(__name__)

SNAPSHOT = "outcome.npz"
JOURNAL = "outcome.journal"     # + ".N": N (12 digits) the sequence number of the file's first record
FORMAT = 1
#: a sample the world has not recorded yet: (joint positions, tool on, sim time, number)
Sample = Tuple[List[float], bool, float, int]
_MAP_ARRAYS = ("thickness", "sanded", "passes", "_last_pass", "into_openings")
_JOINT_ARRAYS = ("tape", "tape_passes", "_tape_last")


def _pen(value: Any) -> Optional[Tuple[List[float], float]]:
    """A journaled tool position (TCP, sim time), None for none."""
    return None if value is None else ([float(x) for x in value[0]], float(value[1]))


def _fingerprint(rec: OutcomeRecorder) -> Dict[str, Any]:
    """What a saved state must match: the site's walls and joints with their map shapes."""
    return {"walls": {w: [m.nt, m.ns] for w, m in sorted(rec.maps.items())},
            "joints": {j: len(a) for j, a in sorted(rec.tape.items())}, "grid": rec.grid}


def recorder_arrays(rec: OutcomeRecorder) -> Tuple[Dict[str, np.ndarray], Dict[str, Any]]:
    """The recorder's state: its arrays (by name) and the rest as JSON-able values."""
    arrays: Dict[str, np.ndarray] = {}
    for wid, m in rec.maps.items():
        for name in _MAP_ARRAYS:
            arrays["wall/%s/%s" % (wid, name)] = getattr(m, name)
    for name in _JOINT_ARRAYS:
        for jid, a in getattr(rec, name).items():
            arrays["joint/%s/%s" % (jid, name)] = a
    rest = {"manual": sorted(rec.manual), "tape_off_joint": rec.tape_off_joint, "spray_time": rec.spray_time,
            "pass": rec._pass, "active": rec._active,
            "axis_hits": {w: [list(map(float, h)) for h in hits] for w, hits in rec._axis_hits.items()},
            "spray_pass_ends": [[w, list(map(float, e)), list(map(float, d)), t]
                                for w, e, d, t in rec.spray_pass_ends]}
    return arrays, rest


def restore_recorder(rec: OutcomeRecorder, arrays: Dict[str, np.ndarray], rest: Dict[str, Any]) -> None:
    """Put a state of :func:`recorder_arrays` back into ``rec`` (of the same site)."""
    for wid, m in rec.maps.items():
        for name in _MAP_ARRAYS:
            getattr(m, name)[...] = arrays["wall/%s/%s" % (wid, name)]
    for name in _JOINT_ARRAYS:
        for jid, a in getattr(rec, name).items():
            a[...] = arrays["joint/%s/%s" % (jid, name)]
    rec.manual = set(rest["manual"])
    rec.tape_off_joint = float(rest["tape_off_joint"])
    rec.spray_time = float(rest["spray_time"])
    rec._pass = int(rest["pass"])
    rec._active = {str(k): bool(v) for k, v in rest["active"].items()}
    rec._axis_hits = {w: [tuple(h) for h in hits] for w, hits in rest["axis_hits"].items()}
    rec.spray_pass_ends = [(w, tuple(e), tuple(d), t) for w, e, d, t in rest["spray_pass_ends"]]


class WorldState:
    """Journal and snapshots of one world's state in ``folder`` (see the module docstring).

    ``restore(recorder)`` first (it returns the saved robot state, or None for a fresh folder), then
    ``attach(recorder)`` to journal what it records, ``snapshot(recorder, robot)`` now and then, ``close()``."""

    def __init__(self, folder: str) -> None:
        self.folder = folder
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as exc:
            raise SimConfigError("cannot make the world state folder: %s" % exc, file=folder) from None
        self.seq = 0                     # the last journal record written (or restored)
        self._fd: Optional[int] = None
        self._lock = threading.Lock()
        self.replayed = 0
        self._last_robot: Optional[Dict[str, Any]] = None
        self._site: Dict[str, Any] = {}
        self._broken = False
        self.samples = 0                 # the number of the last arm sample journaled
        self.drained = 0                 # ... and of the last one the world recorded (note_drained)
        self._pen: Optional[Tuple[List[float], float]] = None     # where the tool then was (TCP, sim time)
        self._unrecorded: Dict[int, Dict[str, Any]] = {}         # sample records after `drained`, by number
        self._segment_end: Optional[Tuple[Optional[int], float]] = None

    # ---------------------------------------------------------------- restoring
    def saved_robot(self) -> Dict[str, Any]:
        """The robot state last saved (``pose``, ``q``, ``tool``, ``sim_time``: the snapshot's, then the journal's
        later notes), {} without any (read before the world is built: the clock goes on from the saved sim time,
        the arm's controller starts where the arm stood)."""
        robot: Dict[str, Any] = {}
        upto = 0
        snap = os.path.join(self.folder, SNAPSHOT)
        if os.path.exists(snap):
            with np.load(snap, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
            robot, upto = dict(meta.get("robot") or {}), int(meta["seq"])
        sample: Optional[Dict[str, Any]] = None
        for record in self._journal_records(repair=False):
            if record["seq"] > upto and record["kind"] == "robot":
                robot, sample = dict(record["robot"]), None
            elif record["seq"] > upto and record["kind"] == "sample":
                sample = record
        if sample is not None:                # the arm moved on after the robot was last noted
            robot["q"] = list(sample["q"])
            robot["sim_time"] = max(float(robot.get("sim_time") or 0.0), float(sample["t"]))
        return robot

    def restore(self, rec: OutcomeRecorder) -> Optional[Dict[str, Any]]:
        """Load the snapshot and replay the journal into ``rec``; returns the saved robot state (``pose``, ``q``,
        ``tool``), or None when the folder holds no state. Raises SimConfigError for another site's state."""
        snap = os.path.join(self.folder, SNAPSHOT)
        robot: Optional[Dict[str, Any]] = None
        upto = 0
        if os.path.exists(snap):
            with np.load(snap, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                self._check_site(meta.get("site", {}), _fingerprint(rec))
                restore_recorder(rec, {k: z[k] for k in z.files if k != "meta"}, meta["recorder"])
            upto = int(meta["seq"])
            robot = meta.get("robot")
        self.seq = upto
        samples: Dict[int, Dict[str, Any]] = {}
        if os.path.exists(snap):
            self.samples = self.drained = int(meta.get("samples", 0))
            self._pen = _pen(meta.get("pen"))
        records = self._journal_records()
        for record in records:
            if record["kind"] == "site":                 # each journal file's first line
                self._check_site(record["site"], _fingerprint(rec))
        for record in records:
            if record["kind"] == "site" or record["seq"] <= upto:
                continue
            if record["kind"] == "robot":
                robot = dict(record["robot"])
            elif record["kind"] == "sample":
                samples[int(record["n"])] = record
                self.samples = max(self.samples, int(record["n"]))
            elif record["kind"] == "drained":
                self.drained, self._pen = max(self.drained, int(record["n"])), _pen(record["pen"])
            else:
                if record["kind"] == "segment" and record.get("n") is not None:
                    self.drained = max(self.drained, int(record["n"]))
                    self._pen = (list(map(float, record["p1"])), float(record["t"]))
                try:
                    self._replay(rec, record)
                except Exception as exc:                # what failed live fails again: as live, it is left out
                    log.warning("world state %s: journal record %d not replayed: %s", self.folder, record["seq"], exc)
                if robot is None:
                    robot = {}
            self.seq = record["seq"]
            self.replayed += 1
        self._last_robot = robot
        self._unrecorded = {n: r for n, r in sorted(samples.items()) if n > self.drained}
        return robot

    @property
    def pending(self) -> List[Sample]:
        """The arm samples the world has not recorded yet, oldest first (after :meth:`restore`: those the saved
        world had not)."""
        with self._lock:
            return [(list(map(float, r["q"])), bool(r["on"]), float(r["t"]), n) for n, r in self._unrecorded.items()]

    @property
    def pen(self) -> Optional[Tuple[List[float], float]]:
        """Where the world's tool was after the samples it recorded (TCP, sim time; None: no tool)."""
        return self._pen

    def _check_site(self, saved: Dict[str, Any], mine: Dict[str, Any]) -> None:
        for key in ("grid", "walls", "joints"):
            if saved.get(key) != mine[key]:
                raise SimConfigError("the world state there was saved for another site: %s is %s there, %s here"
                                     % (key, json.dumps(saved.get(key)), json.dumps(mine[key])), file=self.folder,
                                     allowed="a world state folder of this site, or an empty one")

    def journal_files(self) -> List[str]:
        """The journal files, oldest first."""
        names = [n for n in os.listdir(self.folder) if n.startswith(JOURNAL + ".") and n[len(JOURNAL) + 1:].isdigit()]
        return [os.path.join(self.folder, n) for n in sorted(names)]

    def _journal_records(self, repair: bool = True) -> List[Dict[str, Any]]:
        """Every complete record of the journal files, oldest first. A torn last line (the write the crash
        interrupted) is dropped, and with ``repair`` cut off the file, so records appended later start a line."""
        out = []
        for path in self.journal_files():
            with open(path, "rb") as fh:
                data = fh.read()
            end = data.rfind(b"\n") + 1
            if end < len(data) and repair:
                with open(path, "r+b") as fh:
                    fh.truncate(end)
            for line in data[:end].splitlines():
                try:
                    out.append(json.loads(line))
                except ValueError:
                    log.warning("world state %s: a broken journal line in %s left out", self.folder, path)
        return out

    @staticmethod
    def _replay(rec: OutcomeRecorder, r: Dict[str, Any]) -> None:
        if r["kind"] == "manual":
            rec.mark_manual_taping(r["joint"])
            return
        clock = rec.clock
        stamp = r["clock"]
        rec.clock = None if stamp is None else (lambda: stamp)   # the spray passes' end stamps as recorded
        try:
            OutcomeRecorder.record(rec, r["tool"], r["on"], np.asarray(r["p0"]), np.asarray(r["p1"]),
                                   np.asarray(r["z"]), r["dt"])
        finally:
            rec.clock = clock

    # ---------------------------------------------------------------- journaling
    def attach(self, rec: OutcomeRecorder) -> None:
        """Journal every later ``record`` / ``mark_manual_taping`` of ``rec`` before it changes the maps."""
        with self._lock:
            self._site = _fingerprint(rec)
            self._open_journal()
        record, manual = rec.record, rec.mark_manual_taping

        def journaled_record(tool: str, active: bool, p0: Any, p1: Any, z_axis: Any, dt: float) -> None:
            clock = rec.clock
            stamp = None if clock is None else float(clock())
            entry = {"kind": "segment", "tool": tool, "on": bool(active), "p0": [float(x) for x in p0],
                     "p1": [float(x) for x in p1], "z": [float(x) for x in z_axis], "dt": float(dt),
                     "clock": stamp}
            ends, self._segment_end = self._segment_end, None
            if ends is not None and ends[0] is not None:    # the arm samples up to n are in it, ending at time t
                entry["n"], entry["t"] = ends
            self._append(entry)
            rec.clock = None if stamp is None else (lambda: stamp)   # what a pass ending now stamps: as replayed
            try:
                record(tool, active, p0, p1, z_axis, dt)
            finally:
                rec.clock = clock

        def journaled_manual(joint_id: str) -> None:
            manual(joint_id)             # an unknown joint raises before anything is journaled
            self._append({"kind": "manual", "joint": joint_id})
        rec.record = journaled_record            # type: ignore[method-assign]
        rec.mark_manual_taping = journaled_manual  # type: ignore[method-assign]

    def _open_journal(self) -> None:
        """Go on in a new journal file named for the next record, headed by the site it belongs to (under
        ``_lock``)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        if self._broken:
            return
        path = os.path.join(self.folder, "%s.%012d" % (JOURNAL, self.seq + 1))
        try:
            self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        except OSError as exc:
            self._fail(exc)
            return
        self._write_line({"kind": "site", "site": self._site, "seq": self.seq})

    def _fail(self, exc: OSError) -> None:
        """The journal cannot be written (a full disk): say so once and go on without it (the world keeps
        working; what it does from now on is not kept)."""
        if not self._broken:
            log.error("world state %s: the journal cannot be written (%s); the world goes on without keeping its "
                      "state", self.folder, exc)
        self._broken = True
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def _write_line(self, record: Dict[str, Any]) -> None:
        data = (json.dumps(record, separators=(",", ":")) + "\n").encode()
        try:
            if self._fd is not None and os.write(self._fd, data) != len(data):
                raise OSError("short write")
        except OSError as exc:
            self._fail(exc)

    def _append(self, record: Dict[str, Any]) -> None:
        with self._lock:
            self._append_locked(record)

    def _append_locked(self, record: Dict[str, Any]) -> None:
        if self._fd is None:
            return
        self.seq += 1
        record["seq"] = self.seq
        self._write_line(record)

    def note_sample(self, q: Sequence[float], on: bool, t: float) -> int:
        """Journal an arm controller sample (joint positions, the tool's process on, sim time) as it is made (the
        controller's thread); returns its number for :meth:`note_drained`."""
        with self._lock:
            self.samples += 1
            record = {"kind": "sample", "n": self.samples, "q": [float(x) for x in q], "on": bool(on), "t": float(t)}
            self._unrecorded[self.samples] = record
            self._append_locked(record)
            return self.samples

    def segment_ends(self, n: Optional[int], t: float) -> None:
        """The world's next recorded segment holds the arm samples up to number ``n`` (None: none journaled) and
        ends at sim time ``t`` (its journal record says so: a process killed in the middle of a step has replayed
        segments and pending samples that do not overlap)."""
        self._segment_end = (n, float(t))

    def drop_pending(self) -> None:
        """The restored samples cannot be recorded (no tool): forget them."""
        with self._lock:
            if self._unrecorded:
                self.note_drained_locked(max(self._unrecorded), None, 0.0)

    def note_drained(self, n: Optional[int], tcp: Optional[Sequence[float]], t: float) -> None:
        """After a world step: it recorded the samples up to number ``n`` (None: no new ones) into its maps; its
        tool is at ``tcp`` (None: no tool) at sim time ``t``, where the next sample's segment starts. Journaled when
        either changed."""
        with self._lock:
            self.note_drained_locked(n, tcp, t)

    def note_drained_locked(self, n: Optional[int], tcp: Optional[Sequence[float]], t: float) -> None:
        pen = None if tcp is None else ([float(x) for x in tcp], float(t))
        if (n is None or n <= self.drained) and pen == self._pen:
            return
        if n is not None and n > self.drained:
            self.drained = n
            for k in [k for k in self._unrecorded if k <= n]:
                del self._unrecorded[k]
        self._pen = pen
        self._append_locked({"kind": "drained", "n": self.drained, "pen": pen})

    def note_robot(self, robot: Dict[str, Any]) -> None:
        """Journal the robot's state (``pose``, ``q``, ``tool``) when it changed since it was last noted."""
        if robot != self._last_robot:
            self._last_robot = copy.deepcopy(robot)
            self._append({"kind": "robot", "robot": robot})

    def capture(self, rec: OutcomeRecorder, robot: Dict[str, Any]) -> Tuple[Dict[str, np.ndarray], Dict[str, Any]]:
        """A copy of the state for :meth:`write` (call it under the lock the recorder's writer holds, the
        world's, so it is one moment: a few milliseconds; the writing happens outside that lock)."""
        arrays, rest = recorder_arrays(rec)
        with self._lock:
            meta = {"format": FORMAT, "seq": self.seq, "site": _fingerprint(rec), "recorder": copy.deepcopy(rest),
                    "robot": copy.deepcopy(robot), "samples": self.drained, "pen": self._pen}
            self._last_robot = copy.deepcopy(robot)
            if self._fd is not None:
                self._open_journal()     # what comes after this moment goes to a file the snapshot does not hold
                for record in list(self._unrecorded.values()):   # ... with the samples the maps do not hold yet
                    self._append_locked(dict(record))
        return {k: v.copy() for k, v in arrays.items()}, meta

    def write(self, captured: Tuple[Dict[str, np.ndarray], Dict[str, Any]]) -> None:
        """Write a :meth:`capture` as the snapshot (atomically), then delete the journal files it holds."""
        arrays, meta = captured
        buf = io.BytesIO()
        np.savez(buf, meta=np.array(json.dumps(meta)), **arrays)
        write_whole(os.path.join(self.folder, SNAPSHOT), buf.getvalue())
        for old in self.journal_files():
            if int(old.rsplit(".", 1)[1]) <= meta["seq"]:
                os.remove(old)

    def snapshot(self, rec: OutcomeRecorder, robot: Dict[str, Any]) -> None:
        """:meth:`capture` and :meth:`write` in one go (for callers that hold the recorder still)."""
        self.write(self.capture(rec, robot))

    def close(self) -> None:
        with self._lock:
            if self._fd is not None:
                os.close(self._fd)
                self._fd = None


def snapshot_loop(state: WorldState, take: Callable[[bool], bool], period_s: float,
                  stop: threading.Event, robot_period_s: float = 0.2) -> threading.Thread:
    """A daemon thread calling ``take(False)`` (note the robot) every ``robot_period_s``, and ``take(True)`` (a
    whole snapshot) once every ``period_s`` seconds, again at each tick until it returns True (the caller declines
    while the tools work: see :class:`~locem_bridge.sim.worksite.Worksite`), until ``stop`` is set."""
    every = max(1, int(round(period_s / robot_period_s)))

    def run() -> None:
        n = 0
        due = False
        while not stop.wait(min(period_s, robot_period_s)):
            n += 1
            due = due or n % every == 0
            try:
                if take(due):
                    due = False
            except Exception:            # a full disk must not stop the world; the journal still has it all
                due = False
                log.exception("world state snapshot failed (the journal keeps growing)")
    t = threading.Thread(target=run, name="world-state", daemon=True)
    t.start()
    return t
