"""Units: names users write, the quantity they measure and the factor to SI.

SI inside (docs/architecture.md): s, rad/s, m/s², µT (the magnetometer's SI-prefixed working unit), rad, m, m/s, °C.
Angle channels are degrees at every user-facing surface; :data:`ANGLE_UNITS` converts both ways.
"""

from __future__ import annotations

import math

from .errors import ImutoolError

STANDARD_GRAVITY = 9.80665  # m/s², the conventional value used to convert "g" readings

# unit name (lower case, as written) -> (quantity, factor to the working unit)
_UNITS: dict[str, tuple[str, float]] = {}


def _add(quantity: str, factor: float, *names: str) -> None:
    for n in names:
        _UNITS[n] = (quantity, factor)


_add("time", 1.0, "s", "sec", "secs", "second", "seconds")
_add("time", 1e-3, "ms", "msec", "millisecond", "milliseconds")
_add("time", 1e-6, "us", "µs", "usec", "microsecond", "microseconds")
_add("time", 1e-9, "ns", "nsec", "nanosecond", "nanoseconds")
_add("angular_rate", 1.0, "rad/s", "rad s-1", "rad/sec", "rads", "rps_rad", "radps", "rad_s")
_add("angular_rate", math.pi / 180.0, "deg/s", "°/s", "dps", "deg/sec", "degs", "deg s-1", "degps", "deg_s")
_add("angular_rate", math.pi / 180.0 / 60.0, "deg/min", "°/min")
_add("angular_rate", 1e-3, "mrad/s")
_add("angular_rate", math.pi / 180.0 * 1e-3, "mdps", "mdeg/s")
_add("acceleration", 1.0, "m/s2", "m/s^2", "m/s²", "ms-2", "m s-2", "mps2", "m_s2", "ms2")
_add("acceleration", STANDARD_GRAVITY, "g", "g0", "gee")
_add("acceleration", STANDARD_GRAVITY * 1e-3, "mg")
_add("magnetic", 1.0, "ut", "µt", "μt", "microtesla", "utesla")
_add("magnetic", 1e6, "t", "tesla")
_add("magnetic", 1e-3, "nt", "nanotesla")
_add("magnetic", 100.0, "gauss", "gs", "ga")
_add("magnetic", 0.1, "mgauss", "mga", "milligauss", "mgs")
_add("angle", 1.0, "rad", "radian", "radians")
_add("angle", math.pi / 180.0, "deg", "°", "degree", "degrees")
_add("length", 1.0, "m", "meter", "metre", "meters", "metres")
_add("length", 1e-3, "mm")
_add("length", 1e-2, "cm")
_add("velocity", 1.0, "m/s", "mps")
_add("velocity", 1852.0 / 3600.0, "kn", "kt", "knot", "knots")
_add("temperature", 1.0, "c", "°c", "degc", "celsius")
_add("force", 1.0, "n")
_add("dimensionless", 1.0, "1", "-", "counts", "count", "lsb")

# the working (SI) unit of each quantity, as written in headers and metadata
SI_UNIT = {
    "time": "s",
    "angular_rate": "rad/s",
    "acceleration": "m/s^2",
    "magnetic": "uT",
    "angle": "rad",
    "length": "m",
    "velocity": "m/s",
    "temperature": "degC",
    "force": "N",
    "dimensionless": "1",
}

# what each canonical sensor channel measures
CHANNEL_QUANTITY = {
    "time": "time",
    "gyro": "angular_rate",
    "accel": "acceleration",
    "mag": "magnetic",
    "temp": "temperature",
}


def normalize_unit_name(unit: str) -> str:
    u = unit.strip().lower().replace(" ", "").replace("**", "^")
    return u


def lookup(unit: str) -> tuple[str, float]:
    """(quantity, factor to the working unit) for a unit name; raises ImutoolError if unknown."""
    u = normalize_unit_name(unit)
    if u in _UNITS:
        return _UNITS[u]
    # tolerate "m/s^2" written "m/s2" etc. already covered; try dropping a trailing period
    if u.rstrip(".") in _UNITS:
        return _UNITS[u.rstrip(".")]
    raise ImutoolError(f"unknown unit {unit!r}; known units: {', '.join(sorted(set(_UNITS)))}")


def is_known(unit: str) -> bool:
    try:
        lookup(unit)
        return True
    except ImutoolError:
        return False


def factor_to_si(unit: str, quantity: str | None = None) -> float:
    """Multiply values in ``unit`` by this to get the working SI unit; checks the quantity if given."""
    q, f = lookup(unit)
    if quantity is not None and q != quantity and q != "dimensionless":
        raise ImutoolError(f"unit {unit!r} measures {q}, but a {quantity.replace('_', ' ')} unit was expected")
    return f


def convert(values, from_unit: str, to_unit: str):
    """Convert values between two units of the same quantity."""
    q1, f1 = lookup(from_unit)
    q2, f2 = lookup(to_unit)
    if q1 != q2:
        raise ImutoolError(f"cannot convert {from_unit!r} ({q1}) to {to_unit!r} ({q2})")
    if f1 == f2:
        return values
    return values * (f1 / f2)
