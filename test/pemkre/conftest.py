"""PEMKRE test fixtures: engines on real on-disk oxigraph stores under tmp_path, a deterministic clock; a real
SPARQL 1.1 server (``oxigraph serve``, one per session, emptied for each test) and SparqlStores on it."""
import os
import sys

import pytest

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

from oxigraph_server import OxigraphServer, clear_server  # noqa: E402
from pemkre_testkit import FakeClock  # noqa: E402
from locem_bridge.pemkre import JournaledStore, ProcessEngine  # noqa: E402


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


@pytest.fixture
def make_engine(tmp_path, clock):
    """Factory for engines on a real on-disk store (the default JournaledStore) under tmp_path; closes the stores afterwards."""
    stores = []

    def factory(name: str = "db", **kwargs) -> ProcessEngine:
        store = JournaledStore(str(tmp_path / name))
        stores.append(store)
        kwargs.setdefault("clock", clock)
        return ProcessEngine(store, **kwargs)

    yield factory
    for s in stores:
        s.close()


@pytest.fixture(scope="session")
def oxigraph_server(tmp_path_factory):
    """One ``oxigraph serve`` on a free loopback port for the session (killed at the end)."""
    server = OxigraphServer(str(tmp_path_factory.mktemp("oxigraph") / "data"))
    with server:
        yield server


@pytest.fixture
def sparql_store(oxigraph_server):
    """Factory of SparqlStores on the session's server, emptied before the test; closes them afterwards.
    ``mirror=True``: a :class:`~locem_bridge.pemkre.mirror_store.MirroredSparqlStore` (reads from its copy)."""
    from locem_bridge.pemkre.mirror_store import MirroredSparqlStore
    from locem_bridge.pemkre.sparql_store import SparqlStore

    oxigraph_server.start()  # a test may have killed it
    clear_server(oxigraph_server)
    stores = []

    def factory(mirror: bool = False, **kwargs) -> SparqlStore:
        kind = MirroredSparqlStore if mirror else SparqlStore
        store = kind(oxigraph_server.query_url, oxigraph_server.update_url, **kwargs)
        stores.append(store)
        return store

    yield factory
    for s in stores:
        s.close()
