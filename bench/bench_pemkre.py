#!/usr/bin/env python3
"""PEMKRE benchmark: next_action latency, status-update latency and OWL 2 RL closure time vs world size.

Prints, side by side and measured in the same run:
  * ours     -- ProcessEngine on the default JournaledStore (oxigraph in memory + journal), schema closure
                materialised once, incremental ABox inference;
  * ours_fsync -- ours with every change flushed to the disk (fsync=True: the durability of a power loss)
  * rocksdb  -- the same engine on OxigraphStore (oxigraph's RocksDB backend)          } store choice
  * rdflib   -- the same engine on rdflib's in-memory Dataset + rdflib's SPARQL engine }
  * server   -- the same engine on a real SPARQL 1.1 server (`oxigraph serve` on a loopback port, started here)
                as PEMKRE opens it by default (store:=sparql): MirroredSparqlStore, reads from an exact copy in the
                process checked against the server's version marker once per decision, writes to the server
  * server_plain -- the same server through the plain SparqlStore: every read is a request
  * naive    -- the baseline of the issue: rdflib in memory and a full owlrl OWL 2 RL closure of ontologies +
                world + log before every decision (bounded: a closure over --closure-cap seconds is reported as
                '>cap' and that configuration stops).
World sizes count wall features (half joint lines, half wall areas, one wall per 20 features). Each sample is one
decision of the taping process with every line pending (after each sample the line is reset, untimed), so the
world never shrinks. Goals of the issue: next_action p99 <= 10 ms at 1,000 features and <= 50 ms at 10,000;
status update p99 <= 5 ms; cost growing no faster than linearly. Issue 20: the server's cost per decision
(next_action + its two status updates, p50) <= 3x the embedded store's at 10,000 features; next_action p99
<= 20 ms at 100,000 features on the embedded store.

usage: python3 bench/bench_pemkre.py [--sizes 10,100,1000,10000] [--samples 200] [--budget 20] [--closure-cap 60]
                                    [--configs ours,ours_fsync,rocksdb,rdflib,naive,server,server_plain]
e.g. issue 20's table: --sizes 1000,10000,100000 --configs ours,server
"""
import argparse
import gc
import os
import shutil
import statistics
import sys
import tempfile
import time
from typing import Dict, List, Optional

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "src"))

from rdflib import Graph, Literal, URIRef  # noqa: E402

from locem_bridge.pemkre import PLB, PPR, JournaledStore, OxigraphStore, ProcessEngine, RdflibStore  # noqa: E402
from locem_bridge.pemkre.errors import ReasoningBoundError  # noqa: E402
from locem_bridge.pemkre.ontology import default_ontology_files, load_files  # noqa: E402
from locem_bridge.pemkre.reasoning import bounded_closure  # noqa: E402
from locem_bridge.pemkre.store import ASSERTED_GRAPHS, G_ABOX_INFERRED, G_WORLD, ChangeSet  # noqa: E402


