"""Column/unit mapping for foreign CSVs: inferred from headers, given as options, or from a TOML profile.

A mapping says, for each source column, which imutool column it becomes and the unit its values are in.
Examples of headers understood: ``Gyroscope X (deg/s)``, ``acc_x_g``, ``mag_x_gauss``, ``Time [s]``,
``ACC_Heave_SB [m/s2]``, ``gyr_z``. Columns that are not sensor axes are kept as plain channels under a
cleaned name (``Heave [m]`` → ``heave`` in m), so labels such as ``movement`` survive.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from . import units as _units
from .errors import ImutoolError

try:  # Python 3.11+
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

_QUANTITY_WORDS = [
    ("gyro", ("gyroscope", "gyro", "gyr", "angular_velocity", "angvel", "omega", "rate")),
    ("accel", ("accelerometer", "acceleration", "accel", "acc", "linear_acceleration")),
    ("mag", ("magnetometer", "magnetic_field", "magnetic", "mag", "compass")),
    ("temp", ("temperature", "temp")),
]
_TIME_WORDS = ("time", "timestamp", "t", "stamp", "seconds", "time_s")
_DEFAULT_UNIT = {"gyro": "rad/s", "accel": "m/s^2", "mag": "uT", "temp": "degC", "time": "s"}
_CANONICAL = {"time", "temp"} | {f"{q}_{a}" for q in ("gyro", "accel", "mag") for a in "xyz"}


@dataclass
class ColumnMap:
    """How one source column becomes an imutool column."""

    source: str
    target: str
    unit: str | None  # unit of the source values; None = dimensionless / unknown, kept as is
    inferred: bool = True
    unit_assumed: bool = False
    scale: float = 1.0  # extra multiplier (counts → unit), applied before the unit conversion

    def describe(self) -> str:
        u = self.unit or "-"
        note = " (unit assumed)" if self.unit_assumed else ""
        sc = f" ×{self.scale:g}" if self.scale != 1.0 else ""
        return f"{self.source!r} → {self.target} [{u}{sc}]{note}"


@dataclass
class Mapping:
    columns: list[ColumnMap] = field(default_factory=list)
    origin: str = "inferred"

    def describe(self) -> list[str]:
        return [c.describe() for c in self.columns]

    def as_meta(self) -> str:
        return "; ".join(
            f"{c.source}->{c.target}[{c.unit or '-'}{'' if c.scale == 1 else f'x{c.scale:g}'}]" for c in self.columns
        )


def clean_name(header: str) -> str:
    """A column name reduced to lower-case identifier form, units in brackets removed."""
    h = re.sub(r"[\(\[\{].*?[\)\]\}]", "", header)
    h = re.sub(r"[^0-9a-zA-Z]+", "_", h).strip("_").lower()
    return h or "col"


def _unit_in(header: str) -> str | None:
    m = re.search(r"[\(\[\{]\s*([^\)\]\}]*)\s*[\)\]\}]", header)
    if m:
        return m.group(1).strip()
    return None


_ALL_QWORDS = {w for q, words in _QUANTITY_WORDS if q != "temp" for w in words}
_SHORT_AXIS = {"a": "acc", "g": "gyro", "w": "gyro", "m": "mag"}  # ax, gy, wz, mx ...


def _split_axis_tokens(tokens: list[str]) -> list[str]:
    """``accz`` → ``acc, z``; ``gyrox`` → ``gyro, x``; a lone ``ax``/``gy``/``mz`` → quantity + axis."""
    out: list[str] = []
    for t in tokens:
        if len(t) >= 2 and t[-1] in "xyz" and t[:-1] in _ALL_QWORDS:
            out += [t[:-1], t[-1]]
        elif len(tokens) == 1 and len(t) == 2 and t[0] in _SHORT_AXIS and t[1] in "xyz":
            out += [_SHORT_AXIS[t[0]], t[1]]
        else:
            out.append(t)
    return out


def _infer_one(header: str) -> ColumnMap:
    explicit_unit = _unit_in(header)
    name = clean_name(header)
    tokens = _split_axis_tokens([t for t in name.split("_") if t])
    # time
    if name in _TIME_WORDS or (tokens and tokens[0] in ("time", "timestamp") and len(tokens) <= 2):
        unit = explicit_unit
        if unit is None and len(tokens) == 2 and _units.is_known(tokens[1]):
            unit = tokens[1]
        if unit is None:
            return ColumnMap(header, "time", "s", unit_assumed=True)
        return ColumnMap(header, "time", unit)
    axis = None
    for t in tokens:
        if t in ("x", "y", "z"):
            axis = t
    quantity = None
    if axis is not None:
        joined = "_".join(tokens)
        for q, words in _QUANTITY_WORDS:
            if q == "temp":
                continue
            if any(w == t for t in tokens for w in words) or any(joined.startswith(w) for w in words):
                quantity = q
                break
    if quantity is None and any(t in ("temp", "temperature") for t in tokens) and len(tokens) <= 3:
        quantity = "temp"
    if quantity is None:
        unit = explicit_unit if explicit_unit and _units.is_known(explicit_unit) else None
        target = name
        if header in _CANONICAL or re.fullmatch(r"[a-z_][a-z0-9_]*", header):
            target = header
        return ColumnMap(header, target, unit)
    target = quantity if quantity == "temp" else f"{quantity}_{axis}"
    unit = explicit_unit
    if unit is None:
        for t in tokens:
            if t not in ("x", "y", "z") and _units.is_known(t) and t not in ("t", "n", "m", "c", "1", "-"):
                unit = t
        # short forms that clash with other words: acc_x_g, mag_x_t (tesla), temp_c
        last = tokens[-1]
        if unit is None and last in ("g", "t", "c") and last != axis:
            unit = {"g": "g", "t": "T", "c": "degC"}[last]
    if unit is None:
        return ColumnMap(header, target, _DEFAULT_UNIT[quantity], unit_assumed=True)
    return ColumnMap(header, target, unit)


_QUAT_WORDS = ("orientation", "quaternion", "quat", "attitude")
_REF_WORDS = ("vicon", "ref", "reference", "truth", "groundtruth", "mocap", "optitrack", "qualisys")


def _quaternions(cols: list[ColumnMap]) -> None:
    """Four columns ``<P> w, x, y, z`` whose name P says orientation/quaternion become ``qw..qz`` (body → world as
    the file gives it), or ``ref_qw..ref_qz`` when P names a reference system (Vicon, mocap, truth...)."""
    groups: dict[str, dict[str, ColumnMap]] = {}
    for c in cols:
        tokens = clean_name(c.source).split("_")
        if len(tokens) >= 2 and tokens[-1] in ("w", "x", "y", "z") and any(w in tokens[:-1] for w in _QUAT_WORDS):
            groups.setdefault("_".join(tokens[:-1]), {})[tokens[-1]] = c
    for prefix, by_axis in groups.items():
        if len(by_axis) != 4 or any(c.target.startswith(("gyro", "accel", "mag")) for c in by_axis.values()):
            continue
        ref = any(w in prefix.split("_") for w in _REF_WORDS)
        for a, c in by_axis.items():
            c.target, c.unit, c.unit_assumed = ("ref_q" if ref else "q") + a, None, False


def infer_mapping(headers: list[str]) -> Mapping:
    """Infer the mapping of a foreign header row; raises ImutoolError where two columns claim one target."""
    cols = [_infer_one(h) for h in headers]
    _quaternions(cols)
    seen: dict[str, str] = {}
    for c in cols:
        if c.target in seen:
            # keep both, make the later one unique rather than lose it
            i = 2
            while f"{c.target}_{i}" in seen:
                i += 1
            c.target = f"{c.target}_{i}"
        seen[c.target] = c.source
    for c in cols:
        q = _expected_quantity(c.target)
        c.unit = resolve_unit(c.unit, q)
        if q and c.unit:
            try:
                _units.factor_to_si(c.unit, q)
            except ImutoolError as e:
                raise ImutoolError(f"column {c.source!r}: {e}") from None
    return Mapping(cols, "inferred")


def resolve_unit(unit: str | None, quantity: str | None) -> str | None:
    """Unit names that mean different things per quantity: on a magnetometer ``G``/``mG`` are gauss and
    milligauss (not g and milli-g)."""
    if unit and quantity == "magnetic" and unit.strip().lower() in ("g", "mg"):
        return "gauss" if unit.strip().lower() == "g" else "mgauss"
    return unit


def _expected_quantity(target: str) -> str | None:
    base = target.split("_")[0]
    return {
        "gyro": "angular_rate",
        "accel": "acceleration",
        "mag": "magnetic",
        "time": "time",
        "temp": "temperature",
    }.get(base)


def parse_mapping_option(spec: str, headers: list[str]) -> Mapping:
    """Mapping from a command-line option: ``"Gyro X=gyro_x:deg/s, Acc Z=accel_z:g*0.001"``.

    Each item is ``source=target[:unit][*scale]``; columns not named are inferred.
    """
    given: dict[str, ColumnMap] = {}
    for item in filter(None, (s.strip() for s in spec.split(","))):
        if "=" not in item:
            raise ImutoolError(f"--columns item {item!r}: expected SOURCE=TARGET[:UNIT][*SCALE]")
        src, rhs = (s.strip() for s in item.split("=", 1))
        scale = 1.0
        if "*" in rhs:
            rhs, sc = rhs.split("*", 1)
            try:
                scale = float(sc)
            except ValueError:
                raise ImutoolError(f"--columns item {item!r}: scale {sc!r} is not a number") from None
            _scale(scale, f"--columns item {item!r}: scale")
        target, _, unit = rhs.partition(":")
        if src not in headers:
            raise ImutoolError(f"--columns: no column {src!r} in the file (has: {', '.join(headers)})")
        unit = resolve_unit(unit.strip() or None, _expected_quantity(target.strip()))
        if unit:
            _units.lookup(unit)
        given[src] = ColumnMap(src, target.strip(), unit, inferred=False, scale=scale)
    inferred = infer_mapping(headers)
    cols = [given.get(c.source, c) for c in inferred.columns]
    return Mapping(cols, "options")


def load_profile(path: str) -> dict:
    """Read a TOML sensor profile::

    name = "x-io NGIMU"
    [columns]
    "Gyroscope X (deg/s)" = { to = "gyro_x", unit = "deg/s" }
    "ax" = { to = "accel_x", unit = "counts", scale = 0.000598 }   # counts × scale → m/s²
    """
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except OSError as e:
        raise ImutoolError(f"cannot read profile: {e.strerror}", path=path) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ImutoolError(f"not valid TOML: {e}", path=path) from None


def _scale(v: object, what: str, path: str | None = None) -> float:
    """A mapping's scale factor: a finite non-zero number (a zero scale would erase the channel)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v == 0:
        raise ImutoolError(f"{what} = {v!r} must be a finite non-zero number", path=path)
    return float(v)


