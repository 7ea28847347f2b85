"""World-state updates from below: a SCAN result (docs/contracts.md) -> asserted world triples.

:func:`scan_changes` validates the JSON shape (every error names the offending path, e.g. ``joints[2].start``,
and what is allowed) and returns the :class:`ChangeSet` that merges it into the world graph: new features get the
``unprocessed`` state for every process that works on them and the next ``scanOrder``; known features (same id,
stable across scans) keep their state and get their geometry refreshed. Nothing is written here.

An area may carry ``finish`` (``bare`` -- the default --, ``sprayed`` or ``sanded``): what the perception sees on
the surface. On first sight it sets the area's ``sprayingStatus`` / ``sandingStatus`` (``sprayed``: spraying
``processed``, sanding ``unprocessed``; ``sanded``: both ``processed`` -- the values the SPRAY_AREA / SAND_AREA
effects write), so a sanding run on a fresh store finds the areas someone else sprayed. For a known area a finish
further along than the stored status upgrades it; a scan never downgrades a status (``bare`` on a sprayed area
changes nothing: the perception may miss thin compound, the execution log does not).
"""
import json
import math
from typing import Any, Dict, List, Mapping, Optional, Sequence, Set, Union

from rdflib import Literal, Namespace, URIRef
from rdflib.namespace import RDF, XSD

from ..common.finish import AREA_FINISHES, BARE, WORK_DONE
from .errors import WorldUpdateError
from .store import G_WORLD, ChangeSet, TripleStore
from .terms import FEATURE_ID_RE
from .vocab import GEO, PPR

_JOINT_CLASS = {"vertical": PPR.VerticalJointLine, "horizontal": PPR.HorizontalJointLine}
_GEOMETRY_PROPS = (PPR.geometry, PPR.height, PPR.width, PPR.thickness, PPR.kind, PPR.onWall, PPR.lastScannedAt)
#: statuses that count as done: a scan never replaces them
_DONE = frozenset((PPR.processed, PPR.processedManually))