def world(n: int) -> Dict:
    walls = max(1, n // 20)
    joints = n // 2
    areas = n - joints
    return {"stamp": 1.0,
            "walls": [{"id": "wall_%d" % w, "p0": [0.0, 3.0 * w], "p1": [4.8, 3.0 * w], "height": 2.5}
                      for w in range(walls)],
            "joints": [{"id": "wall_%d_joint_%d" % (i % walls, i), "wall": "wall_%d" % (i % walls),
                        "kind": "vertical" if i % 4 else "horizontal",
                        "start": [1.2, 3.0, 0.0], "end": [1.2, 3.0, 2.5], "width": 0.05} for i in range(joints)],
            "areas": [{"id": "wall_%d_area_%d" % (i % walls, i), "wall": "wall_%d" % (i % walls),
                       "origin": [0.0, 3.0, 0.0], "u": [1.0, 0.0, 0.0], "width": 4.8, "height": 2.5}
                      for i in range(areas)]}


def pct(xs: List[float], q: float) -> float:
    if not xs:
        return float("nan")
    xs = sorted(xs)
    k = min(len(xs) - 1, max(0, int(round(q / 100.0 * (len(xs) - 1)))))
    return xs[k]


class Result:
    def __init__(self) -> None:
        self.next: List[float] = []
        self.status: List[float] = []
        self.decision: List[float] = []      # next_action + its two status updates
        self.note = ""
        self.world_s = float("nan")
        self.triples = 0
        self.closure_s: Optional[float] = None
        self.reload_s: Optional[float] = None   # server: loading the whole copy from the server once
        self.reloads = 0                        # server: copies loaded during the sampled decisions
        self.requests: List[float] = []         # server: time in requests per sampled decision (answers awaited)
        self.writes: List[float] = []           # server: each update request of the sampled decisions
        self.reads: List[float] = []            # server: each query request of the sampled decisions
        self.per_decision: List[tuple] = []     # server: (updates, queries) of each sampled decision


class RequestMeter:
    """Times the HTTP requests a SPARQL store sends while ``on`` (wraps its two endpoints' ``post``)."""

    def __init__(self, store, res: Result) -> None:
        self.on = False
        self.res = res
        self.total = 0.0
        self.counts = [0, 0]
        for i, ep in enumerate((store.update_endpoint, store.query_endpoint)):
            ep.post = self._timed(ep.post, i)

    def _timed(self, send, i: int):
        def post(*args, **kwargs):
            t = time.perf_counter()
            try:
                return send(*args, **kwargs)
            finally:
                if self.on:
                    dt = time.perf_counter() - t
                    self.total += dt
                    self.counts[i] += 1
                    (self.res.writes if i == 0 else self.res.reads).append(dt)
        return post

    def take(self) -> None:
        self.res.requests.append(self.total)
        self.res.per_decision.append((self.counts[0], self.counts[1]))
        self.total, self.counts = 0.0, [0, 0]


class NaiveReasoner:
    """No incremental inference: the naive baseline recomputes the full owlrl closure before each decision."""

    def __init__(self, cap: float) -> None:
        self.cap = cap
        self.last_closure_s = 0.0

    def infer(self, store, changes, max_seconds=None, max_triples=None):
        return changes

    def recompute_all(self, store, pending=None, max_seconds=None, max_triples=None):
        return ChangeSet()

    def refresh(self, store) -> None:
        asserted = Graph()
        for s, p, o, _ in store.quads(None, None, None, ASSERTED_GRAPHS):
            asserted.add((s, p, o))
        t = time.perf_counter()
        closed = bounded_closure(asserted, max_seconds=self.cap)
        self.last_closure_s = time.perf_counter() - t
        store.replace_graph(G_ABOX_INFERRED, [x for x in closed if x not in asserted and not isinstance(x[0], Literal)
                                              and isinstance(x[1], URIRef)])


def reset_line(engine, task: str) -> None:
    line = engine.store.value(URIRef(task), PLB.line)
    if line is None:
        return
    cs = ChangeSet(remove=[(line, PPR.tapingStatus, PPR.processed, G_WORLD)],
                   add=[(line, PPR.tapingStatus, PPR.unprocessed, G_WORLD)])
    engine.store.apply(engine.reasoner.infer(engine.store, cs))


def _server_store(path: str, mirror: bool):
    """The store ``open_store("sparql", ...)`` gives (``mirror``: MirroredSparqlStore, else SparqlStore) on a fresh
    ``oxigraph serve`` (the tests' helper, test/pemkre/oxigraph_server.py)."""
    sys.path.insert(0, os.path.join(REPO, "test", "pemkre"))
    from oxigraph_server import OxigraphServer  # noqa: E402
    from locem_bridge.pemkre.store_factory import open_store  # noqa: E402

    server = OxigraphServer(path).start()
    # a world scan is one change: 10,000 features take about 11 s on the server, 100,000 (staged in parts, then
    # applied by one request) about 3 1/2 min, far over the 10 s default timeout
    store = open_store("sparql", "", query_url=server.query_url, update_url=server.update_url, mirror=mirror,
                       timeout_s=900.0)
    closing = store.close

    def close() -> None:
        closing()
        server.kill()
    store.close = close  # type: ignore[assignment]
    return store


def run_config(kind: str, n: int, samples: int, budget: float, cap: float, tmp: str) -> Result:
    res = Result()
    path = os.path.join(tmp, "%s_%d" % (kind, n))
    store = {"ours": lambda: JournaledStore(path), "ours_fsync": lambda: JournaledStore(path, fsync=True),
             "rocksdb": lambda: OxigraphStore(path),
             "rdflib": RdflibStore, "naive": RdflibStore, "server": lambda: _server_store(path, True), "server_plain": lambda: _server_store(path, False)}[kind]()
    try:
        engine = ProcessEngine(store, reasoning_max_seconds=600, reasoning_max_triples=10 ** 8)
        naive = None
        if kind == "naive":
            naive = NaiveReasoner(cap)
            engine.reasoner = naive  # type: ignore[assignment]
        t = time.perf_counter()
        engine.update_world(world(n), max_seconds=600)
        res.world_s = time.perf_counter() - t
        res.triples = store.count()
        engine.start_process(str(PLB.TapingProcess), {"validateLines": False})
        gc.collect()
        gc.freeze()  # as pemkre_node does after loading: long-lived objects leave the cyclic collector's reach
        if naive is not None:
            try:
                naive.refresh(store)
            except ReasoningBoundError:
                res.note = ">%.0fs closure" % cap
                return res
        a = engine.next_action()           # GET_TOOL (not timed)
        engine.set_task_status(a.task, "succeeded")
        warm = 0 if kind == "naive" else 3
        meter = RequestMeter(store, res) if kind.startswith("server") else None
        reloads = getattr(store, "reloads", 0)
        deadline = time.perf_counter() + budget
        for i in range(samples + warm):
            if i >= warm and time.perf_counter() > deadline and len(res.next) >= 2:
                res.note = "budget"
                break
            if meter is not None:
                meter.on = i >= warm
            t = time.perf_counter()
            if naive is not None:
                try:
                    naive.refresh(store)
                except ReasoningBoundError:
                    res.note = ">%.0fs closure" % cap
                    break
                res.closure_s = naive.last_closure_s
            a = engine.next_action()
            dt = time.perf_counter() - t
            assert a.action_type == "TAPE_LINE", a
            t1 = time.perf_counter()
            engine.set_task_status(a.task, "in_progress")
            t2 = time.perf_counter()
            engine.set_task_status(a.task, "succeeded")
            t3 = time.perf_counter()
            if meter is not None and meter.on:
                meter.on = False
                meter.take()
            reset_line(engine, a.task)
            if i >= warm:
                res.next.append(dt)
                res.status += [t2 - t1, t3 - t2]
                res.decision.append(t3 - t)
        if hasattr(store, "reload"):
            res.reloads = store.reloads - reloads
            t = time.perf_counter()
            store.reload()
            res.reload_s = time.perf_counter() - t
    finally:
        gc.unfreeze()
        store.close()
        shutil.rmtree(path, ignore_errors=True)
    return res


def owlrl_closure_time(n: int, cap: float) -> str:
    loaded = load_files(default_ontology_files())
    g = Graph()
    for t in loaded.schema:
        g.add(t)
    tmp = RdflibStore()
    e = ProcessEngine(tmp, reasoning_max_seconds=600, reasoning_max_triples=10 ** 8)
    e.update_world(world(n), max_seconds=600)
    for s, p, o, _ in tmp.quads(None, None, None, ASSERTED_GRAPHS):
        g.add((s, p, o))
    t = time.perf_counter()
    try:
        closed = bounded_closure(g, max_seconds=cap)
    except ReasoningBoundError:
        return ">%.0f s (bound hit, %d triples in)" % (cap, len(g))
    return "%.2f s (%d -> %d triples)" % (time.perf_counter() - t, len(g), len(closed))


def index_aging(tmp: str, replacements: int = 10000) -> str:
    """Lookup cost of one subject/predicate after it was replaced N times (a process pointer), before and after
    maintain(): removed triples can leave entries behind that lookups walk over until the indexes are rebuilt."""
    out = []
    for kind in ("journal", "rocksdb"):
        path = os.path.join(tmp, "aging_" + kind)
        store = JournaledStore(path) if kind == "journal" else OxigraphStore(path)
        store.rebuild_after_removals = 10 ** 9  # age it first
        a, p = URIRef("https://ex.example/a"), URIRef("https://ex.example/p")
        store.apply(ChangeSet(add=[(a, p, Literal(0), G_WORLD)]))

        def lookup_us() -> float:
            t = time.perf_counter()
            for _ in range(200):
                store.value(a, p)
            return (time.perf_counter() - t) / 200 * 1e6
        fresh = lookup_us()
        for i in range(1, replacements + 1):
            store.apply(ChangeSet(remove=[(a, p, Literal(i - 1), G_WORLD)], add=[(a, p, Literal(i), G_WORLD)]))
        aged = lookup_us()
        store.rebuild_after_removals = 1
        t = time.perf_counter()
        store.maintain()
        took = time.perf_counter() - t
        out.append("%s: %.1f us fresh, %.1f us after %d replacements, %.1f us after maintain() (%.2f s)"
                   % (kind, fresh, aged, replacements, lookup_us(), took))
        store.close()
        shutil.rmtree(path, ignore_errors=True)
    return "; ".join(out)


def ms(x: float) -> str:
    return "%8.2f" % (x * 1e3) if x == x else "       -"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="10,100,1000,10000")
    ap.add_argument("--samples", type=int, default=200)
    ap.add_argument("--budget", type=float, default=20.0, help="seconds of sampling per configuration and size")
    ap.add_argument("--closure-cap", type=float, default=60.0, help="bound on one owlrl closure (s)")
    ap.add_argument("--configs", default="ours,rocksdb,rdflib,naive")
    args = ap.parse_args()
    sizes = [int(x) for x in args.sizes.split(",")]
    configs = args.configs.split(",")
    tmp = tempfile.mkdtemp(prefix="bench_pemkre_")
    print("PEMKRE benchmark -- python %s, %d samples/config (budget %.0f s), owlrl cap %.0f s"
          % (sys.version.split()[0], args.samples, args.budget, args.closure_cap))
    t = time.perf_counter()
    loaded = load_files(default_ontology_files())
    closed = bounded_closure(loaded.schema, max_seconds=args.closure_cap)
    print("schema closure (owlrl, once per ontology version): %.2f s, %d -> %d triples"
          % (time.perf_counter() - t, len(loaded.schema), len(closed)))
    results: Dict[str, Dict[int, Result]] = {c: {} for c in configs}
    closures: Dict[int, str] = {}
    try:
        for n in sizes:
            for c in configs:
                if c == "naive" and n > sizes[0] and results[c].get(sizes[sizes.index(n) - 1]) is not None \
                        and results[c][sizes[sizes.index(n) - 1]].note.startswith(">"):
                    r = Result()
                    r.note = "skipped (smaller size hit the cap)"
                    results[c][n] = r
                    continue
                results[c][n] = run_config(c, n, args.samples, args.budget, args.closure_cap, tmp)
                r = results[c][n]
                print("  size %6d %-8s next p50 %s ms p99 %s ms (n=%d) status p99 %s ms world insert %.2f s %s"
                      % (n, c, ms(pct(r.next, 50)), ms(pct(r.next, 99)), len(r.next), ms(pct(r.status, 99)),
                         r.world_s, r.note), flush=True)
            closures[n] = owlrl_closure_time(n, args.closure_cap)
            print("  size %6d full owlrl closure of ontologies + world: %s" % (n, closures[n]), flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    print()
    print("next_action latency (ms), p50 / p99 (samples):")
    print("%8s %9s | %s" % ("features", "triples", " | ".join("%-24s" % c for c in configs)))
    for n in sizes:
        tri = results[configs[0]][n].triples if n in results[configs[0]] else 0
        cells = []
        for c in configs:
            r = results[c].get(n)
            if r is None or not r.next:
                cells.append("%-24s" % (r.note if r else "-"))
            else:
                cells.append("%-24s" % ("%.2f / %.2f (%d)" % (pct(r.next, 50) * 1e3, pct(r.next, 99) * 1e3, len(r.next))))
        print("%8d %9d | %s" % (n, tri, " | ".join(cells)))
    if "ours" in configs and "naive" in configs:
        print()
        print("speed-up of ours over the naive baseline (p50 ratio):")
        for n in sizes:
            o, b = results["ours"].get(n), results["naive"].get(n)
            if o and b and o.next and b.next:
                print("  %6d features: %8.0fx  (naive p50 %.1f ms; its last owlrl closure took %.2f s)"
                      % (n, pct(b.next, 50) / pct(o.next, 50), pct(b.next, 50) * 1e3, b.closure_s or float("nan")))
            elif b is not None:
                print("  %6d features: naive %s" % (n, b.note or "n/a"))
    if "ours" in configs:
        print()
        print("status update latency (ms), ours: " + ", ".join(
            "%d: p50 %.2f p99 %.2f" % (n, pct(results["ours"][n].status, 50) * 1e3, pct(results["ours"][n].status, 99) * 1e3)
            for n in sizes))
        print("growth of ours (p50 ratio between successive sizes vs size ratio):")
        for a, b in zip(sizes, sizes[1:]):
            ra, rb = results["ours"][a], results["ours"][b]
            print("  %d -> %d: x%.2f for x%.0f more features" % (a, b, pct(rb.next, 50) / pct(ra.next, 50), b / a))
        print()
        goals = [(1000, 0.010), (10000, 0.050)]
        for n, goal in goals:
            if n in results["ours"]:
                p99 = pct(results["ours"][n].next, 99)
                print("goal next_action p99 <= %2.0f ms at %5d features: %6.2f ms -> %s"
                      % (goal * 1e3, n, p99 * 1e3, "met" if p99 <= goal else "MISSED"))
        worst = max(pct(r.status, 99) for r in results["ours"].values())
        print("goal status update p99 <= 5 ms (worst size): %.2f ms -> %s" % (worst * 1e3, "met" if worst <= 0.005 else "MISSED"))
    if "ours" in configs and "server" in configs:
        print()
        print("issue 20: the SPARQL server vs the embedded store (ours), measured in this run:")
        for n in sizes:
            o, r = results["ours"].get(n), results["server"].get(n)
            if o and r and o.decision and r.decision:
                print("  %6d features: next_action p50/p99 ours %.2f/%.2f ms, server %.2f/%.2f ms; status p50/p99 "
                      "ours %.2f/%.2f ms, server %.2f/%.2f ms; decision p50 ratio server/ours x%.2f"
                      % (n, pct(o.next, 50) * 1e3, pct(o.next, 99) * 1e3, pct(r.next, 50) * 1e3, pct(r.next, 99) * 1e3,
                         pct(o.status, 50) * 1e3, pct(o.status, 99) * 1e3, pct(r.status, 50) * 1e3,
                         pct(r.status, 99) * 1e3, pct(r.decision, 50) / pct(o.decision, 50)))
            if r and r.reload_s is not None:
                print("  %6d features: the copy loaded %d times during the sampled decisions; loading it whole "
                      "(a client that starts, or finds another writer's version) %.2f s" % (n, r.reloads, r.reload_s))
            if o and r and r.requests and o.decision:
                w, q = pct(r.writes, 50), pct(r.reads, 50)
                counts = max(set(r.per_decision), key=r.per_decision.count)
                print("  %6d features: of the server's decision (p50 %.2f ms) %.2f ms are spent in its requests "
                      "(most decisions: %d updates and %d queries; p50 per update %.2f ms, per query %.2f ms, each "
                      "from sending to the answer read), the rest is the client's own work; the requests alone are "
                      "x%.2f of ours' whole decision. Any protocol sends at least the decision's 3 changes (issue, 2 "
                      "status reports) and one read: at these times x%.2f"
                      % (n, pct(r.decision, 50) * 1e3, pct(r.requests, 50) * 1e3, counts[0], counts[1], w * 1e3,
                         q * 1e3, pct(r.requests, 50) / pct(o.decision, 50), (3 * w + q) / pct(o.decision, 50)))
            p = results.get("server_plain", {}).get(n)
            if o and p and o.decision and p.decision:
                print("  %6d features: without the copy (server_plain): next_action p50/p99 %.2f/%.2f ms, status "
                      "p50/p99 %.2f/%.2f ms; decision p50 ratio x%.2f"
                      % (n, pct(p.next, 50) * 1e3, pct(p.next, 99) * 1e3, pct(p.status, 50) * 1e3,
                         pct(p.status, 99) * 1e3, pct(p.decision, 50) / pct(o.decision, 50)))
            f = results.get("ours_fsync", {}).get(n)
            if f and r and f.decision and r.decision:
                print("  %6d features: against ours with every change flushed to the disk (ours_fsync: decision p50 "
                      "%.2f ms): server x%.2f" % (n, pct(f.decision, 50) * 1e3, pct(r.decision, 50) / pct(f.decision, 50)))
        if 10000 in results["server"] and results["server"][10000].decision and results["ours"][10000].decision:
            ratio = pct(results["server"][10000].decision, 50) / pct(results["ours"][10000].decision, 50)
            print("goal server cost per decision <= 3x the embedded store's at 10000 features: x%.2f -> %s"
                  % (ratio, "met" if ratio <= 3.0 else "MISSED"))
        for c in ("ours", "server"):
            a, b = sizes[0], sizes[-1]
            ra, rb = results[c].get(a), results[c].get(b)
            if ra and rb and ra.next and rb.next:
                print("  growth %s %d -> %d features: next_action p99 x%.2f, status p99 x%.2f"
                      % (c, a, b, pct(rb.next, 99) / pct(ra.next, 99), pct(rb.status, 99) / pct(ra.status, 99)))
    if 100000 in results.get("ours", {}) and results["ours"][100000].next:
        p99 = pct(results["ours"][100000].next, 99)
        print("goal next_action p99 <= 20 ms at 100000 features (embedded): %.2f ms -> %s"
              % (p99 * 1e3, "met" if p99 <= 0.020 else "MISSED"))
    print()
    print("index aging (why the engine calls store.maintain() after each change; it acts every 10,000 removals):", index_aging(tempfile.mkdtemp(prefix="bench_pemkre_")))
    print()
    print("full owlrl closure time of the shipped ontologies + world:")
    for n in sizes:
        print("  %6d features: %s" % (n, closures.get(n, "-")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
