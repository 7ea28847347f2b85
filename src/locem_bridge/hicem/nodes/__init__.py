"""HICEM's node library: the leaf classes trees name in their XML (the paper's HHLC executes them).

* :mod:`.generic`       use-case-free nodes: health and device checks, LOCEM commands, the data store, operator
  prompts, logging, scan ingestion.
* :mod:`.plasterboard`  the plasterboard use case: taping poses and paths, area rasters, transits past walls.
* :mod:`.area_work`     section progress of area work (spraying, sanding): sections done, left for manual work.

Each module lists its classes in ``LIBRARY``; :func:`locem_bridge.hicem.registry.default_registry` registers
them.
"""
