"""Writing a small file whole: what a crash or a power loss must never leave half written.

:func:`write_whole` writes the text to a new file beside ``path``, syncs it to the disk, renames it over ``path``
and syncs the folder, so a reader finds either the old file or the new one, also after a power loss. Used for the
run's records that a resume reads (the job's journal, ``run.json``, LOCEM's mounted tool, the simulated world's
snapshot).
"""
import os
from typing import Union


def write_whole(path: str, data: Union[str, bytes]) -> None:
    """Replace ``path`` by ``data`` (text as UTF-8, or bytes), whole or not at all; the folder is created (OSError
    when the disk refuses; ``path`` is then as it was)."""
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    tmp = path + ".tmp"
    with open(tmp, "wb") as handle:
        handle.write(data.encode("utf-8") if isinstance(data, str) else data)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)
    try:                                  # the rename itself reaches the disk
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError:
        pass
