"""Electronic-inclinometer evidence per IMO MSC.363(92), structured like the ISO 19697:2016 test clauses.

``inclinometer_evidence(dut, ref, ...)`` compares a device under test (a Recording with ``heel`` from HRM or
``roll``; deg, + starboard down) against a reference (tilt/motion table, reference inclinometer) and returns
``(evidence, plots)``: ``evidence`` is the JSON-safe dict validated by ``schema/evidence.schema.json``,
``plots`` holds the arrays the PDF draws. Everything is evaluated on the reference time base after the time
alignment (cross-correlation lag, :func:`imutool.metrics.best_lag`).

Tolerances (standards.md, confidence tags in the report): angle max(1°, 5 % of reading) (P3, B); period
max(1 s, 5 % of reading) (P4, B); the reading used is the reference value. Criterion ``max`` (every sample or
cycle within tolerance) or ``p95`` (95th percentile of |error|/tolerance ≤ 1, the 95 % bound of
MSC.1/Circ.1575, P12, A).
"""

from __future__ import annotations

import os
import re
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from formats import Recording
from formats.errors import ImutoolError
from formats.nmea import checksum
from imutool.metrics import angle_diff_deg, best_lag, interp_to
from imutool.roll import MOTION_TABLE, PORT, STBD, heel_of, pair_cycles, roll_cycles, roll_stats

from .common import (
    ALIGN,
    CRITERION,
    FAIL,
    INSUFFICIENT,
    MAX_LAG_S,
    NOT_TESTED,
    PASS,
    SCOPE,
    STANDARDS_FILE,
    channel_on,
    check_tolerance,
    clean,
    input_record,
    item,
    judge,
    now_utc,
    overall,
    own_samples,
    plateaus,
    set_clock,
    standards_cited,
    stats,
    tol_angle,
    tol_period,
    tool_identity,
)

EDITIONS = [
    {
        "document": "IMO MSC.363(92)",
        "edition": "Performance standards for electronic inclinometers, adopted 14 June 2013",
        "role": "accuracy criteria (angle, period), definitions §3",
        "confidence": "A",
    },
    {
        "document": "ISO 19697",
        "edition": "2016 (the ISO/DIS 19697 revision of 2025 was not available)",
        "role": "test clause structure §6.2-§6.10 (clause titles only)",
        "confidence": "C",
    },
    {
        "document": "IEC 61162-1",
        "edition": "HRM sentence as reproduced in vendor manuals (Ed.5 2016 likely)",
        "role": "interface, sign convention (+ starboard), HRM fields",
        "confidence": "B",
    },
    {
        "document": "IMO MSC.1/Circ.1575",
        "edition": "PNT guidance, Appendix C Table C-1",
        "role": "95 % interpretation of the accuracy (option --criterion p95)",
        "confidence": "A",
    },
    {
        "document": "SOLAS V/19.2.12 (MSC.532(107))",
        "edition": "in force 1 January 2026",
        "role": "carriage requirement (context only)",
        "confidence": "A/B",
    },
]

UNCONFIRMED = [
    {"id": "P6", "text": "Roll amplitude display resolution (1° is likely but not confirmed).", "confidence": "R"},
    {
        "id": "P7",
        "text": "That MSC.363(92) itself requires a peak-hold display is not confirmed (it is in the IEC "
        "61162-1 HRM notes and ISO 19697 §6.10 title).",
        "confidence": "C",
    },
    {
        "id": "P9",
        "text": "Heel-angle measuring range: not found; the tested range is what the data covered.",
        "confidence": "-",
    },
    {"id": "P10", "text": "Roll-period measuring range: not found.", "confidence": "-"},
    {
        "id": "P11",
        "text": "Output update rate, power-up/settling time, alarm thresholds: not found.",
        "confidence": "-",
    },
    {"id": "P13", "text": "VDR recording of rolling motion (MSC.333(90) §5.5): recalled, not seen.", "confidence": "R"},
    {
        "id": "ISO19697-5.2",
        "text": "Acceleration test conditions of ISO 19697 §5.2: not known; not evaluated.",
        "confidence": "C",
    },
    {
        "id": "ISO19697-6.4",
        "text": "Long-term test duration and limit of ISO 19697 §6.4: not known; imutool "
        "applies the heel tolerance over the whole hold and reports the drift rate.",
        "confidence": "C",
    },
]

NOT_TESTED_ALWAYS = [
    "Vertical acceleration (ISO 19697 §5.2): conditions not known (unconfirmed); only lateral acceleration is "
    "evaluated when the reference carries it.",
    "Reference equipment traceability: certificate and uncertainty as stated in the test record (not verified).",
]

SRC_DEVICE = "reported by the device (HRM fields)"
SRC_DERIVED = "derived by imutool from the device's heel angle (imutool.roll)"

# every item the requirement asks for; the overall result is PASS only when all were tested and passed
REQUIRED = (
    "static_heel",
    "dynamic_heel",
    "amplitude_stbd",
    "amplitude_port",
    "roll_period",
    "long_term",
    "peak_hold",
    "lateral_acceleration",
    "interface",
    "display",
    "alarms",
    "power_supply",
    "environmental_emc",
)
CITED = ["P1", "P2", "P3", "P4", "P5", "P6", "P7", "P8", "P9", "P10", "P11", "P12", "P14"]


