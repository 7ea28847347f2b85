"""HDM (memory) and HDICT (SQLite): one interface, transactions, pruning rules, and surviving kill -9."""
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from locem_bridge.hicem.datastore import DataManager, MemoryStore, PruneRule, SqliteStore
from locem_bridge.hicem.errors import DataStoreError

SRC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "src")


@pytest.fixture(params=["memory", "sqlite"])
def store(request, tmp_path):
    s = MemoryStore() if request.param == "memory" else SqliteStore(str(tmp_path / "hdict.sqlite"))
    yield s
    s.close()


def test_put_get_delete_entries(store):
    store.put("features", "wall_1", {"p0": [0, 3]}, stamp=5.0, source="test")
    e = store.get("features", "wall_1")
    assert (e.value, e.stamp, e.source) == ({"p0": [0, 3]}, 5.0, "test")
    store.put("features", "wall_1", {"p0": [1, 3]})
    assert store.value("features", "wall_1") == {"p0": [1, 3]}
    assert [x.key for x in store.entries("features")] == ["wall_1"]
    assert store.delete("features", "wall_1") and not store.delete("features", "wall_1")
    assert store.get("features", "wall_1") is None and store.collections() == []


def test_transaction_is_all_or_nothing(store):
    store.put("c", "a", 1)
    with pytest.raises(RuntimeError):
        with store.transaction():
            store.put("c", "a", 2)
            store.put("c", "b", 3)
            raise RuntimeError("boom")
    assert store.value("c", "a") == 1 and store.get("c", "b") is None
    with store.transaction():
        store.put("c", "a", 2)
        with store.transaction():  # nested: part of the outer one
            store.put("c", "b", 3)
    assert store.value("c", "a") == 2 and store.value("c", "b") == 3


@pytest.mark.parametrize("coll,key,value,msg", [
    ("c", "k", float("nan"), "not storable as JSON"),
    ("c", "k", {"x": object()}, "not storable as JSON"),
    ("", "k", 1, "collection must be"),
    ("c", None, 1, "key must be"),
])
def test_bad_input_is_rejected_with_reason(store, coll, key, value, msg):
    with pytest.raises(DataStoreError) as ei:
        store.put(coll, key, value)
    assert msg in str(ei.value)


def test_values_are_copies(store):
    v = {"a": [1]}
    store.put("c", "k", v)
    v["a"].append(2)
    got = store.value("c", "k")
    got["a"].append(3)
    assert store.value("c", "k") == {"a": [1]}


def test_sqlite_persists_across_reopen(tmp_path):
    p = str(tmp_path / "h.sqlite")
    s = SqliteStore(p)
    s.put("robot", "tool", "sander")
    s.close()
    s2 = SqliteStore(p)
    assert s2.value("robot", "tool") == "sander"
    s2.close()
    with pytest.raises(DataStoreError):
        s2.get("robot", "tool")


def test_sqlite_bad_location_and_corrupt_file(tmp_path):
    with pytest.raises(DataStoreError) as ei:
        SqliteStore(str(tmp_path / "missing_dir" / "h.sqlite"))
    assert "does not exist" in str(ei.value)
    bad = tmp_path / "junk.sqlite"
    bad.write_bytes(b"this is not a database" * 100)
    with pytest.raises(DataStoreError) as ei:
        SqliteStore(str(bad))
    assert "cannot open HDICT" in str(ei.value)


def test_data_manager_routes_collections_and_prunes_by_rule(tmp_path):
    now = [100.0]
    hdict = SqliteStore(str(tmp_path / "h.sqlite"), clock=lambda: now[0])
    hdm = DataManager(MemoryStore(clock=lambda: now[0]), hdict, ["features", "scan"], [
        PruneRule("modules", max_age_s=10.0),
        PruneRule("log", keep_latest=2),
        PruneRule("features", below=("scan_seq", "scan", "latest_seq")),
    ], clock=lambda: now[0])
    hdm.put("features", "j1", {"scan_seq": 1})
    hdm.put("features", "j2", {"scan_seq": 2})
    hdm.put("scan", "latest_seq", 2)
    hdm.put("modules", "old", {}, stamp=80.0)
    hdm.put("modules", "fresh", {}, stamp=95.0)
    for i in range(4):
        hdm.put("log", "e%d" % i, i, stamp=90.0 + i)
    assert hdict.value("features", "j1") is not None and hdict.get("modules", "old") is None
    removed = hdm.prune()
    assert removed == {"modules": ["old"], "log": ["e0", "e1"], "features": ["j1"]}
    assert [e.key for e in hdm.entries("features")] == ["j2"]
    with pytest.raises(DataStoreError):
        PruneRule.from_dict({"collection": "x", "max_age": 3})


WRITER = textwrap.dedent("""
    import sys
    sys.path.insert(0, %r)
    from locem_bridge.hicem.datastore import SqliteStore
    s = SqliteStore(sys.argv[1])
    i = 0
    while True:
        i += 1
        with s.transaction():
            for k in range(20):
                s.put("batch", "%%06d_%%02d" %% (i, k), {"i": i, "k": k, "pad": "x" * 200})
            s.put("meta", "last", i)
        print(i, flush=True)
""")


def test_hdict_survives_kill_9_with_only_whole_transactions(tmp_path):
    path = str(tmp_path / "killed.sqlite")
    proc = subprocess.Popen([sys.executable, "-c", WRITER % SRC, path], stdout=subprocess.PIPE, text=True)
    try:
        acked = 0
        deadline = time.monotonic() + 30.0
        while acked < 25 and time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            acked = int(line)
        assert acked >= 25, "writer did not get going"
        os.kill(proc.pid, signal.SIGKILL)  # kill -9 while it is in the middle of further transactions
    finally:
        proc.wait(timeout=10)
    assert proc.returncode == -signal.SIGKILL
    s = SqliteStore(path)
    last = s.value("meta", "last")
    assert last >= acked  # every acknowledged commit is there
    per_batch = {}
    for e in s.entries("batch"):
        per_batch[e.value["i"]] = per_batch.get(e.value["i"], 0) + 1
    assert set(per_batch) == set(range(1, last + 1))  # nothing of an unfinished transaction
    assert all(n == 20 for n in per_batch.values())
    s.put("meta", "after", True)  # the file is usable for writing again
    s.close()
