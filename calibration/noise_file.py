"""The sensor noise file ``noise.yaml`` (flat keys, SI units) written by ``imutool allan``, and a kalibr-style
``imu.yaml``.

Keys (each the mean over the three axes; per-axis values under ``<key>_xyz``):
  gyro_noise_density (rad/s/√Hz = ARW N), gyro_bias_instability (rad/s, B), gyro_random_walk (rad/s/√s = RRW K),
  accel_noise_density (m/s²/√Hz = VRW), accel_bias_instability (m/s²), accel_random_walk (m/s²/√s),
  mag_noise_density (µT/√Hz), mag_bias_instability (µT), plus rate_hz, source, samples.

Written by the tiny flat-YAML writer here; read with ruamel.yaml when available, else by the small parser here
(flat ``key: value`` lines, values number / string / ``[a, b, c]``).
"""

from __future__ import annotations

import math
import os
from typing import Any

from formats.atomic import atomic_path
from formats.errors import ImutoolError

KEY_UNITS = {
    "gyro_noise_density": "rad/s/sqrt(Hz)",
    "gyro_bias_instability": "rad/s",
    "gyro_random_walk": "rad/s/sqrt(s)",
    "accel_noise_density": "m/s^2/sqrt(Hz)",
    "accel_bias_instability": "m/s^2",
    "accel_random_walk": "m/s^2/sqrt(s)",
    "mag_noise_density": "uT/sqrt(Hz)",
    "mag_bias_instability": "uT",
    "mag_random_walk": "uT/sqrt(s)",
    "gyro_bias_instability_upper_bound": "rad/s (no flicker floor seen: the Allan minimum is a crossover)",
    "accel_bias_instability_upper_bound": "m/s^2 (no flicker floor seen)",
    "mag_bias_instability_upper_bound": "uT (no flicker floor seen)",
    "gyro_random_walk_upper_bound": "rad/s/sqrt(s) (not resolved: upper bound)",
    "accel_random_walk_upper_bound": "m/s^2/sqrt(s) (not resolved: upper bound)",
    "mag_random_walk_upper_bound": "uT/sqrt(s) (not resolved: upper bound)",
}


def _yaml_scalar(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return ".nan"
        if math.isinf(v):
            return ".inf" if v > 0 else "-.inf"
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_yaml_scalar(x) for x in v) + "]"
    s = str(v)
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def dumps_flat_yaml(d: dict[str, Any], comments: dict[str, str] | None = None, header: str = "") -> str:
    lines = [f"# {h}" for h in header.splitlines()] if header else []
    for k, v in d.items():
        if v is None:
            continue
        c = (comments or {}).get(k)
        lines.append(f"{k}: {_yaml_scalar(v)}" + (f"  # {c}" if c else ""))
    return "\n".join(lines) + "\n"


def write_noise(path: str | os.PathLike, values: dict[str, Any]) -> None:
    """Write ``noise.yaml`` atomically (flat keys; units as trailing comments)."""
    text = dumps_flat_yaml(
        values,
        {k: u for k, u in KEY_UNITS.items()},
        header="imutool sensor noise (Allan deviation, IEEE Std 952 terms); SI units",
    )
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


KALIBR_FALLBACKS = ("refuse", "upper-bound")


