"""SI units used by the models, with their base-unit exponents for modelDescription.xml.

``build_fmu.py`` writes a ``<UnitDefinitions>`` entry for every unit an FMU uses; a unit missing
here stops the build (every variable must have a known unit).  ``""`` is dimensionless.
Units whose exponent is not an integer (``N/m^n`` of a Hunt-Crossley stiffness with a general
``n``) are declared by name only: FMI 2.0 base-unit exponents are integers.
"""

UNITS = {
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "m.s": {"m": 1, "s": 1},
    "s": {"s": 1},
    "1/s": {"s": -1},
    "kg": {"kg": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "J": {"kg": 1, "m": 2, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
    "1/m2": {"m": -2},
    "1/(m.s)": {"m": -1, "s": -1},
    "N/m^n": None,
    "N.s/m^(n+1)": None,
}
