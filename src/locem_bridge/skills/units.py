"""The units a skill parameter may carry: the LOCEM spelling (``CommandSpec`` arguments, tree port ``unit=``) and
its QUDT unit (``http://qudt.org/vocab/unit/``). A unit not listed here is refused when the model is built."""
from typing import Dict

QUDT_UNIT = "http://qudt.org/vocab/unit/"

#: LOCEM unit -> QUDT unit local name ("" = unitless: no sk:unit triple)
UNITS: Dict[str, str] = {
    "": "",
    "m": "M",
    "rad": "RAD",
    "s": "SEC",
    "bar": "BAR",
    "N": "N",
    "kg": "KiloGM",
    "m/s": "M-PER-SEC",
    "rad/s": "RAD-PER-SEC",
    "m/s^2": "M-PER-SEC2",
    "rad/s^2": "RAD-PER-SEC2",
    "Hz": "HZ",
    "A": "A",
    "V": "V",
    "deg": "DEG",
    "mm": "MilliM",
    "ms": "MilliSEC",
}


def qudt_iri(unit: str) -> str:
    """The QUDT IRI of a LOCEM unit ("" for unitless); KeyError for a unit that is not listed."""
    local = UNITS[unit]
    return QUDT_UNIT + local if local else ""