def _num(v: Any, path: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise WorldUpdateError("%s must be a number (SI units), got %r" % (path, v))
    f = float(v)
    if math.isnan(f) or math.isinf(f):
        raise WorldUpdateError("%s must be finite, got %r" % (path, v))
    return f


def _vec(v: Any, n: int, path: str) -> List[float]:
    if not isinstance(v, (list, tuple)) or len(v) != n:
        raise WorldUpdateError("%s must be a list of %d numbers, got %r" % (path, n, v))
    return [_num(x, "%s[%d]" % (path, i)) for i, x in enumerate(v)]


def _id(v: Any, path: str) -> str:
    if not isinstance(v, str) or not FEATURE_ID_RE.match(v):
        raise WorldUpdateError("%s must be a feature id matching [A-Za-z][A-Za-z0-9_]*, got %r" % (path, v))
    return v


def _fmt(x: float) -> str:
    return repr(round(x, 6))


def _wkt_line(points: Sequence[Sequence[float]]) -> Literal:
    return Literal("LINESTRING Z (%s)" % ", ".join(" ".join(_fmt(c) for c in p) for p in points), datatype=GEO.wktLiteral)


def _wkt_polygon(points: Sequence[Sequence[float]]) -> Literal:
    ring = list(points) + [points[0]]
    return Literal("POLYGON Z ((%s))" % ", ".join(" ".join(_fmt(c) for c in p) for p in ring), datatype=GEO.wktLiteral)


def _finish(v: Any, path: str) -> str:
    if v is None:
        return BARE
    if not isinstance(v, str) or v not in WORK_DONE:
        raise WorldUpdateError("%s must be one of %s, got %r" % (path, ", ".join(AREA_FINISHES), v))
    return v


def parse_scan(scan: Union[str, bytes, Mapping[str, Any]]) -> Dict[str, Any]:
    if isinstance(scan, (str, bytes)):
        try:
            scan = json.loads(scan)
        except ValueError as exc:
            raise WorldUpdateError("SCAN result is not valid JSON: %s" % exc) from None
    if not isinstance(scan, Mapping):
        raise WorldUpdateError("SCAN result must be a JSON object with walls/joints/areas lists, got %s"
                               % type(scan).__name__)
    return dict(scan)


def scan_changes(scan: Union[str, bytes, Mapping[str, Any]], store: TripleStore, site: Namespace,
                 next_order: Optional[int] = None) -> ChangeSet:
    """Validate a SCAN result and return the world-graph change that merges it (see the module docstring)."""
    data = parse_scan(scan)
    stamp = data.get("stamp", 0.0)
    stamp = _num(stamp, "stamp") if stamp is not None else 0.0
    for key in ("walls", "joints", "areas"):
        if key in data and not isinstance(data[key], list):
            raise WorldUpdateError("%s must be a list, got %s" % (key, type(data[key]).__name__))
    cs = ChangeSet()
    seen: Set[str] = set()
    wall_ids: Set[str] = set()

    def iri(fid: str) -> URIRef:
        return site[fid]

    def existing_class(node: URIRef) -> Optional[URIRef]:
        for _, _, o, _ in store.quads(node, RDF.type, None, (G_WORLD,)):
            return o  # type: ignore[return-value]
        return None

    def refresh(node: URIRef, cls: URIRef, fid: str, props: List) -> bool:
        """Add type/id on first sight; replace geometry-like properties. Returns True if the node is new."""
        prev = existing_class(node)
        if prev is not None and prev != cls:
            raise WorldUpdateError("feature id %r was a %s before and is a %s in this scan; ids must be stable"
                                   % (fid, prev.split("#")[-1], cls.split("#")[-1]))
        for p in _GEOMETRY_PROPS:
            for s2, p2, o2, _ in store.quads(node, p, None, (G_WORLD,)):
                cs.remove.append((s2, p2, o2, G_WORLD))
        if prev is None:
            cs.add.append((node, RDF.type, cls, G_WORLD))
            cs.add.append((node, PPR.featureId, Literal(fid), G_WORLD))
        for p, o in props:
            cs.add.append((node, p, o, G_WORLD))
        cs.add.append((node, PPR.lastScannedAt, Literal(stamp, datatype=XSD.double), G_WORLD))
        return prev is None

    def unique(fid: str, path: str) -> None:
        if fid in seen:
            raise WorldUpdateError("%s: id %r appears twice in this scan" % (path, fid))
        seen.add(fid)

    walls = data.get("walls", []) or []
    for i, w in enumerate(walls):
        path = "walls[%d]" % i
        if not isinstance(w, Mapping):
            raise WorldUpdateError("%s must be an object" % path)
        fid = _id(w.get("id"), path + ".id")
        unique(fid, path)
        p0, p1 = _vec(w.get("p0"), 2, path + ".p0"), _vec(w.get("p1"), 2, path + ".p1")
        height = _num(w.get("height"), path + ".height")
        thick = _num(w.get("thickness", 0.0125), path + ".thickness")
        if height <= 0:
            raise WorldUpdateError("%s.height must be > 0 m, got %r" % (path, height))
        refresh(iri(fid), PPR.Wall, fid, [(PPR.geometry, _wkt_line([p0 + [0.0], p1 + [0.0]])),
                                          (PPR.height, Literal(height, datatype=XSD.double)),
                                          (PPR.thickness, Literal(thick, datatype=XSD.double))])
        wall_ids.add(fid)

    def check_wall(wid: Any, path: str) -> URIRef:
        wid = _id(wid, path)
        node = iri(wid)
        if wid not in wall_ids and existing_class(node) != PPR.Wall:
            raise WorldUpdateError("%s refers to wall %r, which is neither in this scan nor known" % (path, wid))
        return node

    order = next_order
    if order is None:
        order = 1
        for _, _, o, _ in store.quads(None, PPR.scanOrder, None, (G_WORLD,)):
            order = max(order, int(o.toPython()) + 1)  # type: ignore[union-attr]

    for i, j in enumerate(data.get("joints", []) or []):
        path = "joints[%d]" % i
        if not isinstance(j, Mapping):
            raise WorldUpdateError("%s must be an object" % path)
        fid = _id(j.get("id"), path + ".id")
        unique(fid, path)
        wall = check_wall(j.get("wall"), path + ".wall")
        kind = j.get("kind")
        if kind not in _JOINT_CLASS:
            raise WorldUpdateError("%s.kind must be one of %s, got %r" % (path, sorted(_JOINT_CLASS), kind))
        a, b = _vec(j.get("start"), 3, path + ".start"), _vec(j.get("end"), 3, path + ".end")
        width = _num(j.get("width", 0.05), path + ".width")
        node = iri(fid)
        if refresh(node, _JOINT_CLASS[kind], fid, [(PPR.onWall, wall), (PPR.kind, Literal(kind)),
                                                   (PPR.geometry, _wkt_line([a, b])),
                                                   (PPR.width, Literal(width, datatype=XSD.double))]):
            cs.add.append((node, PPR.scanOrder, Literal(order), G_WORLD))
            cs.add.append((node, PPR.tapingStatus, PPR.unprocessed, G_WORLD))
            order += 1

    for i, a in enumerate(data.get("areas", []) or []):
        path = "areas[%d]" % i
        if not isinstance(a, Mapping):
            raise WorldUpdateError("%s must be an object" % path)
        fid = _id(a.get("id"), path + ".id")
        unique(fid, path)
        wall = check_wall(a.get("wall"), path + ".wall")
        origin, u = _vec(a.get("origin"), 3, path + ".origin"), _vec(a.get("u"), 3, path + ".u")
        width, height = _num(a.get("width"), path + ".width"), _num(a.get("height"), path + ".height")
        if width <= 0 or height <= 0:
            raise WorldUpdateError("%s: width and height must be > 0 m, got %r x %r" % (path, width, height))
        spray_done, sand_done = WORK_DONE[_finish(a.get("finish"), path + ".finish")]
        c1 = [origin[k] + width * u[k] for k in range(3)]
        corners = [origin, c1, [c1[0], c1[1], c1[2] + height], [origin[0], origin[1], origin[2] + height]]
        node = iri(fid)
        if refresh(node, PPR.WallArea, fid, [(PPR.onWall, wall), (PPR.geometry, _wkt_polygon(corners)),
                                            (PPR.width, Literal(width, datatype=XSD.double)),
                                            (PPR.height, Literal(height, datatype=XSD.double))]):
            cs.add.append((node, PPR.scanOrder, Literal(order), G_WORLD))
            cs.add.append((node, PPR.sprayingStatus, PPR.processed if spray_done else PPR.unprocessed, G_WORLD))
            cs.add.append((node, PPR.sandingStatus, PPR.processed if sand_done else PPR.unprocessed, G_WORLD))
            order += 1
        else:  # known area: a finish further along upgrades the stored status, never the other way
            for prop, done in ((PPR.sprayingStatus, spray_done), (PPR.sandingStatus, sand_done)):
                if not done:
                    continue
                stored = list(store.quads(node, prop, None, (G_WORLD,)))
                if any(q[2] in _DONE for q in stored):
                    continue
                cs.remove += [(s2, p2, o2, G_WORLD) for s2, p2, o2, _ in stored]
                cs.add.append((node, prop, PPR.processed, G_WORLD))
    # geometry triples that are removed and re-added unchanged: keep them out of the change set
    rem, add = set(cs.remove), set(cs.add)
    both = rem & add
    cs.remove = [q for q in cs.remove if q not in both]
    cs.add = [q for q in dict.fromkeys(cs.add) if q not in both]
    return cs
