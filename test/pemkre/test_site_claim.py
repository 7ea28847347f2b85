"""A store belongs to one site (store_factory.claim_site): claimed when empty, used again by the same site, refused
for another site in one line naming the store and both sites, with nothing written; on an on-disk store and on a
real SPARQL server (``oxigraph serve``)."""
import pytest
from rdflib import Literal

from locem_bridge.common.config_errors import ConfigError
from locem_bridge.pemkre import JournaledStore, ProcessEngine
from locem_bridge.pemkre.store import G_META, ChangeSet
from locem_bridge.pemkre.store_factory import SITE_PREDICATE, SITE_SUBJECT, claim_site


def _all(store):
    return sorted(store.quads(None, None, None, None))


def _refused(store, site, where):
    before = _all(store)
    with pytest.raises(ConfigError) as info:
        claim_site(store, site, where)
    assert _all(store) == before                      # nothing written
    return info.value.one_line()


def test_an_on_disk_store_is_claimed_once_and_refuses_another_site_after_a_restart(tmp_path, clock):
    path = str(tmp_path / "pemkre_store")
    store = JournaledStore(path)
    try:
        assert claim_site(store, "bay_a", path) is True          # empty: claimed
        engine = ProcessEngine(store, clock=clock)              # PEMKRE then loads its ontologies on it
        assert engine.processes()
    finally:
        store.close()
    store = JournaledStore(path)                                # PEMKRE restarted (or the machine)
    try:
        assert claim_site(store, "bay_a", path) is False        # its own site: used as it is
        line = _refused(store, "bay_b", path)
        assert line == ("%s: site: the store holds the data of site 'bay_a', not of this launch's site 'bay_b': "
                        "PEMKRE starts no process on it (allowed: a store (folder or server dataset) of site "
                        "'bay_b' or an empty one (pemkre.launch fresh:=true empties one))" % path), line
    finally:
        store.close()


def test_a_server_dataset_names_its_endpoint_when_it_refuses_another_site(sparql_store, oxigraph_server, clock):
    first = sparql_store()
    assert claim_site(first, "bay_a", oxigraph_server.query_url) is True
    ProcessEngine(first, clock=clock)
    other = sparql_store()                                       # a second PEMKRE, of another site, same server
    line = _refused(other, "bay_b", oxigraph_server.query_url)
    assert line.startswith("%s: site: the store holds the data of site 'bay_a', not of this launch's site 'bay_b'"
                           % oxigraph_server.query_url), line
    assert claim_site(other, "bay_a", oxigraph_server.query_url) is False


class _Rival:
    """A store on which another site's PEMKRE writes its claim in the moment between our read and our write."""

    def __init__(self, store, rival):
        self._store, self._rival = store, rival

    def objects(self, *args, **kwargs):
        return self._store.objects(*args, **kwargs)

    def value(self, *args, **kwargs):
        return self._store.value(*args, **kwargs)

    def apply(self, changes):
        self._store.apply(ChangeSet(add=[(SITE_SUBJECT, SITE_PREDICATE, Literal(self._rival), G_META)]))
        self._store.apply(changes)


def test_of_two_sites_claiming_one_empty_store_at_once_the_one_that_wrote_last_takes_its_claim_back(tmp_path):
    """Another site's PEMKRE claims the store between our read and our write: we read back two names, take ours
    back and are refused; the other keeps the store (its restart uses it as its own)."""
    path = str(tmp_path / "pemkre_store")
    store = JournaledStore(path)
    try:
        with pytest.raises(ConfigError) as info:
            claim_site(_Rival(store, "bay_b"), "bay_a", path)
        assert "holds the data of site 'bay_a' and 'bay_b', not of this launch's site 'bay_a'" in str(info.value)
        assert [str(o) for o in store.objects(SITE_SUBJECT, SITE_PREDICATE, (G_META,))] == ["bay_b"]
        assert claim_site(store, "bay_b", path) is False
        assert "holds the data of site 'bay_b', not of this launch's site 'bay_a'" in _refused(store, "bay_a", path)
    finally:
        store.close()


def test_a_store_a_pemkre_used_without_naming_its_site_is_refused(tmp_path, clock):
    """A store whose data names no site (a PEMKRE started without site:= loaded its ontologies and ran on it) is
    not known to hold this site's data: refused, nothing written."""
    path = str(tmp_path / "pemkre_store")
    store = JournaledStore(path)
    try:
        ProcessEngine(store, clock=clock)
        line = _refused(store, "bay_a", path)
        assert line.startswith("%s: site: the store holds the data of a site it does not name" % path), line
    finally:
        store.close()


@pytest.mark.parametrize("bad", ["", "   ", None, 3])
def test_a_site_without_a_name_is_refused_before_the_store_is_touched(tmp_path, bad):
    store = JournaledStore(str(tmp_path / "pemkre_store"))
    try:
        line = _refused(store, bad, "x")
        assert "the site's name must be a non-empty string" in line, line
        assert _all(store) == []
    finally:
        store.close()
