"""The one way to open PEMKRE's triplestore by kind, for every process that embeds or serves PEMKRE.

Kinds (:data:`STORE_KINDS`): ``journal`` (:class:`~.journal_store.JournaledStore` at ``path``: survives ``kill -9``;
``fsync`` also a power loss), ``rocksdb`` (:class:`~.oxigraph_store.OxigraphStore` on disk at ``path``),
``memory`` (an in-memory Oxigraph store; ``path`` unused), ``sparql`` (a SPARQL 1.1 server at ``query_url`` /
``update_url``; ``path`` and ``fsync`` unused: the server keeps the data): by default a
:class:`~.mirror_store.MirroredSparqlStore` (reads from an exact copy in this process, checked against the server's
version marker once per decision); ``mirror=False``: the plain :class:`~.sparql_store.SparqlStore` (every read asks
the server).
``fresh`` starts from an empty store: it removes the store folder first, or on a server drops PEMKRE's named graphs
(those under :data:`~locem_bridge.pemkre.vocab.GRAPHS`; other graphs on the server are left alone). The caller
closes the store it opened.

A store belongs to one site (:func:`claim_site`): the first PEMKRE started on it with a site name records it; a
PEMKRE of another site is refused before it reads or writes anything else (one configuration line naming the
store and both sites).
"""
import os
import shutil
import time
from typing import Any, Callable, List

from rdflib import Literal

from locem_bridge.common.config_errors import ConfigError

from .errors import StoreError, StoreUnavailable
from .sparql_http import TRANSIENT_STATUSES, HttpStatusError
from .journal_store import JournaledStore
from .oxigraph_store import OxigraphStore
from .store import G_META, ChangeSet, TripleStore
from .vocab import META

STORE_KINDS = ("journal", "rocksdb", "memory", "sparql")
#: the triple recording whose site a store holds: (META.store, META.site, "name") in the meta graph
SITE_SUBJECT, SITE_PREDICATE = META.store, META.site


def open_store(kind: str, path: str, fsync: bool = False, fresh: bool = False, query_url: str = "",
               update_url: str = "", mirror: bool = True, **sparql_options: Any) -> TripleStore:
    """The store of ``kind`` (see the module docstring); ValueError naming the kinds, or the missing URLs."""
    if kind not in STORE_KINDS:
        raise ValueError("store must be %s or %s, got %r" % (", ".join(STORE_KINDS[:-1]), STORE_KINDS[-1], kind))
    if kind == "sparql":
        if not query_url or not update_url:
            raise ValueError("store sparql needs the server's query_url and update_url (e.g. "
                             "http://127.0.0.1:7878/query and http://127.0.0.1:7878/update), got %r and %r"
                             % (query_url, update_url))
        from .mirror_store import MirroredSparqlStore
        from .sparql_store import SparqlStore

        store = (MirroredSparqlStore if mirror else SparqlStore)(query_url, update_url, **sparql_options)
        if fresh:
            try:
                store.drop_pemkre_graphs()
            except Exception:
                store.close()
                raise
        return store
    if kind == "memory":
        return OxigraphStore(None)
    if fresh and os.path.isdir(path):
        shutil.rmtree(path)
    if kind == "journal":
        return JournaledStore(path, fsync=fsync)
    return OxigraphStore(path)


