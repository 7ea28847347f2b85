"""PEMKRE test fixtures: engines on real on-disk oxigraph stores under tmp_path, a deterministic clock."""
import os
import sys

import pytest

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

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
