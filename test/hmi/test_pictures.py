"""The simulated worksite's wall pictures on the page: drawn into a private folder at most every period, not
again while HICEM stays in a quiet phase, not asked for when the worksite is not there, the folder removed at
the end."""
import os

from locem_bridge.hmi import SimPictures


class Worksite:
    """Draws one picture per wall into the folder it is given, counting the drawings."""

    def __init__(self):
        self.drawings = 0
        self.up = True

    def draw(self, folder):
        self.drawings += 1
        for wall in ("wall_1", "wall_2"):
            with open(os.path.join(folder, wall + ".png"), "wb") as fh:
                fh.write(b"drawing %d" % self.drawings)


class Clock:
    t = 100.0

    def __call__(self):
        return self.t


def test_drawn_at_most_every_period_and_not_again_while_nothing_moves():
    site, clock = Worksite(), Clock()
    pics = SimPictures(5.0, site.draw, lambda: site.up, clock=clock)
    try:
        first = pics.pictures("running")
        assert sorted(first) == ["wall_1", "wall_2"] and site.drawings == 1
        assert open(first["wall_1"], "rb").read() == b"drawing 1"
        clock.t += 4.9
        assert pics.pictures("running") == first and site.drawings == 1      # within the period: the same files
        clock.t += 0.1
        pics.pictures("running")
        assert site.drawings == 2                                           # due again while the job runs
        clock.t += 5.0
        pics.pictures("ended")
        assert site.drawings == 3                                           # the phase changed: draw once more
        clock.t += 50.0
        assert pics.pictures("ended") == first and site.drawings == 3         # nothing moves: no new drawing
        clock.t += 5.0
        site.up = False
        pics.pictures("running")
        assert site.drawings == 3                                           # worksite away: not asked
        clock.t += 5.0
        site.up = True
        pics.pictures("running")
        assert site.drawings == 4 and open(first["wall_1"], "rb").read() == b"drawing 4"
    finally:
        pics.close()
    assert not os.path.exists(pics.folder)


def test_a_period_of_zero_never_asks_the_worksite():
    site = Worksite()
    pics = SimPictures(0.0, site.draw, lambda: True, clock=Clock())
    try:
        assert pics.pictures("running") == {} and site.drawings == 0
    finally:
        pics.close()
