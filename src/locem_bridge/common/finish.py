"""The ``finish`` of a wall area in a SCAN result (docs/contracts.md): what the perception sees on the surface.

One vocabulary for every layer that produces or reads it -- the simulated perception reports it, HICEM validates
and stores it, PEMKRE turns it into spraying / sanding status -- ordered from bare board to finished.
"""

from typing import Dict, Tuple

BARE, SPRAYED, SANDED = "bare", "sprayed", "sanded"

#: every finish, from bare board to finished; ``bare`` is what an area reported without ``finish`` has
AREA_FINISHES: Tuple[str, ...] = (BARE, SPRAYED, SANDED)

#: finish -> (spraying done, sanding done); ``sanded`` implies sprayed (sanding bare board is not a finish)
WORK_DONE: Dict[str, Tuple[bool, bool]] = {BARE: (False, False), SPRAYED: (True, False), SANDED: (True, True)}
