"""Magnetic variation (declination) from the World Magnetic Model, and a position/date from an NMEA log.

The model is evaluated by ``pygeomag`` (pure Python port of NOAA's WMM code, coefficient files WMM-2015 …
WMM-2025 bundled; optional extra ``imutool[wmm]``). Declination D in degrees, east positive (= variation:
true = magnetic + D). The model for the date is chosen by epoch (WMM-2025 for 2025.0–2030.0, WMM-2020 for
2020.0–2025.0, WMM-2015v2 for 2015.0–2020.0); dates outside 2015–2030 are refused. Near the magnetic poles
(horizontal field < 2000 nT, the WMM "blackout zone") the declination is refused, and a warning is given in
the caution zone (< 6000 nT). The model's own declination uncertainty (1 σ, WMM error model) is returned too.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from datetime import date, datetime, timezone

from formats.errors import ImutoolError

_MODELS = (
    (2025.0, 2030.0, "WMM_2025.COF", "WMM-2025"),
    (2020.0, 2025.0, "WMM_2020.COF", "WMM-2020"),
    (2015.0, 2020.0, "WMM_2015v2.COF", "WMM-2015v2"),
)


@dataclass
class Variation:
    """Declination (deg, E +) with its 1-σ uncertainty (deg), the model and where/when it applies."""

    deg: float
    std_deg: float | None
    model: str
    latitude: float
    longitude: float
    decimal_year: float
    warning: str | None = None

    def source(self) -> str:
        return f"{self.model} at {self.latitude:.3f}, {self.longitude:.3f}, {self.decimal_year:.2f}" + (
            f", ± {self.std_deg:.2f}° (1σ)" if self.std_deg is not None else ""
        )


def decimal_year(when: date | datetime) -> float:
    """Decimal year (2025.0 = 1 Jan 2025 00:00 UTC)."""
    if isinstance(when, datetime):
        d = when.astimezone(timezone.utc) if when.tzinfo else when.replace(tzinfo=timezone.utc)
    else:
        d = datetime(when.year, when.month, when.day, tzinfo=timezone.utc)
    y0 = datetime(d.year, 1, 1, tzinfo=timezone.utc)
    y1 = datetime(d.year + 1, 1, 1, tzinfo=timezone.utc)
    return d.year + (d - y0).total_seconds() / (y1 - y0).total_seconds()


def wmm_variation(
    latitude: float, longitude: float, when: date | datetime | float, height_km: float = 0.0
) -> Variation:
    """Declination (deg, E +) at a geodetic position (deg; height km above the WGS-84 ellipsoid) and date
    (date/datetime or decimal year). Raises ImutoolError when pygeomag is missing, the date is outside the
    bundled models, or the position is in a blackout zone."""
    try:
        from pygeomag import GeoMag
    except ImportError:
        raise ImutoolError(
            "the World Magnetic Model needs the optional package pygeomag: "
            "pip install 'imutool[wmm]' (or give --variation)"
        ) from None
    if not (-90.0 <= latitude <= 90.0 and -180.0 <= longitude <= 360.0):
        raise ImutoolError(f"position {latitude}, {longitude} is not a latitude/longitude in degrees")
    y = float(when) if isinstance(when, (int, float)) else decimal_year(when)
    pick = next((m for m in _MODELS if m[0] <= y < m[1] or (m[3] == "WMM-2025" and y == m[1])), None)
    if pick is None:
        raise ImutoolError(f"no World Magnetic Model for {y:.2f} (bundled: 2015.0–2030.0); give --variation")
    _, _, cof, name = pick
    gm = GeoMag(coefficients_file=os.path.join("wmm", cof))
    r = gm.calculate(
        glat=float(latitude), glon=float(longitude), alt=float(height_km), time=y, allow_date_outside_lifespan=False
    )
    if r.h < 2000.0:
        raise ImutoolError(
            f"{latitude:.2f}, {longitude:.2f} is in the WMM blackout zone (horizontal field "
            f"{r.h:.0f} nT < 2000 nT): declination and magnetic compasses are unreliable here"
        )
    warning = None
    if r.h < 6000.0:
        warning = f"WMM caution zone (horizontal field {r.h:.0f} nT < 6000 nT): compass accuracy may be degraded"
    std = None
    try:
        std = float(r.calculate_uncertainty().d)
    except (AttributeError, ValueError):
        std = None
    return Variation(float(r.d), std, name, float(latitude), float(longitude), y, warning)


def parse_position(text: str) -> tuple[float, float]:
    """'lat,lon' in decimal degrees (N, E positive) → (lat, lon)."""
    try:
        a, b = (float(x) for x in text.split(","))
    except ValueError:
        raise ImutoolError(f"--position {text!r}: expected lat,lon in decimal degrees, e.g. 59.44,24.75") from None
    if not (-90 <= a <= 90 and -180 <= b <= 360) or not (math.isfinite(a) and math.isfinite(b)):
        raise ImutoolError(f"--position {text!r}: latitude must be within ±90°, longitude within ±180°")
    return a, b


def position_from_nmea(path: str, max_lines: int = 200_000) -> tuple[float | None, float | None, date | None]:
    """First valid position (RMC status A or GGA fix > 0) and the first RMC/ZDA date in an NMEA log.
    Returns (lat, lon, date) with None for what the log does not carry."""
    import pynmea2

    lat = lon = None
    day: date | None = None
    try:
        fh = open(path, encoding="ascii", errors="replace")
    except OSError as e:
        raise ImutoolError(f"cannot read: {e.strerror}", path=path) from None
    with fh:
        for k, line in enumerate(fh):
            if k >= max_lines or (lat is not None and day is not None):
                break
            i = line.find("$")
            if i < 0 or not any(x in line for x in ("RMC", "GGA", "ZDA")):
                continue
            try:
                s = pynmea2.parse(line[i:].strip(), check=False)
            except (pynmea2.ParseError, ValueError, AttributeError, TypeError):
                continue
            kind = type(s).__name__
            try:
                if kind == "RMC" and getattr(s, "status", "") == "A":
                    if lat is None and s.lat:
                        lat, lon = float(s.latitude), float(s.longitude)
                    if day is None and s.datestamp:
                        day = s.datestamp
                elif kind == "GGA" and lat is None and s.lat and str(s.gps_qual or "0") not in ("0", ""):
                    lat, lon = float(s.latitude), float(s.longitude)
                elif kind == "ZDA" and day is None and s.year:
                    day = date(int(s.year), int(s.month), int(s.day))
            except (ValueError, TypeError, AttributeError):
                continue
    return lat, lon, day
