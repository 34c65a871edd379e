"""The calibration file (TOML): one file, many sections, each with provenance and units.

Sections (all optional)::

    [gyro]       bias (rad/s), scale (3×3, 1), temp_slope (rad/s/°C), temp_ref (°C)
                 applied as  ω = S (ω_meas − b − k (T − T_ref))
    [accel]      bias (m/s²), matrix T (3×3: scale + misalignment)      f = T (f_meas − b)
    [mag]        b (µT, hard iron), A (3×3 symmetric, soft iron)        m_true = A (m_meas − b)
    [deviation]  A, B, C, D, E (deg): δ(ψ) = A + B sinψ + C cosψ + D sin2ψ + E cos2ψ, magnetic = compass + δ
    [mounting]   remap ("x,-y,-z"), misalignment_deg [roll, pitch, yaw] (sensor → body FRD)

Each section carries ``[<section>.provenance]``: input file, input_sha256, date_utc, sensor, method, fit quality.
TOML is written by the small writer here (tables, scalars, strings, numeric arrays and arrays of arrays) and
read with :mod:`tomllib` (Python ≥ 3.11) or ``tomli``.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from formats import Recording
from formats.atomic import atomic_path
from formats.errors import ImutoolError
from formats.frames import parse_axis_remap

from .deviation import DeviationCard
from .magnetometer import MAX_CONDITION

SECTIONS = ("mag", "gyro", "accel", "deviation", "mounting")


# -- TOML writer -------------------------------------------------------------------------------------------
def _toml_key(k: str) -> str:
    if k and all(c.isalnum() or c in "_-" for c in k):
        return k
    return _toml_str(k)


def _toml_str(s: str) -> str:
    out = s.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\t", "\\t")
    return f'"{out}"'


def _toml_value(v: Any) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if math.isnan(f):
            return "nan"
        if math.isinf(f):
            return "inf" if f > 0 else "-inf"
        return repr(f)
    if isinstance(v, str):
        return _toml_str(v)
    if isinstance(v, np.ndarray):
        return _toml_value(v.tolist())
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if v is None:
        return '""'
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def dumps_toml(data: dict[str, Any]) -> str:
    """TOML text for nested dicts of scalars, strings, lists and arrays (a small writer; no dependency)."""
    lines: list[str] = []

    def table(d: dict[str, Any], prefix: str) -> None:
        scalars = [(k, v) for k, v in d.items() if not isinstance(v, dict)]
        subs = [(k, v) for k, v in d.items() if isinstance(v, dict)]
        if prefix and (scalars or not subs):
            lines.append(f"[{prefix}]")
        for k, v in scalars:
            if v is None:
                continue
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
        if prefix and (scalars or not subs):
            lines.append("")
        for k, v in subs:
            table(v, f"{prefix}.{_toml_key(k)}" if prefix else _toml_key(k))

    top = {k: v for k, v in data.items() if not isinstance(v, dict)}
    for k, v in top.items():
        if v is not None:
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
    if top:
        lines.append("")
    table({k: v for k, v in data.items() if isinstance(v, dict)}, "")
    return "\n".join(lines).rstrip() + "\n"


def loads_toml(text: str, path: str | None = None) -> dict[str, Any]:
    try:
        import tomllib  # type: ignore[import-not-found]
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib  # type: ignore[no-redef]
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ImutoolError(f"not a valid TOML calibration file: {e}", path=path) from None


# -- provenance ----------------------------------------------------------------------------------------------
def sha256_of(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file (a folder: of its files' names and contents, sorted)."""
    h = hashlib.sha256()
    p = os.fspath(path)
    files = [p]
    if os.path.isdir(p):
        files = sorted(os.path.join(r, f) for r, _, fs in os.walk(p) for f in fs)
    for f in files:
        if len(files) > 1:
            h.update(os.path.relpath(f, p).encode())
        with open(f, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
    return h.hexdigest()


def provenance(
    input_path: str | os.PathLike | None,
    method: str,
    sensor: str | None = None,
    quality: dict[str, Any] | None = None,
    **extra: Any,
) -> dict[str, Any]:
    """The provenance table of a section: input file and hash, UTC date, sensor id, method, fit quality."""
    out: dict[str, Any] = {
        "input": os.fspath(input_path) if input_path else "",
        "input_sha256": sha256_of(input_path) if input_path and os.path.exists(input_path) else "",
        "date_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "sensor": sensor or "",
        "method": method,
    }
    out.update({k: v for k, v in extra.items() if v is not None})
    if quality:
        out["fit"] = {k: _plain(v) for k, v in quality.items() if v is not None}
    return out


def _plain(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items() if x is not None}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


# -- the calibration object ----------------------------------------------------------------------------------
def _mat(v: Any, name: str, path: str | None, shape: tuple[int, ...]) -> np.ndarray:
    if isinstance(v, str):
        raise ImutoolError(f"calibration {name}: not numeric ({v!r})", path=path)
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise ImutoolError(f"calibration {name}: not numeric", path=path) from None
    if a.shape != shape:
        raise ImutoolError(f"calibration {name}: shape {a.shape}, expected {shape}", path=path)
    if not np.all(np.isfinite(a)):
        raise ImutoolError(f"calibration {name}: non-finite values", path=path)
    return a


@dataclass
class Calibration:
    """Parsed calibration file. ``sections`` holds the raw TOML tables; ``path`` the file it came from."""

    sections: dict[str, Any] = field(default_factory=dict)
    path: str | None = None

    # -- access ------------------------------------------------------------------------------------------
    def __contains__(self, name: str) -> bool:
        return name in self.sections

    @property
    def deviation(self):  # -> DeviationCard | None
        """The deviation card (None when the file has no [deviation] section)."""
        if "deviation" not in self.sections:
            return None

        return DeviationCard.from_section(self.sections["deviation"], path=self.path)

    def mag(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(b µT, A) of the model m_true = A (m_meas − b), or None."""
        s = self.sections.get("mag")
        if s is None:
            return None
        return _mat(s.get("b"), "mag.b", self.path, (3,)), _mat(s.get("A"), "mag.A", self.path, (3, 3))

    def set_section(self, name: str, table: dict[str, Any]) -> None:
        if name not in SECTIONS:
            raise ImutoolError(f"unknown calibration section {name!r} (known: {', '.join(SECTIONS)})")
        self.sections[name] = _plain(table)

    # -- apply -------------------------------------------------------------------------------------------
    def apply(self, rec: Recording) -> Recording:
        """A copy of ``rec`` with every section that exists applied to its sensor channels.

        gyro: ω = S (ω_meas − b − k (T − T_ref)) (rad/s, T from channel ``temp`` when a slope is given);
        accel: f = T (f_meas − b) (m/s²); mag: m = A (m_meas − b) (µT); mounting: sensor → body FRD.
        The deviation card is not applied to channels (it corrects a heading; see :attr:`deviation`).
        What was applied is recorded in ``rec.meta['calibration']``.
        """
        out = rec.copy()
        applied: list[str] = []
        s = self.sections
        if "gyro" in s and "gyro" in out.channels:
            g = s["gyro"]
            w = out.get("gyro", "rad/s") - _mat(g.get("bias", [0, 0, 0]), "gyro.bias", self.path, (3,))
            what = "bias"
            if "temp_slope" in g:
                k = _mat(g["temp_slope"], "gyro.temp_slope", self.path, (3,))
                if "temp" in out.channels:
                    tc = out.get("temp", "degC") if out.units.get("temp") else out["temp"]
                    w = w - (tc - float(g.get("temp_ref", 0.0)))[:, None] * k
                    what += "+temperature slope"
            if "scale" in g:
                w = w @ _mat(g["scale"], "gyro.scale", self.path, (3, 3)).T
                what += "+scale"
            out.add("gyro", w, "rad/s", columns=out.columns.get("gyro"))
            applied.append(f"gyro {what}")
        if "accel" in s and "accel" in out.channels:
            a = s["accel"]
            f = out.get("accel", "m/s^2") - _mat(a.get("bias", [0, 0, 0]), "accel.bias", self.path, (3,))
            what = "bias"
            if "T" in a:
                f = f @ _mat(a["T"], "accel.T", self.path, (3, 3)).T
                what += "+scale/misalignment"
            out.add("accel", f, "m/s^2", columns=out.columns.get("accel"))
            applied.append(f"accel {what}")
        if "mag" in s and "mag" in out.channels:
            b, am = self.mag()  # type: ignore[misc]
            m = (out.get("mag", "uT") - b) @ am.T
            out.add("mag", m, "uT", columns=out.columns.get("mag"))
            applied.append(f"mag hard/soft iron ({s['mag'].get('kind', '?')})")
        if "mounting" in s:
            mt = s["mounting"]
            remap = str(mt.get("remap", "x,y,z"))
            mis = tuple(float(x) for x in mt.get("misalignment_deg", [0.0, 0.0, 0.0]))
            out = out.mounted(remap, mis)  # type: ignore[arg-type]
            applied.append(f"mounting {remap} {list(mis)} deg")
        if "deviation" in s:
            applied.append("deviation card available (applied to headings by compass/NMEA outputs)")
        out.meta["calibration"] = {"file": self.path or "", "applied": applied}
        return out

    # -- write -------------------------------------------------------------------------------------------
    def to_toml(self) -> str:
        head = {
            "imutool_calibration": 1,
            "model": "gyro: w = S (w_meas - b - k (T - T_ref)); accel: f = T (f_meas - b); "
            "mag: m_true = A (m_meas - b); deviation: magnetic = compass + A + B sin(psi) + C cos(psi)"
            " + D sin(2 psi) + E cos(2 psi), psi = compass heading",
        }
        ordered = {k: self.sections[k] for k in SECTIONS if k in self.sections}
        return dumps_toml({**head, **ordered})

    def save(self, path: str | os.PathLike) -> None:
        """Write the TOML file atomically."""
        text = self.to_toml()
        with atomic_path(path) as tmp:
            tmp.write_text(text, encoding="utf-8")
        self.path = os.fspath(path)


def load_calibration(path: str | os.PathLike) -> Calibration:
    """Read a calibration TOML file (ImutoolError on a missing/invalid file or malformed section)."""
    p = os.fspath(path)
    if not os.path.exists(p):
        raise ImutoolError("no such calibration file", path=p)
    try:
        with open(p, encoding="utf-8") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError) as e:
        raise ImutoolError(f"cannot read calibration file: {e}", path=p) from None
    data = loads_toml(text, p)
    sections = {k: v for k, v in data.items() if k in SECTIONS and isinstance(v, dict)}
    if not sections:
        raise ImutoolError(f"no calibration sections ({', '.join(SECTIONS)}) in the file", path=p)
    validate_calibration(data, p)
    return Calibration(sections, p)


FILE_VERSION = 1
# what a calibration term may be: beyond these the file describes no real sensor (SI units)
GYRO_BIAS_MAX = 1.0  # rad/s (57 °/s; MEMS biases are ≤ a few °/s)
ACCEL_BIAS_MAX = 0.5 * 9.80665  # m/s²
SCALE_RANGE = (0.5, 2.0)  # singular values of a gyro scale / accel T matrix
MAG_A_RANGE = (1e-3, 1e3)  # singular values of the soft-iron matrix
MISALIGNMENT_MAX_DEG = 45.0
DEVIATION_COEFF_MAX_DEG = 90.0


def _key(section: str, key: str) -> str:
    return f"[{section}] {key}"


def _matrix_checks(a: np.ndarray, where: str, path: str, sv_range: tuple[float, float], max_condition: float) -> None:
    sv = np.linalg.svd(a, compute_uv=False)
    rank = int(np.count_nonzero(sv > 1e-9 * max(float(sv[0]), 1e-300)))
    if rank < 3:
        raise ImutoolError(f"{where} is singular (rank {rank}): it would collapse the data; recalibrate", path=path)
    if np.linalg.det(a) <= 0:
        raise ImutoolError(f"{where} has a negative determinant (a mirror image); recalibrate", path=path)
    cond = float(sv[0] / sv[-1])
    if cond > max_condition:
        raise ImutoolError(
            f"{where} is badly conditioned (singular value ratio {cond:.3g} > {max_condition:g}); "
            "recalibrate with more orientations",
            path=path,
        )
    if sv[-1] < sv_range[0] or sv[0] > sv_range[1]:
        raise ImutoolError(
            f"{where} scales by {sv[-1]:.3g}…{sv[0]:.3g}, outside {sv_range[0]:g}…{sv_range[1]:g}", path=path
        )


def validate_calibration(data: dict[str, Any], path: str) -> None:
    """Refuse (ImutoolError naming the file and key) a calibration that no real sensor has.

    Version: ``imutool_calibration`` (or ``version``) must be 1 when present. Unknown top-level tables are
    refused (a misspelt section would silently not apply). [mag]: b finite (3,), A finite 3×3, full rank,
    positive determinant, singular-value ratio ≤ ``MAX_CONDITION``, field_ut > 0 when present. [gyro]/[accel]:
    biases finite and below ``GYRO_BIAS_MAX`` / ``ACCEL_BIAS_MAX``, scale/T matrices as A with singular values
    in ``SCALE_RANGE``. [deviation]: A–E finite numbers (deg) below ``DEVIATION_COEFF_MAX_DEG``. [mounting]:
    a valid remap and three finite misalignment angles below ``MISALIGNMENT_MAX_DEG``.
    """
    for vk in ("imutool_calibration", "version"):
        if vk in data and data[vk] != FILE_VERSION:
            raise ImutoolError(
                f"{vk} = {data[vk]!r}: unknown calibration file version (this imutool reads {FILE_VERSION})", path=path
            )
    unknown = [k for k, v in data.items() if isinstance(v, dict) and k not in SECTIONS]
    if unknown:
        raise ImutoolError(f"unknown section [{unknown[0]}] (known: {', '.join(SECTIONS)})", path=path)
    for name in SECTIONS:
        if name in data and not isinstance(data[name], dict):
            raise ImutoolError(f"{name} must be a table [{name}]", path=path)
    if "mag" in data:
        s = data["mag"]
        for k in ("b", "A"):
            if k not in s:
                raise ImutoolError(f"{_key('mag', k)} is missing", path=path)
        b = _mat(s["b"], "mag.b", path, (3,))
        a = _mat(s["A"], "mag.A", path, (3, 3))
        del b
        _matrix_checks(a, f"{_key('mag', 'A')} (soft iron)", path, MAG_A_RANGE, MAX_CONDITION)
        if "field_ut" in s:
            f = _number(s["field_ut"], _key("mag", "field_ut"), path)
            if not f > 0:
                raise ImutoolError(f"{_key('mag', 'field_ut')} = {f}: a field strength must be > 0 µT", path=path)
    if "gyro" in data:
        s = data["gyro"]
        bias = _mat(s.get("bias", [0, 0, 0]), "gyro.bias", path, (3,))
        if np.max(np.abs(bias)) > GYRO_BIAS_MAX:
            raise ImutoolError(
                f"{_key('gyro', 'bias')} {bias.tolist()} rad/s exceeds {GYRO_BIAS_MAX} rad/s (deg/s written as rad/s?)",
                path=path,
            )
        if "scale" in s:
            _matrix_checks(
                _mat(s["scale"], "gyro.scale", path, (3, 3)), _key("gyro", "scale"), path, SCALE_RANGE, MAX_CONDITION
            )
        if "temp_slope" in s:
            _mat(s["temp_slope"], "gyro.temp_slope", path, (3,))
        if "temp_ref" in s:
            _number(s["temp_ref"], _key("gyro", "temp_ref"), path)
    if "accel" in data:
        s = data["accel"]
        bias = _mat(s.get("bias", [0, 0, 0]), "accel.bias", path, (3,))
        if np.max(np.abs(bias)) > ACCEL_BIAS_MAX:
            raise ImutoolError(
                f"{_key('accel', 'bias')} {bias.tolist()} m/s² exceeds {ACCEL_BIAS_MAX:.3g} m/s² (g written as m/s²?)",
                path=path,
            )
        if "T" in s:
            _matrix_checks(_mat(s["T"], "accel.T", path, (3, 3)), _key("accel", "T"), path, SCALE_RANGE, MAX_CONDITION)
    if "deviation" in data:
        s = data["deviation"]
        for k in ("A", "B", "C", "D", "E"):
            if k in s:
                v = _number(s[k], _key("deviation", k), path)
                if abs(v) > DEVIATION_COEFF_MAX_DEG:
                    raise ImutoolError(
                        f"{_key('deviation', k)} = {v}° is beyond {DEVIATION_COEFF_MAX_DEG:g}°: not a deviation card",
                        path=path,
                    )
        for k in ("std", "header"):
            if k in s and not isinstance(s[k], dict):
                raise ImutoolError(f"{_key('deviation', k)} must be a table", path=path)
        for k, v in (s.get("std") or {}).items():
            _number(v, _key("deviation", f"std.{k}"), path)
    if "mounting" in data:
        s = data["mounting"]

        try:
            parse_axis_remap(str(s.get("remap", "x,y,z")))
        except ImutoolError as e:
            raise ImutoolError(f"{_key('mounting', 'remap')}: {e}", path=path) from None
        mis = _mat(s.get("misalignment_deg", [0, 0, 0]), "mounting.misalignment_deg", path, (3,))
        if np.max(np.abs(mis)) > MISALIGNMENT_MAX_DEG:
            raise ImutoolError(
                f"{_key('mounting', 'misalignment_deg')} {mis.tolist()}: a misalignment is a small "
                f"angle (≤ {MISALIGNMENT_MAX_DEG:g}°); put the rotation in remap",
                path=path,
            )


def _number(v: Any, where: str, path: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ImutoolError(f"{where} must be a number, got {v!r}", path=path)
    f = float(v)
    if not math.isfinite(f):
        raise ImutoolError(f"{where} is not finite ({f})", path=path)
    return f


def update_calibration(path: str | os.PathLike, name: str, table: dict[str, Any], append: bool) -> Calibration:
    """Write section ``name`` into ``path``: merged into the existing file with ``append``, else a new file."""
    cal = load_calibration(path) if append and os.path.exists(path) else Calibration()
    cal.set_section(name, table)
    try:  # the same checks as on loading: a file imutool writes, imutool reads
        validate_calibration(cal.sections, os.fspath(path))
    except ImutoolError as e:
        raise ImutoolError(f"the {name} calibration is not usable, nothing written: {e}") from None
    cal.save(path)
    return cal
