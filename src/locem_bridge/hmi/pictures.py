"""Wall pictures the simulated worksite draws on request, asked for no more often than the page needs them.

:class:`SimPictures` keeps a private folder; :meth:`SimPictures.pictures` asks the worksite to draw into it (the
``draw(folder)`` callable, e.g. the simulator's ``save_outcome`` service) at most every ``period_s`` seconds, and
not again while HICEM stays in the same quiet phase (:data:`QUIET_PHASES`: nothing on the walls changes), and
only when ``can_draw()`` says the worksite is there. It always answers with the pictures the folder holds
(``{wall_id: path}``). ``period_s`` 0 or less: never ask. :meth:`close` removes the folder.
"""
import shutil
import tempfile
import time
from typing import Callable, Dict, Optional

from .hicem_view import wall_pictures_in

#: HICEM phases in which no wall changes: one drawing is enough until the phase changes
QUIET_PHASES = ("", "idle", "ended", "failed", "stopped")


class SimPictures:
    def __init__(self, period_s: float, draw: Callable[[str], None], can_draw: Callable[[], bool],
                 clock: Callable[[], float] = time.monotonic, prefix: str = "operator_hmi_walls_") -> None:
        self.period_s = float(period_s)
        self.draw = draw
        self.can_draw = can_draw
        self.clock = clock
        self.folder = tempfile.mkdtemp(prefix=prefix)
        self._asked_at = -1e9
        self._drawn_phase: Optional[str] = None

    def pictures(self, phase: str) -> Dict[str, str]:
        """``{wall_id: path}`` in the folder, after asking for a new drawing when one is due (see above)."""
        now = self.clock()
        if self.period_s <= 0 or now - self._asked_at < self.period_s:
            return wall_pictures_in(self.folder)
        if phase == self._drawn_phase and phase in QUIET_PHASES:
            return wall_pictures_in(self.folder)        # nothing moves: no need to redraw
        self._asked_at = now
        if self.can_draw():
            self.draw(self.folder)
            self._drawn_phase = phase
        return wall_pictures_in(self.folder)

    def close(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)
