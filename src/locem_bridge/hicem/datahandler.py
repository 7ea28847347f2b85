"""HDH (the paper's HICEM Data Handler): turns data from the other modules into HICEM data, and new world facts
into PEMKRE updates.

- :meth:`DataHandler.ingest_scan`: a LOCEM ``SCAN`` result (docs/contracts.md) is validated field by field
  (:class:`ScanFormatError` names the culprit), then, in one HDICT transaction, every wall/joint/area is stored
  in the persistent collection ``features`` (key = feature id, value = its geometry + ``type``, ``scan_seq``
  and the processing ``status`` carried over from earlier scans), the scan counter ``scan/latest_seq`` is
  advanced and outdated features (not seen by the latest scan) are pruned by the HDM rules. New or changed
  features are forwarded to PEMKRE (``report_world``) in the SCAN shape; if PEMKRE cannot be reached the update
  waits in the persistent ``outbox`` and is retried by :meth:`flush_outbox`. An area's optional ``finish``
  (``bare`` / ``sprayed`` / ``sanded``: what the perception sees on the surface) is stored and forwarded with its
  geometry; a finish different from the stored one makes a known area *changed* (PEMKRE then upgrades its
  spraying/sanding status, never downgrades it). An area reported without ``finish`` keeps the stored one.
  The scan's ``obstacles`` (walls that are no work surface: floor-plan segments the planner keeps the robot off)
  are no features: the latest scan's list is stored as one entry (``scan/obstacles``, read by :meth:`obstacles`)
  and never forwarded to PEMKRE.
- :meth:`ingest_status` / :meth:`ingest_diagnostics` / :meth:`heartbeat`: module health into the HEM.
- :meth:`feature` / :meth:`mark_feature`: what trees read and write about features.
"""
import math
import re
import time
from typing import Any, Callable, Dict, List, Optional, Sequence

from ..common.finish import AREA_FINISHES
from .datastore import DataManager
from .errors import DataStoreError, HicemError, ScanFormatError

FEATURES = "features"
_ID = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