def mapping_from_profile(profile: dict, headers: list[str], path: str = "profile") -> Mapping:
    cols_spec = profile.get("columns", {})
    if not isinstance(cols_spec, dict):
        raise ImutoolError("[columns] must be a table", path=path)
    given: dict[str, ColumnMap] = {}
    for src, spec in cols_spec.items():
        if isinstance(spec, str):
            spec = {"to": spec}
        if not isinstance(spec, dict) or "to" not in spec:
            raise ImutoolError(f"column {src!r}: expected {{ to = ..., unit = ... }}", path=path)
        unknown = sorted(set(spec) - {"to", "unit", "scale"})
        if unknown:
            raise ImutoolError(f"column {src!r}: unknown key(s) {', '.join(unknown)} (to, unit, scale)", path=path)
        if not isinstance(spec["to"], str) or not spec["to"].strip():
            raise ImutoolError(f"column {src!r}: to = {spec['to']!r} must be a column name (a string)", path=path)
        unit = spec.get("unit")
        if unit is not None and not isinstance(unit, str):
            raise ImutoolError(f'column {src!r}: unit = {unit!r} must be a string such as "deg/s"', path=path)
        scale = _scale(spec.get("scale", 1.0), f"column {src!r}: scale", path)
        if unit in ("counts", "count", "lsb"):
            q = _expected_quantity(spec["to"])
            unit = _DEFAULT_UNIT.get(spec["to"].split("_")[0]) if q else None
        elif unit:
            unit = resolve_unit(unit, _expected_quantity(spec["to"]))
            try:
                _units.lookup(unit)
            except ImutoolError as e:
                raise ImutoolError(f"column {src!r}: {e}", path=path) from None
        if src not in headers:
            raise ImutoolError(f"column {src!r} named in the profile is not in the file", path=path)
        given[src] = ColumnMap(src, spec["to"], unit, inferred=False, scale=scale)
    inferred = infer_mapping(headers)
    return Mapping([given.get(c.source, c) for c in inferred.columns], f"profile {path}")
