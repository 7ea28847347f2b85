"""Task statuses: what HICEM reports to PEMKRE about one task (``set_task_status``, docs/contracts.md).

The one definition: PEMKRE accepts exactly these, HICEM reports them, the ROS service carries them as text.
A task goes ``in_progress`` first, then ``succeeded`` or ``failed``; each status once per task.
"""
from typing import Tuple

IN_PROGRESS = "in_progress"
"""HICEM started the task's tree."""
SUCCEEDED = "succeeded"
"""The task's tree ended in SUCCESS (its detail: e.g. the operator's ``valid`` / ``invalid``)."""
FAILED = "failed"
"""The task's tree ended in FAILURE, or the task could not be run (its detail: the reason)."""

TASK_STATUSES: Tuple[str, ...] = (IN_PROGRESS, SUCCEEDED, FAILED)
"""Every status a report may carry, in the order a task takes them."""