@dataclass
class InclinometerOptions:
    """Every tuning constant of the inclinometer report (degrees, seconds, percent, m/s²)."""

    angle_floor_deg: float = 1.0  # MSC.363(92) ±1°
    angle_pct: float = 5.0  # 5 % of reading
    period_floor_s: float = 1.0  # ±1 s
    period_pct: float = 5.0
    criterion: str = CRITERION  # max | p95 (MSC.1/Circ.1575 95 %)
    align: str = ALIGN  # none (common clock; latency counts as error) | xcorr (remove the measured constant lag)
    max_lag_s: float = MAX_LAG_S
    hysteresis_deg: float = 0.5  # roll cycle detection (imutool.roll)
    min_cycles: int = 3  # per side, for amplitude and period items
    min_cycle_amp_deg: float = 1.0  # reference cycles with a smaller maximum are not judged
    crest_band_deg: float = 0.05  # crest width: samples within this of the maximum (time-of-maximum ambiguity)
    min_steps_per_side: int = 2  # static heel steps on each side of zero
    step_band_deg: float = 0.2  # plateau detection: range over the window ≤ band
    step_min_s: float = 10.0  # a plateau lasts at least this long
    step_settle_s: float = 2.0  # ignored at the start of each plateau
    level_band_deg: float = 0.5  # |heel| ≤ this is the level (zero) step, neither side
    long_term_min_s: float = 3600.0  # minimum static hold for the long-term test (ISO 19697 §6.4 duration unknown)
    drift_limit_deg_per_h: float | None = None  # optional drift-rate limit; the hold must resolve it
    min_dynamic_s: float = 30.0  # minimum non-static time for the dynamic heel test
    lat_accel_channel: str = "lat_accel"  # reference channel: applied lateral acceleration (m/s², + starboard)
    lat_accel_min_ms2: float = 0.2  # samples with |lateral acceleration| ≥ this belong to the acceleration item
    lat_accel_min_s: float = 20.0  # time under acceleration needed to judge it
    declared_heel_range_deg: float | None = None  # ± range the static steps must cover (test record)
    declared_period_range_s: tuple[float, float] | None = None  # period range the judged cycles must cover
    default_period_range_s: tuple[float, float] = (4.0, 30.0)  # used when none is declared (P10, I)
    range_cover_frac: float = 0.9  # a range counts as covered when tested to ≥ 90 % of its ends (I)
    guard_band: bool = False  # decision rule: acceptance limit = tolerance − U (k = 2) of the reference
    uncertainty_k2_deg: float | None = None
    uncertainty_k2_s: float | None = None

    def check(self) -> None:
        """Refuse impossible settings (exit status 2 at the command line)."""
        check_tolerance("angle", self.angle_floor_deg, self.angle_pct, "deg")
        check_tolerance("period", self.period_floor_s, self.period_pct, "s")
        if self.criterion not in ("max", "p95"):
            raise ImutoolError(f"criterion must be 'max' or 'p95' (got {self.criterion!r})")
        if self.align not in ("xcorr", "none"):
            raise ImutoolError(f"align must be 'xcorr' or 'none' (got {self.align!r})")
        for name in ("min_cycles", "min_steps_per_side"):
            if getattr(self, name) < 1:
                raise ImutoolError(f"{name} must be ≥ 1 (got {getattr(self, name)})")
        for name in ("long_term_min_s", "min_cycle_amp_deg", "crest_band_deg", "max_lag_s", "lat_accel_min_ms2"):
            if not getattr(self, name) > 0:
                raise ImutoolError(f"{name} must be > 0 (got {getattr(self, name)})")
        if self.hysteresis_deg < 0:
            raise ImutoolError(f"hysteresis must be ≥ 0 deg (got {self.hysteresis_deg})")
        if self.drift_limit_deg_per_h is not None and not self.drift_limit_deg_per_h > 0:
            raise ImutoolError(f"drift limit must be > 0 °/h (got {self.drift_limit_deg_per_h})")
        if self.guard_band:
            u = self.uncertainty_k2_deg
            if u is None:
                raise ImutoolError(
                    "the guard-band decision rule needs the reference's expanded uncertainty "
                    "(test record [reference] uncertainty_k2_deg)"
                )
            if u >= self.angle_floor_deg:
                raise ImutoolError(
                    f"reference uncertainty U = {u:g}° is not below the {self.angle_floor_deg:g}° "
                    "tolerance: with a guard band nothing could pass (use a better reference)"
                )


def _read_steps(path: str) -> list[tuple[float, float, float | None]]:
    """Steps file: CSV header ``start,end[,reference]`` (s, s, deg); '#' comments allowed."""
    rows: list[tuple[float, float, float | None]] = []
    with open(path) as f:
        lines = [(i + 1, ln.strip()) for i, ln in enumerate(f)]
    lines = [(i, ln) for i, ln in lines if ln and not ln.startswith("#")]
    if not lines:
        raise ImutoolError("static steps file is empty", path=path)
    head = [h.strip().lower() for h in lines[0][1].split(",")]
    if "start" not in head or "end" not in head:
        raise ImutoolError(
            "static steps file needs a header 'start,end[,reference]' (s, s, deg)", path=path, line=lines[0][0]
        )
    ia, ib = head.index("start"), head.index("end")
    ir = head.index("reference") if "reference" in head else None
    for ln, text in lines[1:]:
        f = [c.strip() for c in text.split(",")]
        try:
            a, b = float(f[ia]), float(f[ib])
            r = float(f[ir]) if ir is not None and ir < len(f) and f[ir] not in ("", "nan") else None
        except (ValueError, IndexError):
            raise ImutoolError(
                f"bad step row {text!r} (expected start,end[,reference] numbers)", path=path, line=ln
            ) from None
        if not b > a:
            raise ImutoolError(f"step end {b} is not after start {a}", path=path, line=ln)
        rows.append((a, b, r))
    return rows


def _dut_outputs(dut: Recording, heel: np.ndarray, o: InclinometerOptions) -> tuple[dict[str, np.ndarray], str]:
    """Per-sample amplitude/period/peak-hold of the DUT: its own HRM fields if present, else derived."""
    have = [c for c in ("amp_port", "amp_stbd", "roll_period") if c in dut.channels]
    if len(have) == 3:
        out = {k: np.asarray(dut[k], float) for k in have}
        out["period_port"] = out["period_stbd"] = out["roll_period"]
        for k in ("peak_port", "peak_stbd"):
            if k in dut.channels:
                out[k] = np.asarray(dut[k], float)
        return out, SRC_DEVICE
    rs = roll_stats(dut.time, heel, hysteresis_deg=o.hysteresis_deg, **MOTION_TABLE)
    return (
        {
            "amp_port": rs.amp_port,
            "amp_stbd": rs.amp_stbd,
            "roll_period": rs.roll_period,
            "period_port": rs.period_port,
            "period_stbd": rs.period_stbd,
            "peak_port": rs.peak_port,
            "peak_stbd": rs.peak_stbd,
        },
        SRC_DERIVED,
    )


_HRM_FIELDS = [
    ("heel", r"(-?\d+(\.\d+)?)?"),
    ("period", r"(\d+(\.\d+)?)?"),
    ("amp_port", r"(\d+(\.\d+)?)?"),
    ("amp_stbd", r"(\d+(\.\d+)?)?"),
    ("status", r"[AV]"),
    ("peak_port", r"(\d+(\.\d+)?)?"),
    ("peak_stbd", r"(\d+(\.\d+)?)?"),
    ("reset_time", r"(\d{6}(\.\d+)?)?"),
    ("reset_day", r"(\d{2})?"),
    ("reset_month", r"(\d{2})?"),
]

# a sentence's fields after the address, joined by commas, against the field patterns joined the same way (no
# pattern matches a comma, so this is each field against its own): one match per sentence, not one per field
_HRM_FORMAT = {n: re.compile(",".join(pat for _n, pat in _HRM_FIELDS[:n])) for n in (5, 10)}


def hrm_capture_check(path: str) -> dict[str, Any]:
    """Interface evidence of an HRM capture: checksum pass rate, field formats, status counts, talkers."""
    n_lines = n_hrm = ck_ok = ck_bad = ck_missing = fmt_bad = too_long = 0
    talkers: dict[str, int] = {}
    status: dict[str, int] = {}
    first_bad: list[str] = []
    with open(path, errors="replace") as f:
        for lineno, raw in enumerate(f, 1):
            line = raw.strip()
            if not line:
                continue
            n_lines += 1
            k = line.find("$")
            if k < 0 or line[k + 3 : k + 7] != "HRM,":
                continue
            s = line[k:]
            n_hrm += 1
            talkers[s[1:3]] = talkers.get(s[1:3], 0) + 1
            if len(s) + 2 > 82:
                too_long += 1
            body, star, cks = s[1:].partition("*")
            if not star:
                ck_missing += 1
                continue
            if cks[:2].upper() != checksum(body):
                ck_bad += 1
                if len(first_bad) < 5:
                    first_bad.append(f"line {lineno}: checksum")
                continue
            ck_ok += 1
            fields = body.split(",")[1:]
            good = len(fields) in _HRM_FORMAT and _HRM_FORMAT[len(fields)].fullmatch(",".join(fields)) is not None
            if not good:
                fmt_bad += 1
                if len(first_bad) < 5:
                    first_bad.append(f"line {lineno}: field format {s[:60]!r}")
            elif len(fields) >= 5:
                status[fields[4]] = status.get(fields[4], 0) + 1
    return {
        "lines": n_lines,
        "hrm_sentences": n_hrm,
        "checksum_ok": ck_ok,
        "checksum_bad": ck_bad,
        "checksum_missing": ck_missing,
        "checksum_pass_rate": (ck_ok / n_hrm) if n_hrm else None,
        "field_format_errors": fmt_bad,
        "over_82_chars": too_long,
        "talkers": talkers,
        "status_counts": status,
        "first_problems": first_bad,
    }


