"""Result codes of every LOCEM command: the one definition. LOCEM answers with them, HICEM checks every reply
against them, the ROS adapters put them on the wire (``response.code``). Extend, never rename: other layers and
scripts match on them."""

from enum import Enum


class Code(str, Enum):
    """The code carried in every LOCEM response (``response.code``)."""

    OK = "OK"
    """The command did what it was asked."""
    INVALID_COMMAND = "INVALID_COMMAND"
    """Unknown name, unparsable string, or a command the interface may not carry."""
    INVALID_ARGUMENT = "INVALID_ARGUMENT"
    """Known command, but an argument is missing, extra, of the wrong type, non-finite or out of range."""
    BUSY = "BUSY"
    """A resource the command needs is occupied by another running command."""
    TIMEOUT = "TIMEOUT"
    """The command did not finish before its deadline; it was told to stop."""
    HARDWARE_ERROR = "HARDWARE_ERROR"
    """A device refused, faulted, or its link is down."""
    ABORTED = "ABORTED"
    """Cancelled by the caller or pre-empted by ``STOP``."""
    NOT_READY = "NOT_READY"
    """The command is known but its backend is not configured or not connected yet."""

    def __str__(self) -> str:  # so f"{code}" gives "OK", not "Code.OK"
        return self.value
