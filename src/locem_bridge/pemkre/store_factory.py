"""The one way to open PEMKRE's triplestore by kind, for every process that embeds or serves PEMKRE.

Kinds (:data:`STORE_KINDS`): ``journal`` (:class:`~.journal_store.JournaledStore` at ``path``: survives ``kill -9``;
``fsync`` also a power loss), ``rocksdb`` (:class:`~.oxigraph_store.OxigraphStore` on disk at ``path``),
``memory`` (an in-memory Oxigraph store; ``path`` unused), ``sparql`` (:class:`~.sparql_store.SparqlStore` on a
SPARQL 1.1 server at ``query_url`` / ``update_url``; ``path`` and ``fsync`` unused: the server keeps the data).
``fresh`` starts from an empty store: it removes the store folder first, or on a server drops PEMKRE's named graphs
(those under :data:`~locem_bridge.pemkre.vocab.GRAPHS`; other graphs on the server are left alone). The caller
closes the store it opened.
"""
import os
import shutil
from typing import Any

from .journal_store import JournaledStore
from .oxigraph_store import OxigraphStore
from .store import TripleStore

STORE_KINDS = ("journal", "rocksdb", "memory", "sparql")


def open_store(kind: str, path: str, fsync: bool = False, fresh: bool = False, query_url: str = "",
               update_url: str = "", **sparql_options: Any) -> TripleStore:
    """The store of ``kind`` (see the module docstring); ValueError naming the kinds, or the missing URLs."""
    if kind not in STORE_KINDS:
        raise ValueError("store must be %s or %s, got %r" % (", ".join(STORE_KINDS[:-1]), STORE_KINDS[-1], kind))
    if kind == "sparql":
        if not query_url or not update_url:
            raise ValueError("store sparql needs the server's query_url and update_url (e.g. "
                             "http://127.0.0.1:7878/query and http://127.0.0.1:7878/update), got %r and %r"
                             % (query_url, update_url))
        from .sparql_store import SparqlStore

        store = SparqlStore(query_url, update_url, **sparql_options)
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
