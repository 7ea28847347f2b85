"""The bottom floor: meanings every layer shares, defined once, importing nothing else of the package.

Modules (each one concept):

* :mod:`.finish`         the ``finish`` vocabulary of a wall area (bare, sprayed, sanded)
* :mod:`.base_kinematics` wheeled base kinematics, mecanum and differential (the base bridge and the simulated worksite)
* :mod:`.rate`           a fixed-rate loop timer for device loops
* :mod:`.config_errors`  one-line configuration errors and the one YAML reader of configuration files
* :mod:`.config_keys`    checked reading of a configuration mapping (type, range, allowed values, known keys)
* :mod:`.can_bus`        opening the base's CAN bus (allowed interfaces, own-echo filter; bridge and simulator)
* :mod:`.geometry`       angle wrapping, rotation vectors / matrices / RPY / quaternions, rigid transforms
* :mod:`.raster_progress` the progress text of a raster command (LOCEM's SPRAY_AREA feedback, HICEM's resume)
* :mod:`.health`         health levels (OK, WARN, ERROR, STALE) and the grading of a device's health record
* :mod:`.locem_codes`    LOCEM's answer codes (``OK``, ``INVALID_ARGUMENT``, ...)
* :mod:`.task_status`    the task statuses HICEM reports to PEMKRE (``in_progress``, ``succeeded``, ``failed``)

Anything that crosses layers (LOCEM codes, task statuses, the next-action record, health grading, geometry,
CAN bus opening) belongs here, never copied into a layer. Modules here import only the standard library, numpy
and PyYAML (python-can inside :mod:`.can_bus`'s functions), never another ``locem_bridge`` package.
"""