def _durations(t: np.ndarray, gap_factor: float = 3.0) -> np.ndarray:
    """Time each sample stands for (s): half the steps to its neighbours (a non-uniform time base is allowed),
    each step counted up to ``gap_factor`` × the median step (a gap in the samples is not time they cover)."""
    if t.size < 2:
        return np.zeros(t.size)
    g = np.diff(t)
    g = np.minimum(g, gap_factor * float(np.median(g)))
    return 0.5 * (np.concatenate([[g[0]], g]) + np.concatenate([g, [g[-1]]]))


def _time_base(dut: Recording, ref: Recording) -> str:
    """The conventions' time-base sentence: the reference heel's own samples, the DUT's interpolated onto them;
    each named by its stream when it comes from a many-clock log."""

    def of(rec: Recording, who: str) -> str:
        k = rec.meta.get("stream")
        return f"{who}'s heel samples" + (f" (stream {k} of a many-clock log, its own rows only)" if k else "")

    return (
        f"reference time (s): the {of(ref, 'reference')}; the {of(dut, 'DUT')} interpolated linearly onto "
        "them inside the overlap (NaN across a gap in the DUT's samples)"
    )


def _judged_cycles(
    t: np.ndarray,
    cr: Any,
    cd: Any,
    pair: np.ndarray,
    moving: np.ndarray,
    outs_al: dict,
    device: bool,
    o: InclinometerOptions,
    tola: Any,
    tolp: Any,
) -> tuple[dict[int, list], list, dict[str, dict[str, int]]]:
    """Amplitude and period rows of the reference cycles that can be judged, and why the others were not.

    A reference excursion k is judged for amplitude when it is clear of the static steps, its maximum is at
    least ``min_cycle_amp_deg`` and it pairs one-to-one (time overlap) with a DUT excursion j. For the period,
    also the previous same-side excursion k−2 must qualify and pair with j−2 (the same cycle on both units), and
    the crests of the four maxima must be narrower than the period tolerance (time of the maximum resolved).
    The DUT value is its own cycle's (derived) or the value the device displays during its next excursion
    (reported, HRM).
    """
    amp_rows: dict[int, list] = {PORT: [], STBD: []}
    per_rows: list = []
    why_a: dict[str, int] = {}
    why_p: dict[str, int] = {}

    def no(d: dict[str, int], reason: str) -> None:
        d[reason] = d.get(reason, 0) + 1

    def dut_value(name: str, j: int, field: str) -> float:
        if not device:
            return float(getattr(cd, field)[j])
        if j + 1 >= len(cd):
            return float("nan")
        ts = 0.5 * (cd.t_end[j] + cd.t_end[j + 1])
        i = min(int(np.searchsorted(t, ts)), t.size - 1)
        return float(outs_al[name][i])

    for k in range(len(cr)):
        s = int(cr.side[k])
        side = "stbd" if s == STBD else "port"
        if not moving[k]:
            no(why_a, "overlaps a static step")
            no(why_p, "overlaps a static step")
            continue
        amp_ok = cr.amplitude_deg[k] >= o.min_cycle_amp_deg
        j = int(pair[k])
        if not amp_ok:
            no(why_a, f"maximum below {o.min_cycle_amp_deg:g}°")
        elif j < 0:
            no(why_a, "no one-to-one DUT excursion (time overlap)")
        else:
            a_dut = dut_value(f"amp_{side}", j, "amplitude_deg")
            if not np.isfinite(a_dut):
                no(why_a, "no DUT value")
            else:
                a_ref = float(cr.amplitude_deg[k])
                amp_rows[s].append(
                    {
                        "t_peak_s": float(cr.t_peak[k]),
                        "side": side,
                        "reference_deg": a_ref,
                        "dut_deg": a_dut,
                        "error_deg": a_dut - a_ref,
                        "tolerance_deg": float(tola(a_ref)),
                    }
                )
        # period: same-side maxima k-2 and k with one opposite excursion between (imutool.roll)
        if not np.isfinite(cr.period_s[k]) or k < 2 or not moving[k - 2]:
            no(why_p, "no previous same-side maximum in the motion")
            continue
        if not (amp_ok and cr.amplitude_deg[k - 2] >= o.min_cycle_amp_deg):
            no(why_p, f"a maximum below {o.min_cycle_amp_deg:g}°")
            continue
        if j < 2 or int(pair[k - 2]) != j - 2 or not np.isfinite(cd.period_s[j]):
            no(why_p, "no one-to-one DUT cycle (time overlap)")
            continue
        p_ref = float(cr.period_s[k])
        tl = float(tolp(p_ref))
        crest = max(cr.crest_s[k], cr.crest_s[k - 2], cd.crest_s[j], cd.crest_s[j - 2])
        if crest > tl:
            no(why_p, "crest wider than the period tolerance (time of the maximum not resolved)")
            continue
        p_dut = dut_value(f"period_{side}", j, "period_s")
        if not np.isfinite(p_dut):
            no(why_p, "no DUT value")
            continue
        per_rows.append(
            {
                "t_peak_s": float(cr.t_peak[k]),
                "side": side,
                "reference_s": p_ref,
                "dut_s": p_dut,
                "error_s": p_dut - p_ref,
                "tolerance_s": tl,
                "crest_s": float(crest),
            }
        )
    counts = {
        "amplitude": {
            "reference_maxima": len(cr),
            "judged": len(amp_rows[PORT]) + len(amp_rows[STBD]),
            "not_judged": why_a,
        },
        "period": {"reference_maxima": len(cr), "judged": len(per_rows), "not_judged": why_p},
    }
    return amp_rows, per_rows, counts


def _device_function(st: str, why: str, src: str) -> tuple[str, str, str | None]:
    """A device function (amplitude, period, peak hold) passes only on the values the device reported."""
    if src == SRC_DEVICE or st in (NOT_TESTED,):
        return st, why, None
    return (
        NOT_TESTED,
        (
            f"values {SRC_DERIVED}, not reported by the device: the device's own function is not "
            f"tested (imutool's derived values would give: {st}; {why})"
        ),
        st,
    )


