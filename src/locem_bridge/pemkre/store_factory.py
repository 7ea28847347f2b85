"""The one way to open PEMKRE's triplestore by kind, for every process that embeds or serves PEMKRE.

Kinds (:data:`STORE_KINDS`): ``journal`` (:class:`~.journal_store.JournaledStore` at ``path``: survives ``kill -9``;
``fsync`` also a power loss), ``rocksdb`` (:class:`~.oxigraph_store.OxigraphStore` on disk at ``path``),
``memory`` (an in-memory Oxigraph store; ``path`` unused). ``fresh`` removes the store folder first. The caller
closes the store it opened.
"""
import os
import shutil

from .journal_store import JournaledStore
from .oxigraph_store import OxigraphStore
from .store import TripleStore

STORE_KINDS = ("journal", "rocksdb", "memory")


def open_store(kind: str, path: str, fsync: bool = False, fresh: bool = False) -> TripleStore:
    """The store of ``kind`` at ``path`` (see the module docstring); ValueError naming the kinds otherwise."""
    if kind not in STORE_KINDS:
        raise ValueError("store must be %s or %s, got %r" % (", ".join(STORE_KINDS[:-1]), STORE_KINDS[-1], kind))
    if kind == "memory":
        return OxigraphStore(None)
    if fresh and os.path.isdir(path):
        shutil.rmtree(path)
    if kind == "journal":
        return JournaledStore(path, fsync=fsync)
    return OxigraphStore(path)