def open_store_waiting(opener: Callable[[], TripleStore], kind: str, log: Callable[[str], None],
                       stop: Callable[[], bool] = lambda: False, first_delay_s: float = 0.5, max_delay_s: float = 5.0,
                       sleep: Callable[[float], None] = time.sleep) -> TripleStore:
    """The store from ``opener()`` (e.g. :func:`open_store`), for a node starting up. While its server cannot be
    reached (StoreUnavailable, or a gateway's 502/503/504 in front of it) it waits and tries again
    (``first_delay_s`` doubling up to ``max_delay_s``), one ``log`` line per attempt naming the endpoint and the
    reason, until ``stop()`` (then the last StoreUnavailable is raised: not a configuration error); the node
    offers nothing meanwhile. A SPARQL server that answers wrongly (HTML, other HTTP errors, two URLs of different
    datasets) or a bad store setting (ValueError) does not heal by waiting: :class:`ConfigError`, one line
    (ros/startup.py). An embedded store's own StoreError (e.g. its lock while the previous process exits) is
    raised as it is."""
    delay, attempts = first_delay_s, 0
    while True:
        attempts += 1
        try:
            return opener()
        except (StoreUnavailable, HttpStatusError) as exc:
            if isinstance(exc, HttpStatusError) and exc.status not in TRANSIENT_STATUSES:
                if kind != "sparql":
                    raise
                raise ConfigError("store %s: %s" % (kind, exc), key="~store") from None
            if stop():
                raise
            log("PEMKRE waiting for its store (attempt %d, next in %.1f s): %s" % (attempts, delay, exc))
            waited = 0.0
            while waited < delay and not stop():      # in slices: a shutdown is not held up
                step = min(0.1, delay - waited)
                sleep(step)
                waited += step
            if stop():
                raise
            delay = min(max_delay_s, delay * 2)
        except (StoreError, ValueError) as exc:
            if isinstance(exc, StoreError) and kind != "sparql":
                raise
            raise ConfigError("store %s: %s" % (kind, exc), key="~store") from None


def claim_site(store: TripleStore, site: str, where: str) -> bool:
    """Make sure ``store`` holds the data of ``site`` (a site's name) before PEMKRE uses it: an empty store is
    claimed for it (True); one that names ``site`` is used as it is (False); one that names another site, or one
    a PEMKRE has used without naming its site (its ontologies loaded, no site recorded), is refused with a
    :class:`ConfigError` naming ``where`` (the store's folder or endpoint) and what it holds, and nothing is
    written. Two PEMKREs of different sites claiming one empty server dataset at the same moment: the one that
    reads back only its own name keeps it; one that reads back two takes its own back and is refused."""
    if not isinstance(site, str) or not site.strip():
        raise ConfigError("the site's name must be a non-empty string, got %r" % (site,), key="site.name")
    allowed = ("a store (folder or server dataset) of site %r or an empty one (pemkre.launch fresh:=true empties "
               "one)" % site)
    mine = (SITE_SUBJECT, SITE_PREDICATE, Literal(site), G_META)

    def held() -> List[str]:
        return sorted(str(o) for o in store.objects(SITE_SUBJECT, SITE_PREDICATE, (G_META,)))

    names = held()
    if not names:
        if store.value(META.ontology, META.schemaHash, (G_META,)) is not None:
            raise ConfigError("the store holds the data of a site it does not name (a PEMKRE started without a "
                              "site used it), not known to be this launch's site %r: PEMKRE starts no process on "
                              "it" % site, file=where, key="site", allowed=allowed)
        store.apply(ChangeSet(add=[mine]))
        names = held()
        if names == [site]:
            return True
        if site in names:                        # another site claimed it at the same moment: ours goes back
            store.apply(ChangeSet(remove=[mine]))
    if names != [site]:
        raise ConfigError("the store holds the data of site %s, not of this launch's site %r: PEMKRE starts no "
                          "process on it" % (" and ".join(repr(n) for n in names), site), file=where, key="site",
                          allowed=allowed)
    return False


def claim_site_or_close(store: TripleStore, site: str, where: str, site_file: str) -> bool:
    """:func:`claim_site` for a node starting on ``store``: on any failure the store is closed first, and a
    :class:`ConfigError` names ``site_file`` unless it names the store itself (a refused store)."""
    try:
        return claim_site(store, site, where)
    except ConfigError as exc:
        store.close()
        raise exc.in_file(site_file)
    except Exception:
        store.close()
        raise