def inclinometer_evidence(
    dut: Recording,
    ref: Recording,
    *,
    dut_path: str | None = None,
    ref_path: str | None = None,
    steps_path: str | None = None,
    options: InclinometerOptions | None = None,
    identification: dict[str, Any] | None = None,
    dut_channel: str | None = None,
    ref_channel: str | None = None,
    test_info: dict[str, Any] | None = None,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Build the inclinometer evidence (JSON-safe dict) and the plot arrays. See module docstring.

    dut_channel / ref_channel choose the heel channels (default ``heel``, else ``roll``), e.g. ``ref_roll`` to use
    the truth column of a simulated recording as the reference. test_info: the test record
    (:func:`imutool.report.testinfo.load_test_info`); its declared ranges, reference uncertainty and decision rule
    fill the options that are not set, its external attestations the items imutool cannot test.
    """
    from .testinfo import EXTERNAL, empty_test_info, missing_fields

    o = replace(options) if options is not None else InclinometerOptions()
    info = test_info or empty_test_info()
    if o.declared_heel_range_deg is None:
        o.declared_heel_range_deg = info["dut"].get("heel_range_deg")
    if o.declared_period_range_s is None and info["dut"].get("period_range_s"):
        o.declared_period_range_s = tuple(info["dut"]["period_range_s"])
    if o.uncertainty_k2_deg is None:
        o.uncertainty_k2_deg = info["reference"].get("uncertainty_k2_deg")
    if o.uncertainty_k2_s is None:
        o.uncertainty_k2_s = info["reference"].get("uncertainty_k2_s")
    if info["decision_rule"].get("rule") == "guard band":
        o.guard_band = True
    o.check()
    heel_of(dut, dut_path or "DUT", dut_channel)  # refuses a missing or multi-column heel channel
    heel_of(ref, ref_path or "reference", ref_channel)
    dch = dut_channel or ("heel" if "heel" in dut.channels else "roll")
    rch = ref_channel or ("heel" if "heel" in ref.channels else "roll")
    if (dut_path and ref_path and os.path.realpath(dut_path) == os.path.realpath(ref_path) and dch == rch) or (
        dut is ref and dch == rch
    ):
        raise ImutoolError(
            f"the reference is the DUT itself (same file, channel {dch!r}): a device cannot be its own reference",
            path=ref_path,
        )
    # many clocks: each heel on its own samples (another sentence's row is not a missing heel sample); the
    # reference's other channels (lateral acceleration) are taken onto the reference heel's times
    ref_all, dut_all = ref, dut
    dut, ref = own_samples(dut, dch), own_samples(ref, rch)
    for k in ("amp_port", "amp_stbd", "roll_period", "peak_port", "peak_stbd"):  # the device's own HRM fields,
        if k in dut_all.channels and k not in dut.channels:  # when another sentence also carries its heel
            dut.add(k, dut_all.held(k, dut.time), dut_all.units.get(k))
    h_dut = heel_of(dut, dut_path or "DUT", dch)
    h_ref = heel_of(ref, ref_path or "reference", rch)
    t = ref.time
    dts = _durations(t)
    crit_txt = (
        "every sample/cycle |error| ≤ tolerance"
        if o.criterion == "max"
        else "95th percentile of |error|/tolerance ≤ 1 (MSC.1/Circ.1575 95 % bound)"
    )
    u_a = o.uncertainty_k2_deg if o.guard_band else 0.0
    u_p = (o.uncertainty_k2_s or 0.0) if o.guard_band else 0.0
    gb_txt = (
        f"; acceptance limit = tolerance − U (guard band, U = {u_a:g}° / {u_p:g} s at k = 2)" if o.guard_band else ""
    )
    angle_txt = f"max({o.angle_floor_deg:g}°, {o.angle_pct:g} % of reference reading){gb_txt}; {crit_txt}"
    period_txt = f"max({o.period_floor_s:g} s, {o.period_pct:g} % of reference reading){gb_txt}; {crit_txt}"

    def tola(v: Any) -> np.ndarray:
        return tol_angle(v, o.angle_floor_deg, o.angle_pct) - u_a

    def tolp(v: Any) -> np.ndarray:
        return tol_period(v, o.period_floor_s, o.period_pct) - u_p

    # ---- time alignment -------------------------------------------------------------------------------------
    okd = np.isfinite(h_dut)
    if okd.sum() < 10 or np.isfinite(h_ref).sum() < 10:
        raise ImutoolError("DUT and reference need at least 10 finite heel samples each")
    overlap = min(dut.time[-1], t[-1]) - max(dut.time[0], t[0])
    if overlap <= 0:
        raise ImutoolError("the DUT and reference recordings do not overlap in time (check the clocks)")
    lag, lag_rms = best_lag(dut.time[okd], h_dut[okd], t, h_ref, o.max_lag_s)
    # a heel that stays within the plateau band everywhere has no motion to time: every lag fits as well
    still_ref = float(np.nanmax(h_ref) - np.nanmin(h_ref)) <= o.step_band_deg
    if still_ref:
        lag = 0.0
    lag_at_edge = not still_ref and abs(abs(lag) - o.max_lag_s) < 1e-6
    shift = lag if o.align == "xcorr" else 0.0
    # DUT on the reference time base, the lag removed: x_al(t) = x(t + lag)
    d = interp_to(t, dut.time[okd] - shift, h_dut[okd])
    e = angle_diff_deg(d, h_ref)  # on the circle (formats.frames.angle_diff_deg: exact within ±180°)
    both = np.isfinite(e)
    if both.sum() >= 10 and float(np.max(np.abs(e[both]))) == 0.0 and float(np.ptp(h_ref[both])) > 0:
        raise ImutoolError(
            "the reference is identical to the DUT sample for sample: a device cannot be its own "
            "reference (wrong file or channel?)",
            path=ref_path,
        )
    corr = (
        float(np.corrcoef(d[both], h_ref[both])[0, 1]) if both.sum() > 2 and np.ptp(h_ref[both]) > 0 else float("nan")
    )
    if np.isfinite(corr) and abs(corr) < 0.5 and float(np.std(h_ref[both])) > 0.5:
        raise ImutoolError(
            f"the DUT and reference heel are uncorrelated (r = {corr:.2f}): not the same motion "
            "(wrong file, channel, axis or clock?)",
            path=ref_path,
        )
    if both.sum() > 2 and still_ref:  # no spread of reference values: an offset, no scale
        b1, b0 = float("nan"), float(np.mean(d[both] - h_ref[both]))
    elif both.sum() > 2:
        b1, b0 = np.polyfit(h_ref[both], d[both], 1)
    else:
        b1, b0 = float("nan"), float("nan")
    alignment = {
        "method": "cross-correlation: constant lag minimising RMS(DUT(t) − REF(t − lag)) (imutool.metrics.best_lag)",
        "lag_s": lag,
        "lag_positive_means": "DUT lags the reference",
        "rms_at_lag_deg": lag_rms,
        "search_range_s": o.max_lag_s,
        "lag_at_search_limit": bool(lag_at_edge),
        "applied": o.align == "xcorr",
        "note": (
            "lag removed before comparison (independent clocks assumed); use --align none to count latency as error"
        )
        if o.align == "xcorr"
        else "no lag removed (common clock assumed)",
        "correlation": corr,
        "linear_fit": {
            "offset_deg": b0,
            "scale_error": b1 - 1.0,
            "model": "DUT = offset + (1 + scale_error) · REF on aligned samples",
        },
        "overlap_s": overlap,
    }
    warnings: list[str] = []
    if both.sum() >= 10 and float(np.max(np.abs(e[both]))) == 0.0:
        warnings.append(
            "the DUT equals the reference on every compared sample (|error| 0, heel constant): the same device "
            "or file? (a device cannot be its own reference)"
        )
    if corr < 0:
        warnings.append("DUT and reference heel are anti-correlated: sign convention mismatch (HRM: + starboard)?")
    if overlap < 0.9 * ref.duration:
        warnings.append(f"the DUT covers only {overlap:.0f} s of the {ref.duration:.0f} s reference recording")
    if lag_at_edge:
        warnings.append(f"time lag at the search limit ±{o.max_lag_s} s: alignment unreliable (widen --max-lag)")
    if still_ref:
        alignment["lag_measurable"] = False
        alignment["note"] = "no lag measured: the reference heel does not move; " + alignment["note"]
        warnings.append(
            f"the reference heel stays within {o.step_band_deg:g}° over the whole recording: no motion to "
            "measure a time lag against (lag not measured, 0 s taken)"
        )

    # ---- lateral acceleration applied by the reference (m/s², + starboard) ---------------------------------
    lat = channel_on(ref_all, o.lat_accel_channel, t)
    if lat is not None:
        if lat.ndim != 1:
            raise ImutoolError(f"channel {o.lat_accel_channel!r} must be one column (m/s²)", path=ref_path)
    acc_mask = (np.abs(np.nan_to_num(lat)) >= o.lat_accel_min_ms2) if lat is not None else np.zeros(t.size, bool)
    # samples under any noticeable applied acceleration (≥ 10 % of the threshold) are kept out of the static and
    # dynamic heel items: they belong to the acceleration item (judged from the threshold up)
    acc_any = (np.abs(np.nan_to_num(lat)) >= 0.1 * o.lat_accel_min_ms2) if lat is not None else acc_mask

    items: list[dict[str, Any]] = []
    # ---- static steps (ISO 19697 §6.2) ----------------------------------------------------------------------
    if steps_path:
        steps = _read_steps(steps_path)
        step_src = f"steps file {os.path.basename(steps_path)}"
    else:
        steps = [(a, b, None) for a, b in plateaus(t, h_ref, o.step_band_deg, o.step_min_s, o.step_settle_s)]
        step_src = (
            f"plateaus detected in the reference (range ≤ {o.step_band_deg}° over 2 s, ≥ {o.step_min_s} s, "
            f"first {o.step_settle_s} s ignored)"
        )
    steps = [(a, b, rv) for a, b, rv in steps if not acc_any[(t >= a) & (t <= b)].any()]
    static_mask = np.zeros(t.size, bool)
    step_rows = []
    errs_static = []
    for a, b, rv in steps:
        m = (t >= a) & (t <= b)
        static_mask |= m
        mm = m & both
        if mm.sum() == 0:
            step_rows.append({"start_s": a, "end_s": b, "reference_deg": rv, "n": 0, "status": NOT_TESTED})
            continue
        rmean = float(np.mean(h_ref[mm])) if rv is None else rv
        ee = angle_diff_deg(d[mm], h_ref[mm] if rv is None else rv)
        tl = float(tola(rmean))
        st, info_ = judge(ee, tl, o.criterion)
        errs_static.append(ee)
        step_rows.append(
            {
                "start_s": a,
                "end_s": b,
                "reference_deg": rmean,
                "dut_mean_deg": float(np.mean(d[mm])),
                "error_mean_deg": float(np.mean(ee)),
                "error_std_deg": float(np.std(ee)),
                "max_abs_error_deg": float(np.max(np.abs(ee))),
                "tolerance_deg": tl,
                "n": int(mm.sum()),
                "status": st,
            }
        )
    tested = [r for r in step_rows if r["status"] in (PASS, FAIL)]
    n_stbd = sum(1 for r in tested if r["reference_deg"] > o.level_band_deg)
    n_port = sum(1 for r in tested if r["reference_deg"] < -o.level_band_deg)
    hi_s = max((r["reference_deg"] for r in tested), default=0.0)
    lo_s = min((r["reference_deg"] for r in tested), default=0.0)
    R = o.declared_heel_range_deg
    if not steps:
        st, why = NOT_TESTED, "no static steps (no steps file and no plateau found in the reference)"
    elif any(r["status"] == FAIL for r in tested):
        st, why = FAIL, f"{sum(r['status'] == FAIL for r in tested)} of {len(tested)} steps outside tolerance"
    elif n_stbd < o.min_steps_per_side or n_port < o.min_steps_per_side:
        st, why = (
            INSUFFICIENT,
            (f"{n_stbd} starboard and {n_port} port steps; at least {o.min_steps_per_side} per side needed"),
        )
    elif R is None:
        st, why = (
            INSUFFICIENT,
            (
                f"all {len(tested)} steps within tolerance ({lo_s:+.0f}° to {hi_s:+.0f}°), but the "
                "device's declared heel range is not stated (test record [dut] heel_range_deg): "
                "coverage of the range cannot be assessed"
            ),
        )
    elif min(hi_s, -lo_s) < o.range_cover_frac * R:
        st, why = (
            INSUFFICIENT,
            (
                f"steps reach {lo_s:+.0f}° to {hi_s:+.0f}°; the declared range ±{R:g}° needs steps "
                f"to at least ±{o.range_cover_frac * R:.0f}° on both sides"
            ),
        )
    else:
        st, why = (
            PASS,
            (
                f"all {len(tested)} steps within tolerance ({n_stbd} starboard, {n_port} port), "
                f"{lo_s:+.0f}° to {hi_s:+.0f}° covering the declared range ±{R:g}°"
            ),
        )
    ee_all = np.concatenate(errs_static) if errs_static else np.array([])
    items.append(
        item(
            "static_heel",
            "ISO 19697 §6.2; MSC.363(92) accuracy (P3)",
            "Static actual heel angle",
            st,
            why,
            angle_txt,
            stats(ee_all),
            step_rows,
            {
                "unit": "deg",
                "source": "device heel angle",
                "steps_from": step_src,
                "range_tested_deg": [lo_s, hi_s],
                "declared_range_deg": R,
            },
        )
    )

    # ---- reference and DUT roll cycles ----------------------------------------------------------------------
    rs_ref = roll_stats(t, h_ref, hysteresis_deg=o.hysteresis_deg, **MOTION_TABLE)
    cr = roll_cycles(t, h_ref, o.hysteresis_deg, crest_band_deg=o.crest_band_deg, **MOTION_TABLE)
    cd = roll_cycles(t, d, o.hysteresis_deg, crest_band_deg=o.crest_band_deg, **MOTION_TABLE)
    pair = pair_cycles(cr, cd)
    outs, out_src = _dut_outputs(dut, h_dut, o)
    outs_al = {k: interp_to(t, dut.time - shift, v) for k, v in outs.items()}

    # ---- dynamic heel (§6.3) ---------------------------------------------------------------------------------
    dyn = ~static_mask & ~acc_any & both
    dyn_s = float(dts[dyn].sum())
    n_cyc = int(np.isfinite(cr.period_s).sum())
    e_dyn = e[dyn]
    st, info_ = judge(e_dyn, tola(h_ref[dyn]), o.criterion)
    if not dyn.any():
        st, why = NOT_TESTED, "no data outside the static steps"
    elif dyn_s < o.min_dynamic_s or n_cyc < 2 * o.min_cycles:
        st, why = (
            (FAIL if st == FAIL else INSUFFICIENT),
            (
                f"{dyn_s:.0f} s of motion with {n_cyc} roll half-cycles; at least {o.min_dynamic_s:g} s and "
                f"{2 * o.min_cycles} needed" + ("; tolerance exceeded" if st == FAIL else "")
            ),
        )
    else:
        why = (
            f"{info_['n_exceed']} of {int(dyn.sum())} samples outside tolerance; worst |error|/tolerance "
            f"{info_['worst_ratio']:.2f}, 95th percentile {info_['p95_ratio']:.2f}"
        )
    items.append(
        item(
            "dynamic_heel",
            "ISO 19697 §6.3; MSC.363(92) accuracy (P3)",
            "Dynamic actual heel angle",
            st,
            why,
            angle_txt,
            stats(e_dyn),
            [],
            {"unit": "deg", "duration_s": dyn_s, "ratio": info_, "source": "device heel angle"},
        )
    )

    # ---- amplitude port / starboard and roll period (§6.3, §6.5) --------------------------------------------
    # only excursions clear of the static steps (and of the acceleration segment) are roll cycles
    i_a = np.searchsorted(t, cr.t_start)
    i_b = np.searchsorted(t, cr.t_end, side="right")
    cs = np.concatenate([[0], np.cumsum(static_mask | acc_any)])
    moving = (cs[np.minimum(i_b, t.size)] - cs[i_a]) == 0
    amp_rows, per_rows, cyc_counts = _judged_cycles(
        t, cr, cd, pair, moving, outs_al, out_src == SRC_DEVICE, o, tola, tolp
    )
    resol = (
        f"cycles judged: reference maximum ≥ {o.min_cycle_amp_deg:g}°, paired one-to-one with a DUT "
        f"excursion by time overlap; periods also need both crests (samples within {o.crest_band_deg:g}° of "
        "the maximum) narrower than the period tolerance"
    )
    for s, id_, title in (
        (STBD, "amplitude_stbd", "Roll amplitude to starboard"),
        (PORT, "amplitude_port", "Roll amplitude to port"),
    ):
        rows = amp_rows[s]
        err = np.array([r["error_deg"] for r in rows])
        tl = np.array([r["tolerance_deg"] for r in rows])
        for r in rows:
            r["status"] = judge(np.array([r["error_deg"]]), r["tolerance_deg"], "max")[0]
        st, info_ = judge(err, tl, o.criterion, n_min=o.min_cycles)
        if st == NOT_TESTED:
            why = "no judged roll cycle on this side"
        elif st == INSUFFICIENT:
            why = f"{len(rows)} judged cycles; at least {o.min_cycles} needed"
            if info_["n_exceed"]:
                st, why = FAIL, why + f"; {info_['n_exceed']} outside tolerance"
        else:
            why = f"{info_['n_exceed']} of {len(rows)} judged cycles outside tolerance"
        st, why, derived = _device_function(st, why, out_src)
        items.append(
            item(
                id_,
                "ISO 19697 §6.3; MSC.363(92) accuracy (P3), display both sides (P6)",
                title,
                st,
                why,
                angle_txt,
                stats(err),
                rows,
                {
                    "unit": "deg",
                    "source": out_src,
                    "derived_result": derived,
                    "cycles": cyc_counts["amplitude"],
                    "judging": resol,
                },
            )
        )
    err = np.array([r["error_s"] for r in per_rows])
    tl = np.array([r["tolerance_s"] for r in per_rows])
    for r in per_rows:
        r["status"] = judge(np.array([r["error_s"]]), r["tolerance_s"], "max")[0]
    per_sides = {s: sum(1 for r in per_rows if r["side"] == s) for s in ("port", "stbd")}
    prange = o.declared_period_range_s or o.default_period_range_s
    judged_p = [r["reference_s"] for r in per_rows]
    st, info_ = judge(err, tl, o.criterion, n_min=1)
    if st == NOT_TESTED:
        why = "no judged roll period (needs two judged maxima on the same side)"
    elif min(per_sides.values()) < o.min_cycles:
        why = (
            f"{per_sides['stbd']} starboard and {per_sides['port']} port judged periods; at least "
            f"{o.min_cycles} per side"
        )
        st = FAIL if info_["n_exceed"] else INSUFFICIENT
    elif st == PASS and (
        min(judged_p) > prange[0] / o.range_cover_frac or max(judged_p) < o.range_cover_frac * prange[1]
    ):
        st = INSUFFICIENT
        why = (
            f"all {len(per_rows)} judged periods within tolerance, but they span {min(judged_p):.1f}-"
            f"{max(judged_p):.1f} s; the {'declared' if o.declared_period_range_s else 'default (P10, I)'} range "
            f"{prange[0]:g}-{prange[1]:g} s is not covered"
        )
    else:
        why = (
            f"{info_['n_exceed']} of {len(per_rows)} judged periods outside tolerance "
            f"({min(judged_p):.1f}-{max(judged_p):.1f} s)"
        )
    st, why, derived = _device_function(st, why, out_src)
    items.append(
        item(
            "roll_period",
            "ISO 19697 §6.5; MSC.363(92) accuracy (P4), definition §3 (P1)",
            "Roll period",
            st,
            why,
            period_txt,
            stats(err),
            per_rows,
            {
                "unit": "s",
                "source": out_src,
                "derived_result": derived,
                "cycles": cyc_counts["period"],
                "judging": resol,
                "period_range_s": list(prange),
                "definition": "time between successive maxima on the same side; port "
                "and starboard tracked separately (imutool.roll)",
            },
        )
    )

    # ---- long-term (§6.4) ------------------------------------------------------------------------------------
    holds = []
    for a, b, rv in steps:
        m = (t >= a) & (t <= b) & both
        if m.sum() >= 10:
            holds.append((float(t[m][-1] - t[m][0]), a, b, rv, m))
    extra: dict[str, Any] = {"unit": "deg", "minimum_hold_s": o.long_term_min_s, "source": "device heel angle"}
    ee = np.array([])
    if not holds:
        st, why = NOT_TESTED, f"no static hold (the long-term test needs one of ≥ {o.long_term_min_s:g} s)"
    else:
        dur, a, b, rv, m = max(holds, key=lambda h: h[0])
        rr = h_ref[m] if rv is None else np.full(m.sum(), rv)
        ee = angle_diff_deg(d[m], rr)
        tt = t[m] - t[m][0]
        coef, cov = np.polyfit(tt, ee, 1, cov=True) if m.sum() > 3 else (np.array([np.nan, np.nan]), None)
        slope = float(coef[0]) * 3600.0
        u95 = float(2.0 * np.sqrt(cov[0, 0]) * 3600.0) if cov is not None else float("nan")
        extra.update(
            {
                "duration_s": dur,
                "start_s": a,
                "end_s": b,
                "drift_deg_per_h": slope,
                "drift_u95_deg_per_h": u95,
                "drift_limit_deg_per_h": o.drift_limit_deg_per_h,
            }
        )
        st, info_ = judge(ee, tola(rr), o.criterion)
        base = (
            f"{dur:.0f} s hold at {float(np.mean(rr)):.1f}°: drift {slope:+.3f} ± {u95:.3f} °/h (95 %); "
            f"{info_['n_exceed']} samples outside tolerance"
        )
        if dur < o.long_term_min_s:
            st = FAIL if st == FAIL else INSUFFICIENT
            why = (
                f"longest hold {dur:.0f} s is shorter than the {o.long_term_min_s:g} s minimum (--long-term-min; "
                f"ISO 19697 §6.4 duration not known, C): too short to resolve long-term drift; " + base
            )
        elif o.drift_limit_deg_per_h is not None and u95 > 0.5 * o.drift_limit_deg_per_h:
            st = FAIL if st == FAIL else INSUFFICIENT
            why = (
                f"drift resolution ±{u95:.3f} °/h cannot resolve the {o.drift_limit_deg_per_h:g} °/h limit "
                "(needs ≤ half of it; longer hold needed); " + base
            )
        elif o.drift_limit_deg_per_h is not None and abs(slope) > o.drift_limit_deg_per_h:
            st, why = FAIL, f"drift beyond {o.drift_limit_deg_per_h:g} °/h; " + base
        else:
            why = base
    items.append(
        item(
            "long_term",
            "ISO 19697 §6.4 (duration/limit not confirmed, C)",
            "Long-term heel (drift)",
            st,
            why,
            angle_txt
            + f" over a hold ≥ {o.long_term_min_s:g} s"
            + (f"; |drift| ≤ {o.drift_limit_deg_per_h:g} °/h" if o.drift_limit_deg_per_h else ""),
            stats(ee),
            [],
            extra,
        )
    )

    # ---- peak hold (§6.10) -----------------------------------------------------------------------------------
    own_peak = "peak_port" in dut.channels and "peak_stbd" in dut.channels
    ref_ps = rs_ref.peak_stbd
    ref_pp = rs_ref.peak_port
    peak_rows = []
    e_peak = []
    for name, rp in (("stbd", ref_ps), ("port", ref_pp)):
        dp = outs_al.get(f"peak_{name}")
        if dp is None:
            continue
        m = np.isfinite(dp) & np.isfinite(rp)
        if not m.any():
            continue
        last = int(np.flatnonzero(m)[-1])
        ee = angle_diff_deg(dp[m], rp[m])
        e_peak.append(ee)
        peak_rows.append(
            {
                "side": name,
                "reference_deg": float(rp[last]),
                "dut_deg": float(dp[last]),
                "error_deg": float(angle_diff_deg(dp[last], rp[last])),
                "tolerance_deg": float(tola(rp[last])),
                "max_abs_error_deg": float(np.max(np.abs(ee))),
            }
        )
    peak_src = SRC_DEVICE if own_peak else SRC_DERIVED
    if not peak_rows:
        st, why, eall = NOT_TESTED, "the DUT provides no peak-hold output", np.array([])
    else:
        eall = np.concatenate(e_peak)
        st, info_ = judge(
            np.array([r["error_deg"] for r in peak_rows]), np.array([r["tolerance_deg"] for r in peak_rows]), "max"
        )
        why = "final peak-hold values since the reset compared with the reference maxima"
    st, why, derived = _device_function(st, why, peak_src)
    items.append(
        item(
            "peak_hold",
            "ISO 19697 §6.10 (title only); IEC 61162-1 HRM (P7, C)",
            "Roll peak hold",
            st,
            why,
            f"max({o.angle_floor_deg:g}°, {o.angle_pct:g} % of reading), 1° resolution (P7)",
            stats(eall),
            peak_rows,
            {"unit": "deg", "source": peak_src, "derived_result": derived, "reset_utc": rs_ref.resets_utc},
        )
    )

    # ---- heel under lateral acceleration (ISO 19697 §5.2) ----------------------------------------------------
    acc_txt = (
        f"heel tolerance {angle_txt.split(';')[0]} while |lateral acceleration| ≥ {o.lat_accel_min_ms2:g} "
        "m/s² (ISO 19697 §5.2 conditions not known, C; imutool applies the heel tolerance)"
    )
    if lat is None:
        items.append(
            item(
                "lateral_acceleration",
                "ISO 19697 §5.2 (C)",
                "Heel under lateral acceleration",
                NOT_TESTED,
                f"the reference has no {o.lat_accel_channel!r} channel (applied lateral "
                "acceleration, m/s², + starboard)",
                acc_txt,
                {},
                [],
                {"unit": "deg"},
            )
        )
    else:
        m = acc_mask & both
        secs = float(dts[m].sum())
        ea = e[m]
        st, info_ = judge(ea, tola(h_ref[m]), o.criterion)
        amax = float(np.nanmax(np.abs(lat[m]))) if m.any() else 0.0
        if not m.any():
            st, why = NOT_TESTED, f"no sample with |lateral acceleration| ≥ {o.lat_accel_min_ms2:g} m/s²"
        elif secs < o.lat_accel_min_s:
            st = FAIL if st == FAIL else INSUFFICIENT
            why = f"{secs:.0f} s under acceleration; ≥ {o.lat_accel_min_s:g} s needed"
        else:
            why = (
                f"{secs:.0f} s at up to {amax:.2f} m/s² (apparent tilt of an accelerometer "
                f"{np.degrees(np.arctan2(amax, 9.80665)):.1f}°): {info_['n_exceed']} of {int(m.sum())} samples "
                f"outside tolerance, max |error| {float(np.max(np.abs(ea))):.2f}°"
            )
        items.append(
            item(
                "lateral_acceleration",
                "ISO 19697 §5.2 (C)",
                "Heel under lateral acceleration",
                st,
                why,
                acc_txt,
                stats(ea),
                [],
                {"unit": "deg", "duration_s": secs, "max_accel_ms2": amax, "source": "device heel angle"},
            )
        )

    # ---- interface (§6.6) ------------------------------------------------------------------------------------
    is_nmea = dut_path is not None and os.path.splitext(dut_path)[1].lower() in (".nmea", ".log", ".txt", ".nmea0183")
    if is_nmea:
        cap = hrm_capture_check(dut_path)
        dtt = np.round(np.diff(dut.time), 3)
        rate = float(1.0 / np.median(dtt)) if dtt.size and np.median(dtt) > 0 else None
        cap["output_rate_hz"] = rate
        vals, cnt = np.unique(dtt, return_counts=True)
        top = np.argsort(cnt)[::-1][:3]
        cap["output_intervals_s"] = {f"{vals[i]:g}": int(cnt[i]) for i in top}
        if cap["hrm_sentences"] == 0:
            st, why = FAIL, "no HRM sentence in the capture"
        elif cap["checksum_bad"] or cap["checksum_missing"] or cap["field_format_errors"] or cap["over_82_chars"]:
            st, why = (
                FAIL,
                (
                    f"{cap['checksum_bad']} bad and {cap['checksum_missing']} missing checksums, "
                    f"{cap['field_format_errors']} field-format errors, {cap['over_82_chars']} over 82 chars "
                    f"in {cap['hrm_sentences']} HRM sentences"
                ),
            )
        else:
            st, why = (
                PASS,
                (
                    f"{cap['hrm_sentences']} HRM sentences, all checksums and field formats valid; median "
                    f"output rate {rate:.2f} Hz (no confirmed rate requirement, P11)"
                    if rate
                    else ""
                ),
            )
        items.append(
            item(
                "interface",
                "ISO 19697 §6.6; IEC 61162-1 HRM (standards.md §2.2)",
                "Interface: HRM sentence capture",
                st,
                why,
                "every HRM sentence: valid checksum, IEC 61162-1 field formats, ≤ 82 characters",
                {"n": cap["hrm_sentences"]},
                [],
                {"capture": cap, "meta": clean(dut.meta.get("nmea", {})), "source": SRC_DEVICE},
            )
        )
    else:
        items.append(
            item(
                "interface",
                "ISO 19697 §6.6",
                "Interface: HRM sentence capture",
                NOT_TESTED,
                "the DUT input is not an NMEA capture (give the raw HRM log as DUT to test the interface)",
            )
        )

    # ---- clauses imutool cannot test from data: the test house's attestation ----------------------------------
    for key, (title, clause) in EXTERNAL.items():
        att = info["external"].get(key)
        if att:
            items.append(
                item(
                    key,
                    clause,
                    title,
                    att["result"],
                    f"attested by the test house: {att['evidence']}"
                    + (f" ({att['by']})" if att.get("by") else "")
                    + " — not verified by imutool",
                    None,
                    {"n": 1},
                    [],
                    {"source": "test record attestation (not verified by imutool)"},
                )
            )
        else:
            items.append(
                item(
                    key,
                    clause,
                    title,
                    NOT_TESTED,
                    f"not in the data; the test record gives no [external.{key}] attestation with evidence",
                )
            )

    not_tested = [
        f"{it['title']} ({it['clause']}): {it['reason']}" for it in items if it["status"] in (NOT_TESTED, INSUFFICIENT)
    ] + NOT_TESTED_ALWAYS
    ident = clean(identification or {}) | {
        "dut_device": dut.meta.get("device") or dut.meta.get("sensor"),
        "reference_device": ref.meta.get("device") or ref.meta.get("sensor"),
        "mounting": clean(dut.meta.get("mounting")),
        "calibration": clean(dut.meta.get("calibration")),
        "filter": clean(dut.meta.get("filter")),
    }
    ev = {
        "schema": "imutool-evidence/1",
        "report": "inclinometer",
        "title": "Electronic inclinometer: test evidence per IMO MSC.363(92) / ISO 19697",
        "generated_utc": now_utc(),
        "tool": tool_identity(),
        "scope": SCOPE,
        "test_record": clean({k: v for k, v in info.items()}),
        "test_record_missing": missing_fields(info),
        "identification": ident,
        "inputs": {
            "dut": input_record(dut_path, dut, dch, "nmea" if is_nmea else "recording"),
            "reference": input_record(ref_path, ref, rch, "recording"),
            "static_steps": input_record(steps_path, None, None, "steps") if steps_path else None,
        },
        "conventions": {
            "angle_unit": "deg",
            "time_unit": "s",
            "sign": "heel + starboard down, − port (IEC 61162-1 HRM, P8); port amplitude positive",
            "frame": "vessel body FRD (x bow, y starboard, z down)",
            "time_base": _time_base(dut, ref),
            "lateral_acceleration": "m/s², + starboard, kinematic (gravity excluded)",
        },
        "editions": EDITIONS,
        "criteria": [
            {
                "id": "angle",
                "text": f"heel angle and roll amplitude: max({o.angle_floor_deg:g}°, {o.angle_pct:g} % of reading)",
                "source": "MSC.363(92) annex, accuracy clause (P3)",
                "confidence": "B",
            },
            {
                "id": "period",
                "text": f"roll period: max({o.period_floor_s:g} s, {o.period_pct:g} % of reading)",
                "source": "MSC.363(92) annex, accuracy clause (P4)",
                "confidence": "B",
            },
            {
                "id": "statistic",
                "text": crit_txt,
                "source": "MSC.1/Circ.1575 Table C-1 (P12)"
                if o.criterion == "p95"
                else "imutool default (strictest reading)",
                "confidence": "A" if o.criterion == "p95" else "I",
            },
            {
                "id": "reading",
                "text": "the 'reading' in '% of reading' is the reference value",
                "source": "imutool choice",
                "confidence": "I",
            },
            {
                "id": "decision_rule",
                "text": (
                    "guard band: acceptance limit = tolerance − U of the reference (k = 2)"
                    if o.guard_band
                    else "simple acceptance: the measured error is compared "
                    "with the tolerance; the reference uncertainty is stated, not deducted"
                ),
                "source": "ILAC-G8 decision rules (test record [decision_rule])",
                "confidence": "I",
            },
            {
                "id": "device_functions",
                "text": "amplitude, period and peak hold pass only on values the device "
                "reported (HRM); values derived by imutool from the heel are shown but leave the item not tested",
                "source": "imutool rule",
                "confidence": "I",
            },
            {
                "id": "long_term",
                "text": f"hold ≥ {o.long_term_min_s:g} s",
                "source": "imutool minimum (ISO 19697 §6.4 duration not known)",
                "confidence": "I",
            },
            {
                "id": "ranges",
                "text": f"static steps to ≥ {o.range_cover_frac:.0%} of the declared heel range on both "
                f"sides; judged periods across the declared period range (default {o.default_period_range_s[0]:g}-"
                f"{o.default_period_range_s[1]:g} s)",
                "source": "imutool rule (P9, P10 not found)",
                "confidence": "I",
            },
        ],
        "standards_cited": {"file": STANDARDS_FILE, "rows": standards_cited(CITED)},
        "settings": clean(asdict(o)),
        "alignment": clean(alignment),
        "items": items,
        "overall": overall(items, REQUIRED),
        "not_tested": not_tested,
        "unconfirmed": UNCONFIRMED,
        "warnings": warnings,
    }
    plots = {
        "t": t,
        "ref": h_ref,
        "dut": d,
        "err": e,
        "tol": tola(h_ref),
        "static_mask": static_mask,
        "acc_mask": acc_mask,
        "steps": step_rows,
        "amp_rows": amp_rows[STBD] + amp_rows[PORT],
        "per_rows": per_rows,
        "tol_angle": tola,
        "tol_period": tolp,
        "tol_angle_label": f"tolerance max({o.angle_floor_deg:g}°, {o.angle_pct:g} %)",
        "tol_period_label": f"tolerance max({o.period_floor_s:g} s, {o.period_pct:g} %)",
        "ref_peak_stbd": ref_ps,
        "ref_peak_port": ref_pp,
        "dut_peak_stbd": outs_al.get("peak_stbd"),
        "dut_peak_port": outs_al.get("peak_port"),
    }
    set_clock(ev, plots, ref)
    return ev, plots