def _num(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ScanFormatError("%s must be a finite number, got %r" % (where, v))
    return float(v)


def _vec(v: Any, n: int, where: str) -> List[float]:
    if not isinstance(v, (list, tuple)) or len(v) != n:
        raise ScanFormatError("%s must be a list of %d numbers, got %r" % (where, n, v))
    return [_num(x, "%s[%d]" % (where, i)) for i, x in enumerate(v)]


def _pos(v: Any, where: str) -> float:
    x = _num(v, where)
    if x <= 0:
        raise ScanFormatError("%s must be > 0, got %r" % (where, v))
    return x


def _unit(v: List[float], where: str) -> List[float]:
    n = math.sqrt(sum(x * x for x in v))
    if n < 1e-9:
        raise ScanFormatError("%s must not be the zero vector" % where)
    return [x / n for x in v]


def _interval(v: Any, where: str) -> List[float]:
    a, b = _vec(v, 2, where)
    if not a < b:
        raise ScanFormatError("%s must be two numbers first < second, got %r" % (where, v))
    return [a, b]


def _items(d: Dict[str, Any], key: str, where: str, parse: Callable[[Any, str], Dict[str, Any]]) -> List[Dict[str, Any]]:
    """``d[key]`` (default: none), a list whose items ``parse(item, path)`` checks one by one."""
    items = d.get(key, [])
    if not isinstance(items, list):
        raise ScanFormatError("%s.%s must be a list, got %r" % (where, key, items))
    return [parse(x, "%s.%s[%d]" % (where, key, k)) for k, x in enumerate(items)]


def _opening(fid: Callable[[Any, str], str]) -> Callable[[Any, str], Dict[str, Any]]:
    def parse(o: Any, ow: str) -> Dict[str, Any]:
        i = fid(o, ow)
        if o.get("kind") not in ("door", "window"):
            raise ScanFormatError("%s.kind must be door or window, got %r" % (ow, o.get("kind")))
        frame = _num(o.get("frame", 0.0), ow + ".frame")
        if frame < 0:
            raise ScanFormatError("%s.frame must be >= 0 m, got %r" % (ow, frame))
        return {"id": i, "kind": o["kind"], "s": _interval(o.get("s"), ow + ".s"),
                "t": _interval(o.get("t"), ow + ".t"), "frame": frame}
    return parse


def _corner(c: Any, cw: str) -> Dict[str, Any]:
    if not isinstance(c, dict) or c.get("end") not in (0, 1) or isinstance(c.get("end"), bool):
        raise ScanFormatError("%s must be an object with end 0 (at p0) or 1 (at p1), got %r" % (cw, c))
    ang = _num(c.get("angle"), cw + ".angle")
    if not 0.0 < ang < 2.0 * math.pi:
        raise ScanFormatError("%s.angle must be between 0 and 2 pi rad, got %r" % (cw, ang))
    return {"end": c["end"], "angle": ang}


def _hole(h: Any, hw: str) -> Dict[str, Any]:
    if not isinstance(h, dict):
        raise ScanFormatError("%s must be an object {s: [a, b], t: [a, b]}" % hw)
    return {"s": _interval(h.get("s"), hw + ".s"), "t": _interval(h.get("t"), hw + ".t")}


def _obstacle(fid: Callable[[Any, str], str]) -> Callable[[Any, str], Dict[str, Any]]:
    def parse(o: Any, ow: str) -> Dict[str, Any]:
        i = fid(o, ow)
        p0, p1 = _vec(o.get("p0"), 2, ow + ".p0"), _vec(o.get("p1"), 2, ow + ".p1")
        if math.dist(p0, p1) < 1e-6:
            raise ScanFormatError("%s: p0 and p1 are the same point" % ow)
        return {"id": i, "p0": p0, "p1": p1, "height": _pos(o.get("height"), ow + ".height")}
    return parse


def validate_scan(scan: Any, known_walls: Sequence[str] = ()) -> Dict[str, List[Dict[str, Any]]]:
    """Normalised copy of a SCAN result, or ScanFormatError naming the first bad field. ``obstacles`` is always
    in the copy (default: none)."""
    if not isinstance(scan, dict):
        raise ScanFormatError("SCAN result must be a JSON object, got %s" % type(scan).__name__)
    bad = set(scan) - {"stamp", "walls", "joints", "areas", "obstacles"}
    if bad:
        raise ScanFormatError("SCAN result has unknown keys %s; allowed: stamp, walls, joints, areas, obstacles"
                              % sorted(bad))
    out: Dict[str, List[Dict[str, Any]]] = {"walls": [], "joints": [], "areas": [], "obstacles": []}
    ids = set()

    def fid(item: Any, where: str) -> str:
        if not isinstance(item, dict):
            raise ScanFormatError("%s must be an object" % where)
        i = item.get("id")
        if not isinstance(i, str) or not _ID.match(i):
            raise ScanFormatError("%s.id must match [A-Za-z][A-Za-z0-9_]*, got %r" % (where, i))
        if i in ids:
            raise ScanFormatError("%s.id '%s' appears twice" % (where, i))
        ids.add(i)
        return i

    for k in ("walls", "joints", "areas"):
        if not isinstance(scan.get(k, []), list):
            raise ScanFormatError("SCAN '%s' must be a list" % k)
    for n, w in enumerate(scan.get("walls", [])):
        where = "walls[%d]" % n
        i = fid(w, where)
        out["walls"].append({"id": i, "p0": _vec(w.get("p0"), 2, where + ".p0"), "p1": _vec(w.get("p1"), 2, where + ".p1"),
                             "height": _pos(w.get("height"), where + ".height"),
                             "thickness": _num(w.get("thickness", 0.0), where + ".thickness"),
                             "normal": _unit(_vec(w.get("normal"), 3, where + ".normal"), where + ".normal")})
        for key, parse in (("openings", lambda: _items(w, "openings", where, _opening(fid))),
                           ("corners", lambda: _items(w, "corners", where, _corner)),
                           ("ceiling", lambda: _pos(w.get("ceiling"), where + ".ceiling"))):
            if key in w:
                out["walls"][-1][key] = parse()
    walls = {w["id"] for w in out["walls"]} | set(known_walls)
    for n, j in enumerate(scan.get("joints", [])):
        where = "joints[%d]" % n
        i = fid(j, where)
        if j.get("wall") not in walls:
            raise ScanFormatError("%s.wall %r is not a known wall (%s)" % (where, j.get("wall"), ", ".join(sorted(walls)) or "none"))
        if j.get("kind") not in ("vertical", "horizontal"):
            raise ScanFormatError("%s.kind must be vertical or horizontal, got %r" % (where, j.get("kind")))
        s = _vec(j.get("start"), 3, where + ".start")
        e = _vec(j.get("end"), 3, where + ".end")
        if math.dist(s, e) < 1e-6:
            raise ScanFormatError("%s: start and end are the same point" % where)
        out["joints"].append({"id": i, "wall": j["wall"], "kind": j["kind"], "start": s, "end": e,
                              "width": _pos(j.get("width"), where + ".width")})
    for n, a in enumerate(scan.get("areas", [])):
        where = "areas[%d]" % n
        i = fid(a, where)
        if a.get("wall") not in walls:
            raise ScanFormatError("%s.wall %r is not a known wall" % (where, a.get("wall")))
        area = {"id": i, "wall": a["wall"], "origin": _vec(a.get("origin"), 3, where + ".origin"),
                "u": _unit(_vec(a.get("u"), 3, where + ".u"), where + ".u"),
                "width": _pos(a.get("width"), where + ".width"),
                "height": _pos(a.get("height"), where + ".height")}
        if "holes" in a:
            area["holes"] = _items(a, "holes", where, _hole)
        finish = a.get("finish")
        if finish is not None:
            if not isinstance(finish, str) or finish not in AREA_FINISHES:
                raise ScanFormatError("%s.finish must be one of %s, got %r"
                                      % (where, ", ".join(AREA_FINISHES), finish))
            area["finish"] = finish
        out["areas"].append(area)
    out["obstacles"] = _items(scan, "obstacles", "SCAN", _obstacle(fid))
    return out


class ScanIngest:
    def __init__(self, seq: int, new: List[str], changed: List[str], removed: List[str], forwarded: bool):
        self.seq = seq
        self.new = new
        self.changed = changed
        self.removed = removed
        self.forwarded = forwarded


class DataHandler:
    def __init__(self, store: DataManager, pemkre: Any = None, health: Any = None,
                 clock: Callable[[], float] = time.time) -> None:
        self.store = store
        self.pemkre = pemkre
        self.health = health
        self.clock = clock

    # -- world ----------------------------------------------------------------------------------------------
    def ingest_scan(self, scan: Any) -> ScanIngest:
        known = [e.key for e in self.store.entries(FEATURES) if e.value.get("type") == "wall"]
        data = validate_scan(scan, known)
        new: List[str] = []
        changed: List[str] = []
        update: Dict[str, List[Dict[str, Any]]] = {"walls": [], "joints": [], "areas": []}
        with self.store.transaction():
            seq = int(self.store.value("scan", "latest_seq", 0)) + 1
            for kind, items in (("wall", data["walls"]), ("joint", data["joints"]), ("area", data["areas"])):
                for item in items:
                    old = self.store.value(FEATURES, item["id"])
                    geometry = dict(item)
                    if kind == "area" and "finish" not in geometry and old is not None and "finish" in old:
                        geometry["finish"] = old["finish"]   # not reported this time: keep what was seen
                    value = dict(geometry, type=kind, scan_seq=seq,
                                 status=(old or {}).get("status", "detected"))
                    if old is None:
                        new.append(item["id"])
                    elif {k: old.get(k) for k in geometry} != geometry or old.get("type") != kind:
                        changed.append(item["id"])
                    else:
                        self.store.put(FEATURES, item["id"], value, source="HDH")
                        continue
                    self.store.put(FEATURES, item["id"], value, source="HDH")
                    update[kind + "s"].append(geometry)
            self.store.put("scan", "latest_seq", seq, source="HDH")
            self.store.put("scan", "obstacles", data["obstacles"], source="HDH")   # the latest scan's; no feature
            self.store.put("scan", "latest_stamp", scan.get("stamp", self.clock())
                           if isinstance(scan.get("stamp", 0), (int, float)) else self.clock(), source="HDH")
            removed = self.store.prune().get(FEATURES, [])
            if new or changed:
                self.store.put("outbox", "scan_%06d" % seq, dict(update, stamp=scan.get("stamp", 0.0)), source="HDH")
        forwarded = self.flush_outbox() if (new or changed) else True
        return ScanIngest(seq, new, changed, removed, forwarded)

    def flush_outbox(self) -> bool:
        """Send waiting world updates to PEMKRE, oldest first; False if PEMKRE is absent or refused."""
        if self.pemkre is None:
            return False
        for e in sorted(self.store.entries("outbox"), key=lambda e: e.key):
            try:
                self.pemkre.report_world(e.value)
            except HicemError:
                return False
            except (OSError, RuntimeError):
                return False
            self.store.delete("outbox", e.key)
        return True

    def feature(self, fid: str, kind: Optional[str] = None) -> Dict[str, Any]:
        v = self.store.value(FEATURES, fid)
        if v is None or (kind is not None and v.get("type") != kind):
            known = sorted(e.key for e in self.store.entries(FEATURES)
                           if kind is None or e.value.get("type") == kind)
            raise DataStoreError("no stored %s with id '%s' (scan first?); stored: %s" % (
                kind or "feature", fid, ", ".join(known[:20]) or "none"))
        return v

    def obstacles(self) -> List[Dict[str, Any]]:
        """The latest scan's obstacles (SCAN ``obstacles``: ``{id, p0, p1, height}``, walls that are no work
        surface); none before the first scan."""
        return [dict(o) for o in self.store.value("scan", "obstacles", None) or []]

    def features(self, kind: str) -> List[Dict[str, Any]]:
        """Every stored feature of ``kind`` (wall, joint, area), with its id."""
        return [dict(e.value, id=e.key) for e in self.store.entries(FEATURES) if e.value.get("type") == kind]

    def mark_feature(self, fid: str, status: str) -> None:
        with self.store.transaction():
            v = self.feature(fid)
            v["status"] = status
            self.store.put(FEATURES, fid, v, source="HDH")

    # -- operator -------------------------------------------------------------------------------------------
    def record_operator_event(self, event: str, prompt: Any) -> None:
        """OperatorDesk listener: every prompt opened/answered/cancelled goes to the persistent log."""
        d = prompt.as_dict()
        self.store.put("operator_log", "%s_%s" % (d["id"], event), dict(d, event=event, time=self.clock()),
                       source="HDH")

    # -- health ---------------------------------------------------------------------------------------------
    def heartbeat(self, module: str) -> None:
        if self.health is not None:
            self.health.heartbeat(module)

    def ingest_status(self, status: Dict[str, Any]) -> None:
        """One LOCEM/backend status: {"module": name, "level": OK|WARN|ERROR|STALE|0..3, "message": text}."""
        if not isinstance(status, dict) or "module" not in status or "level" not in status:
            raise HicemError("status must be an object with 'module' and 'level' (and 'message'), got %r" % (status,))
        if self.health is not None:
            self.health.report(status["module"], status["level"], str(status.get("message", "")))

    def ingest_diagnostics(self, statuses: Sequence[Dict[str, Any]]) -> None:
        """``diagnostic_msgs/DiagnosticArray`` entries as dicts (name, level, message)."""
        for s in statuses:
            self.ingest_status({"module": s.get("name"), "level": s.get("level"), "message": s.get("message", "")})
