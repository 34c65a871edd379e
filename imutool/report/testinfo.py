"""The test record of an evidence report: who tested what, where, with which reference, under which rule.

``load_test_info(path)`` reads a TOML file (example: ``docs/examples/test_info.toml``) into a dict with every
field of :data:`FIELDS` present; a field the file does not give is ``None`` and the PDF prints it as a blank line
to fill in by hand. Nothing is invented: imutool never fills a field the test house did not state.

Sections and fields (units in the names): ``[report] number``; ``[test] house, site, date, operator, witness``;
``[dut] make, model, serial, firmware, heel_range_deg, period_range_s``; ``[reference] instrument, serial,
certificate, calibration_date, calibration_due, uncertainty_k2_deg, uncertainty_k2_s``; ``[environment]
temperature_c, humidity_pct, notes``; ``[setup] description, mounting, photos``; ``[decision_rule] rule``
(``simple acceptance`` or ``guard band``: acceptance limit = tolerance − U, U the reference's expanded
uncertainty at k = 2, per ILAC-G8); ``[external.<item>] result, evidence`` for the clauses imutool cannot test
from data (display, alarms, power_supply, environmental_emc): the test house's attestation with a reference to
its evidence (a photo, a laboratory report number), shown as *attested, not verified by imutool*.
"""

from __future__ import annotations

import os
import sys
from typing import Any

from formats.errors import ImutoolError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

# (section, key, label, kind) in the order the PDF prints them; kind: str, num, range, list
FIELDS: list[tuple[str, str, str, str]] = [
    ("report", "number", "Report number", "str"),
    ("test", "house", "Test house", "str"),
    ("test", "site", "Test site", "str"),
    ("test", "date", "Test date(s)", "str"),
    ("test", "operator", "Operator", "str"),
    ("test", "witness", "Witness (surveyor)", "str"),
    ("dut", "make", "DUT make", "str"),
    ("dut", "model", "DUT model", "str"),
    ("dut", "serial", "DUT serial number", "str"),
    ("dut", "firmware", "DUT firmware", "str"),
    ("dut", "heel_range_deg", "Declared heel range (deg, ±)", "num"),
    ("dut", "period_range_s", "Declared roll-period range (s)", "range"),
    ("reference", "instrument", "Reference instrument", "str"),
    ("reference", "serial", "Reference serial number", "str"),
    ("reference", "certificate", "Calibration certificate no.", "str"),
    ("reference", "calibration_date", "Calibration date", "str"),
    ("reference", "calibration_due", "Calibration due date", "str"),
    ("reference", "uncertainty_k2_deg", "Reference expanded uncertainty U (k = 2), angle (deg)", "num"),
    ("reference", "uncertainty_k2_s", "Reference expanded uncertainty U (k = 2), period (s)", "num"),
    ("environment", "temperature_c", "Ambient temperature (°C)", "num"),
    ("environment", "humidity_pct", "Relative humidity (%)", "num"),
    ("environment", "notes", "Environment notes", "str"),
    ("setup", "description", "Test set-up", "str"),
    ("setup", "mounting", "DUT mounting and alignment", "str"),
    ("setup", "photos", "Set-up photographs", "list"),
    ("decision_rule", "rule", "Decision rule", "str"),
]

EXTERNAL = {
    "display": ("Display function", "ISO 19697 §6.7 (C); MSC.363(92) display (P5, P6)"),
    "alarms": ("Alarms", "ISO 19697 §4.5, §6.8-6.9 (C)"),
    "power_supply": ("Power supply interruption and restart", "ISO 19697 §4.7 (C)"),
    "environmental_emc": ("Environmental and EMC tests", "IEC 60945 via ISO 19697 scope (P14, A)"),
}

RULES = ("simple acceptance", "guard band")


def _bad(msg: str, path: str) -> ImutoolError:
    return ImutoolError(f"test record: {msg}", path=path)


def empty_test_info() -> dict[str, Any]:
    """Every field present and None (the blank test record)."""
    out: dict[str, Any] = {}
    for sec, key, _, _ in FIELDS:
        out.setdefault(sec, {})[key] = None
    out["external"] = {}
    return out


def load_test_info(path: str | None) -> dict[str, Any]:
    """Read and check a test-record TOML; every field of FIELDS present (None when not given)."""
    info = empty_test_info()
    if path is None:
        info["source"] = None
        return info
    if os.path.isdir(path) or not os.path.exists(path):
        raise _bad("no such file", path)
    try:
        with open(path, "rb") as f:
            raw = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise _bad(f"not valid TOML ({exc})", path) from None
    known = {sec for sec, _, _, _ in FIELDS} | {"external"}
    for sec in raw:
        if sec not in known:
            raise _bad(f"unknown section [{sec}] (known: {', '.join(sorted(known))})", path)
    for sec, key, label, kind in FIELDS:
        v = raw.get(sec, {}).get(key) if isinstance(raw.get(sec), dict) else None
        if v is None or v == "":
            continue
        if kind == "str":
            v = str(v)
        elif kind == "num":
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
                raise _bad(f"[{sec}] {key} must be a positive number ({label})", path)
            v = float(v)
        elif kind == "range":
            if (
                not isinstance(v, list)
                or len(v) != 2
                or not all(isinstance(x, (int, float)) for x in v)
                or not 0 < v[0] < v[1]
            ):
                raise _bad(f"[{sec}] {key} must be [min, max] with 0 < min < max ({label})", path)
            v = [float(v[0]), float(v[1])]
        elif kind == "list":
            v = [str(x) for x in (v if isinstance(v, list) else [v])]
        info[sec][key] = v
    for sec in raw:
        if sec == "external" or not isinstance(raw[sec], dict):
            continue
        extra = set(raw[sec]) - {k for s, k, _, _ in FIELDS if s == sec}
        if extra:
            raise _bad(f"unknown field(s) in [{sec}]: {', '.join(sorted(extra))}", path)
    rule = info["decision_rule"]["rule"]
    if rule is not None and rule not in RULES:
        raise _bad(f"[decision_rule] rule must be one of {', '.join(RULES)} (got {rule!r})", path)
    ext = raw.get("external", {})
    if not isinstance(ext, dict):
        raise _bad("[external] must be a table of [external.<item>] tables", path)
    for item, v in ext.items():
        if item not in EXTERNAL:
            raise _bad(f"unknown [external.{item}] (known: {', '.join(EXTERNAL)})", path)
        if not isinstance(v, dict) or v.get("result") not in ("pass", "fail"):
            raise _bad(f'[external.{item}] needs result = "pass" or "fail"', path)
        if not str(v.get("evidence") or "").strip():
            raise _bad(
                f'[external.{item}] needs evidence = "<report no., photo, ...>" (an attestation '
                "without evidence is not accepted)",
                path,
            )
        info["external"][item] = {"result": v["result"], "evidence": str(v["evidence"]), "by": str(v.get("by") or "")}
    info["source"] = os.fspath(path)
    return info


def missing_fields(info: dict[str, Any]) -> list[str]:
    """Labels of the fields the test record leaves blank."""
    return [label for sec, key, label, _ in FIELDS if info.get(sec, {}).get(key) in (None, "", [])]