def write_kalibr(
    path: str | os.PathLike, values: dict[str, Any], topic: str = "/imu0", fallback: str = "refuse"
) -> list[str]:
    """kalibr-style ``imu.yaml`` (accelerometer/gyroscope noise density and random walk, update_rate).

    A term the recording did not resolve (missing, None, NaN or 0 — a zero random walk makes kalibr treat the
    bias as constant) is refused (``fallback='refuse'``, ImutoolError naming the terms), or written from the
    labelled upper bound ``<sensor>_random_walk_upper_bound`` (``fallback='upper-bound'``: the value carries an
    ``UPPER BOUND`` comment and a warning is returned). Noise densities have no fallback. Returns warnings."""
    if fallback not in KALIBR_FALLBACKS:
        raise ImutoolError(f"kalibr fallback {fallback!r}: use one of {', '.join(KALIBR_FALLBACKS)}")

    def known(v: Any) -> bool:
        return isinstance(v, (int, float)) and math.isfinite(v) and v > 0

    keys = {
        "accelerometer_noise_density": "accel_noise_density",
        "accelerometer_random_walk": "accel_random_walk",
        "gyroscope_noise_density": "gyro_noise_density",
        "gyroscope_random_walk": "gyro_random_walk",
    }
    units = {
        "accelerometer_noise_density": "m/s^2/sqrt(Hz)",
        "accelerometer_random_walk": "m/s^3/sqrt(Hz)",
        "gyroscope_noise_density": "rad/s/sqrt(Hz)",
        "gyroscope_random_walk": "rad/s^2/sqrt(Hz)",
    }
    d: dict[str, Any] = {"rostopic": topic, "update_rate": float(values.get("rate_hz", 0.0))}
    comments = dict(units)
    missing: list[str] = []
    warnings: list[str] = []
    for kk, ik in keys.items():
        v = values.get(ik)
        if known(v):
            d[kk] = float(v)
            continue
        bound = values.get(ik + "_upper_bound")
        if kk.endswith("random_walk") and fallback == "upper-bound" and known(bound):
            d[kk] = float(bound)
            comments[kk] = units[kk] + "  UPPER BOUND, not resolved by the recording (record longer)"
            warnings.append(
                f"kalibr {kk}: not resolved, written as the upper bound {float(bound):.3g} "
                f"{units[kk]} (labelled in the file)"
            )
        else:
            missing.append(kk)
    if missing:
        why = (
            "; a random walk needs the +1/2 slope of the Allan deviation (record longer)"
            if any(m.endswith("random_walk") for m in missing)
            else ""
        )
        hint = (
            " or write the labelled upper bound with the 'upper-bound' fallback (--kalibr-fallback upper-bound)"
            if fallback == "refuse" and any(m.endswith("random_walk") for m in missing)
            else ""
        )
        raise ImutoolError(
            f"kalibr file not written: {', '.join(missing)} not resolved by this recording{why}{hint}",
            path=os.fspath(path),
        )
    text = dumps_flat_yaml(
        d,
        comments,
        header="kalibr IMU noise model (continuous-time), from imutool allan; inflate for "
        "real-world use as kalibr recommends" + ("\nWARNING: " + "\nWARNING: ".join(warnings) if warnings else ""),
    )
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return warnings


def _parse_scalar(s: str) -> Any:
    s = s.strip()
    if s.startswith("[") and s.endswith("]"):
        inner = s[1:-1].strip()
        return [_parse_scalar(x) for x in inner.split(",")] if inner else []
    if len(s) >= 2 and s[0] == s[-1] and s[0] in "\"'":
        return s[1:-1].replace('\\"', '"').replace("\\\\", "\\")
    low = s.lower()
    if low in ("true", "false"):
        return low == "true"
    if low in (".nan", "nan"):
        return float("nan")
    if low in (".inf", "inf"):
        return float("inf")
    if low in ("-.inf", "-inf"):
        return float("-inf")
    if low in ("null", "~", ""):
        return None
    try:
        return int(s)
    except ValueError:
        pass
    try:
        return float(s)
    except ValueError:
        return s


def _parse_flat(text: str, path: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for i, line in enumerate(text.splitlines(), 1):
        raw = line
        if "#" in line and not line.lstrip().startswith(("'", '"')):
            # strip a trailing comment outside quotes
            q = False
            for j, ch in enumerate(line):
                if ch == '"':
                    q = not q
                elif ch == "#" and not q:
                    line = line[:j]
                    break
        if not line.strip():
            continue
        if ":" not in line:
            raise ImutoolError(f"noise file: expected 'key: value', got {raw.strip()!r}", path=path, line=i)
        k, v = line.split(":", 1)
        out[k.strip()] = _parse_scalar(v)
    return out


def load_noise(path: str | os.PathLike) -> dict[str, Any]:
    """Read ``noise.yaml`` → dict (flat keys as written by :func:`write_noise`; SI units)."""
    p = os.fspath(path)
    if not os.path.exists(p):
        raise ImutoolError("no such noise file", path=p)
    with open(p, encoding="utf-8") as fh:
        text = fh.read()
    data: Any = None
    try:
        from ruamel.yaml import YAML  # installed with rosbags

        data = YAML(typ="safe").load(text)
    except ImportError:
        data = _parse_flat(text, p)
    except Exception as e:  # ruamel's parser errors: report as bad input
        raise ImutoolError(f"noise file is not valid YAML: {str(e).splitlines()[0]}", path=p) from None
    if not isinstance(data, dict):
        raise ImutoolError("noise file: expected a mapping of key: value", path=p)
    out = {}
    for k, v in data.items():
        if isinstance(v, list):
            v = [float(x) for x in v] if all(isinstance(x, (int, float)) for x in v) else list(v)
        out[str(k)] = v
    known = [k for k in KEY_UNITS if k in out]
    if not known:
        raise ImutoolError(f"noise file has none of the keys {', '.join(KEY_UNITS)}", path=p)
    return out
