"""A calibration file as code that pastes and compiles/runs as it is: C (x-io Fusion), MATLAB, Python/numpy, JSON.

imutool's models (calibration file, SI inside):

- magnetometer  m_true = A (m_meas − b)          b µT (sensor axes), A symmetric soft iron, field_ut µT;
- gyroscope     w = S (w_meas − b)               b rad/s, S scale/misalignment (identity when not fitted);
- accelerometer f = T (f_meas − b)               b m/s², T scale/misalignment.

Conventions written out:

- **C / x-io Fusion** (``FusionMath.h``: ``FusionVector`` = union {float array[3]; struct {x, y, z} axis},
  ``FusionMatrix`` = union {float array[9]; struct {xx, xy, …, zz} element}, row-major):
  ``FusionCalibrationMagnetic(m, softIronMatrix, hardIronOffset)`` = softIronMatrix (m − hardIronOffset), so
  softIronMatrix = A, hardIronOffset = b (µT; Fusion does not care about the magnetometer's unit);
  ``FusionCalibrationInertial(x, misalignment, sensitivity, offset)`` = misalignment (sensitivity ⊙ (x − offset))
  with the gyroscope in **deg/s** and the accelerometer in **g** (Fusion's units): offset = b converted,
  misalignment = S or T, sensitivity = ones.
- **MATLAB** ``magcal``: C = (D − b) · A with samples as rows, b a 1×3 row, ``expmfs`` the expected field
  strength; A symmetric, so MATLAB A = imutool A, b = imutool b (µT), expmfs = field_ut.
- **Python/numpy**: arrays plus ``correct_mag(m)`` (rows = samples), runnable with ``exec``.
- **JSON**: every section of the file, no comment lines.

Each form uses its own language's comments (``//``, ``%``, ``#``); nothing else precedes the code.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from formats.errors import ImutoolError

FORMS = ("c", "matlab", "python", "json")
G0 = 9.80665  # m/s² per g (Fusion's accelerometer unit)


def _num(v: float, c: bool = False) -> str:
    x = float(v)
    if not math.isfinite(x):
        raise ImutoolError(f"calibration value {x} is not a finite number: cannot write it as code")
    s = f"{x:.9g}"
    if c:
        if "e" not in s and "." not in s:
            s += ".0"
        return s + "f"
    return s


def _sections(cal: Any) -> dict[str, dict[str, Any]]:
    mg = cal.mag()
    if mg is None:
        raise ImutoolError("no [mag] section to convert", path=getattr(cal, "path", None))
    b, a = mg
    out: dict[str, dict[str, Any]] = {
        "mag": {
            "A": np.asarray(a, float),
            "b": np.asarray(b, float),
            "field": float(cal.sections["mag"].get("field_ut", float("nan"))),
        }
    }
    g = cal.sections.get("gyro")
    if g and "bias" in g:
        out["gyro"] = {
            "b": np.asarray(g["bias"], float),
            "S": np.asarray(g["scale"], float) if g.get("scale") is not None else np.eye(3),
        }
    acc = cal.sections.get("accel")
    if acc and "bias" in acc:
        out["accel"] = {"b": np.asarray(acc["bias"], float), "T": np.asarray(acc.get("T", np.eye(3)), float)}
    return out


def to_c(cal: Any) -> str:
    """C for x-io Fusion (see the module docstring); compiles with the FusionMath.h types."""
    s = _sections(cal)
    m = s["mag"]

    def mat(name: str, a: np.ndarray, note: str) -> str:
        return f"const FusionMatrix {name} = {{.array = {{{', '.join(_num(v, True) for v in a.ravel())}}}}};  // {note}"

    def vec(name: str, v: np.ndarray, note: str) -> str:
        return f"const FusionVector {name} = {{.array = {{{', '.join(_num(x, True) for x in v)}}}}};  // {note}"

    lines = [
        "// imutool calibration for x-io Fusion (FusionMath.h types). Row-major matrices.",
        "// Magnetometer: FusionCalibrationMagnetic(m, softIronMatrix, hardIronOffset)"
        " = softIronMatrix (m - hardIronOffset)",
        "// imutool m_true = A (m_meas - b): softIronMatrix = A, hardIronOffset = b (uT).",
        '#include "Fusion.h"',
        mat("softIronMatrix", m["A"], "imutool A"),
        vec("hardIronOffset", m["b"], "imutool b, uT"),
    ]
    if "gyro" in s:
        lines += [
            "// Gyroscope: FusionCalibrationInertial(g, gyroscopeMisalignment, gyroscopeSensitivity,"
            " gyroscopeOffset), deg/s",
            mat("gyroscopeMisalignment", s["gyro"]["S"], "imutool S"),
            vec("gyroscopeSensitivity", np.ones(3), "scale is inside S"),
            vec("gyroscopeOffset", np.degrees(s["gyro"]["b"]), "imutool b in deg/s"),
        ]
    if "accel" in s:
        lines += [
            "// Accelerometer: FusionCalibrationInertial(a, accelerometerMisalignment,"
            " accelerometerSensitivity, accelerometerOffset), g",
            mat("accelerometerMisalignment", s["accel"]["T"], "imutool T"),
            vec("accelerometerSensitivity", np.ones(3), "scale is inside T"),
            vec("accelerometerOffset", s["accel"]["b"] / G0, "imutool b in g (9.80665 m/s^2)"),
        ]
    return "\n".join(lines) + "\n"


def to_matlab(cal: Any) -> str:
    """MATLAB ``magcal`` convention: A, b (1×3 row), expmfs; C = (D - b) * A."""
    s = _sections(cal)
    m = s["mag"]

    def row(v: np.ndarray) -> str:
        return " ".join(_num(x) for x in v)

    lines = [
        "% imutool calibration in the MATLAB magcal convention: C = (D - b) * A  (rows of D are samples)",
        "% imutool m_true = A (m_meas - b); A is symmetric, so A and b carry over unchanged (uT).",
        "A = [" + "; ".join(row(r) for r in m["A"]) + "];",
        "b = [" + row(m["b"]) + "];",
        ("expmfs = " + _num(m["field"]) + ";  % expected magnetic field strength, uT")
        if math.isfinite(m["field"])
        else "expmfs = NaN;  % field strength not in the calibration file",
    ]
    if "gyro" in s:
        lines += [
            "% gyroscope w = S (w_meas - b), rad/s: as rows, W = (Wm - gyro_b) * gyro_S'",
            "gyro_b = [" + row(s["gyro"]["b"]) + "];",
            "gyro_S = [" + "; ".join(row(r) for r in s["gyro"]["S"]) + "];",
        ]
    if "accel" in s:
        lines += [
            "% accelerometer f = T (f_meas - b), m/s^2: as rows, F = (Fm - accel_b) * accel_T'",
            "accel_b = [" + row(s["accel"]["b"]) + "];",
            "accel_T = [" + "; ".join(row(r) for r in s["accel"]["T"]) + "];",
        ]
    return "\n".join(lines) + "\n"


def to_python(cal: Any) -> str:
    """Python/numpy: arrays and correct_* functions (rows = samples)."""
    s = _sections(cal)
    m = s["mag"]

    def arr(a: np.ndarray) -> str:
        if a.ndim == 1:
            return "np.array([" + ", ".join(_num(x) for x in a) + "])"
        return "np.array([" + ", ".join("[" + ", ".join(_num(x) for x in r) + "]" for r in a) + "])"

    fld = _num(m["field"]) if math.isfinite(m["field"]) else 'float("nan")'
    lines = [
        "# imutool calibration as Python/numpy. Model: m_true = A (m_meas - b); rows of m are samples.",
        "import numpy as np",
        "",
        f"A = {arr(m['A'])}",
        f"b = {arr(m['b'])}  # uT",
        f"field_ut = {fld}",
        "",
        "",
        "def correct_mag(m):",
        '    """Calibrated field (uT) from raw samples (N, 3) in uT."""',
        "    return (np.asarray(m, dtype=float) - b) @ A.T",
    ]
    if "gyro" in s:
        lines += [
            "",
            "",
            f"gyro_b = {arr(s['gyro']['b'])}  # rad/s",
            f"gyro_S = {arr(s['gyro']['S'])}",
            "",
            "",
            "def correct_gyro(w):",
            '    """w = S (w_meas - b), rad/s, rows = samples."""',
            "    return (np.asarray(w, dtype=float) - gyro_b) @ gyro_S.T",
        ]
    if "accel" in s:
        lines += [
            "",
            "",
            f"accel_b = {arr(s['accel']['b'])}  # m/s^2",
            f"accel_T = {arr(s['accel']['T'])}",
            "",
            "",
            "def correct_accel(f):",
            '    """f = T (f_meas - b), m/s^2, rows = samples."""',
            "    return (np.asarray(f, dtype=float) - accel_b) @ accel_T.T",
        ]
    return "\n".join(lines) + "\n"


def to_json(cal: Any) -> str:
    """Every section of the file as JSON (NaN written as null)."""

    def clean(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [clean(x) for x in v]
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, np.ndarray):
            return clean(v.tolist())
        return v

    return json.dumps(clean(cal.sections), indent=2, default=str, allow_nan=False)


def render(cal: Any, form: str) -> str:
    """The calibration in ``form`` (c | fusion | matlab | python | json)."""
    f = "c" if form == "fusion" else form
    if f == "c":
        return to_c(cal)
    if f == "matlab":
        return to_matlab(cal)
    if f == "python":
        return to_python(cal)
    if f == "json":
        return to_json(cal) + "\n"
    raise ImutoolError(f"unknown form {form!r} ({', '.join(FORMS)})")
