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
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from formats import Recording
from formats.errors import ImutoolError
from imutool.metrics import best_lag, interp_to
from imutool.roll import PORT, STBD, heel_of, roll_stats

from .common import (
    FAIL,
    INSUFFICIENT,
    NOT_TESTED,
    PASS,
    SCOPE,
    clean,
    input_record,
    judge,
    now_utc,
    overall,
    plateaus,
    stats,
    tol_angle,
    tol_period,
    tool_identity,
)

EDITIONS = [
    {"document": "IMO MSC.363(92)", "edition": "Performance standards for electronic inclinometers, adopted 14 June "
     "2013", "role": "accuracy criteria (angle, period), definitions §3", "confidence": "A"},
    {"document": "ISO 19697", "edition": "2016 (the ISO/DIS 19697 revision of 2025 was not available)",
     "role": "test clause structure §6.2-§6.10 (clause titles only)", "confidence": "C"},
    {"document": "IEC 61162-1", "edition": "HRM sentence as reproduced in vendor manuals (Ed.5 2016 likely)",
     "role": "interface, sign convention (+ starboard), HRM fields", "confidence": "B"},
    {"document": "IMO MSC.1/Circ.1575", "edition": "PNT guidance, Appendix C Table C-1",
     "role": "95 % interpretation of the accuracy (option --criterion p95)", "confidence": "A"},
    {"document": "SOLAS V/19.2.12 (MSC.532(107))", "edition": "in force 1 January 2026",
     "role": "carriage requirement (context only)", "confidence": "A/B"},
]

UNCONFIRMED = [
    {"id": "P6", "text": "Roll amplitude display resolution (1° is likely but not confirmed).", "confidence": "R"},
    {"id": "P7", "text": "That MSC.363(92) itself requires a peak-hold display is not confirmed (it is in the IEC "
     "61162-1 HRM notes and ISO 19697 §6.10 title).", "confidence": "C"},
    {"id": "P9", "text": "Heel-angle measuring range: not found; the tested range is what the data covered.",
     "confidence": "-"},
    {"id": "P10", "text": "Roll-period measuring range: not found.", "confidence": "-"},
    {"id": "P11", "text": "Output update rate, power-up/settling time, alarm thresholds: not found.",
     "confidence": "-"},
    {"id": "P13", "text": "VDR recording of rolling motion (MSC.333(90) §5.5): recalled, not seen.",
     "confidence": "R"},
    {"id": "ISO19697-5.2", "text": "Acceleration test conditions of ISO 19697 §5.2: not known; not evaluated.",
     "confidence": "C"},
    {"id": "ISO19697-6.4", "text": "Long-term test duration and limit of ISO 19697 §6.4: not known; imutool "
     "applies the heel tolerance over the whole hold and reports the drift rate.", "confidence": "C"},
]

NOT_TESTED_ALWAYS = [
    "Display function (ISO 19697 §6.7): screenshots of heel, roll period and both amplitudes are not in the data.",
    "Alarms (ISO 19697 §4.5, §6.8-6.9): not in the data.",
    "Power supply interruption and restart (ISO 19697 §4.7): not in the data.",
    "Accuracy under lateral/vertical acceleration (ISO 19697 §5.2): conditions not known (unconfirmed).",
    "Environmental and EMC tests (IEC 60945): external laboratory reports; imutool does not produce these.",
    "Reference equipment traceability and uncertainty budget: to be attached by the test house.",
]

REQUIRED = ("static_heel", "dynamic_heel", "amplitude_stbd", "amplitude_port", "roll_period", "long_term")


@dataclass
class InclinometerOptions:
    """Every tuning constant of the inclinometer report (degrees, seconds, percent)."""

    angle_floor_deg: float = 1.0  # MSC.363(92) ±1°
    angle_pct: float = 5.0  # 5 % of reading
    period_floor_s: float = 1.0  # ±1 s
    period_pct: float = 5.0
    criterion: str = "max"  # max | p95 (MSC.1/Circ.1575 95 %)
    align: str = "none"  # none (common clock; latency counts as error) | xcorr (remove the measured constant lag)
    max_lag_s: float = 5.0
    hysteresis_deg: float = 0.5  # roll cycle detection (imutool.roll)
    min_cycles: int = 3  # per side, for amplitude and period items
    min_steps_per_side: int = 2  # static heel steps on each side of zero
    step_band_deg: float = 0.2  # plateau detection: range over the window ≤ band
    step_min_s: float = 10.0  # a plateau lasts at least this long
    step_settle_s: float = 2.0  # ignored at the start of each plateau
    level_band_deg: float = 0.5  # |heel| ≤ this is the level (zero) step, neither side
    drift_min_s: float = 300.0  # minimum static hold for the long-term test
    min_dynamic_s: float = 30.0  # minimum non-static time for the dynamic heel test


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
        raise ImutoolError("static steps file needs a header 'start,end[,reference]' (s, s, deg)", path=path,
                           line=lines[0][0])
    ia, ib = head.index("start"), head.index("end")
    ir = head.index("reference") if "reference" in head else None
    for ln, text in lines[1:]:
        f = [c.strip() for c in text.split(",")]
        try:
            a, b = float(f[ia]), float(f[ib])
            r = float(f[ir]) if ir is not None and ir < len(f) and f[ir] not in ("", "nan") else None
        except (ValueError, IndexError):
            raise ImutoolError(f"bad step row {text!r} (expected start,end[,reference] numbers)", path=path,
                               line=ln) from None
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
        return out, "device output (HRM fields)"
    rs = roll_stats(dut.time, heel, hysteresis_deg=o.hysteresis_deg)
    return ({"amp_port": rs.amp_port, "amp_stbd": rs.amp_stbd, "roll_period": rs.roll_period,
             "period_port": rs.period_port, "period_stbd": rs.period_stbd, "peak_port": rs.peak_port,
             "peak_stbd": rs.peak_stbd},
            "derived by imutool roll from the DUT heel (the same algorithm as `imutool nmea` HRM output)")


_HRM_FIELDS = [
    ("heel", r"(-?\d+(\.\d+)?)?"), ("period", r"(\d+(\.\d+)?)?"), ("amp_port", r"(\d+(\.\d+)?)?"),
    ("amp_stbd", r"(\d+(\.\d+)?)?"), ("status", r"[AV]"), ("peak_port", r"(\d+(\.\d+)?)?"),
    ("peak_stbd", r"(\d+(\.\d+)?)?"), ("reset_time", r"(\d{6}(\.\d+)?)?"), ("reset_day", r"(\d{2})?"),
    ("reset_month", r"(\d{2})?"),
]


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
            if k < 0 or line[k + 3:k + 7] != "HRM,":
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
            x = 0
            for ch in body:
                x ^= ord(ch)
            if cks[:2].upper() != f"{x:02X}":
                ck_bad += 1
                if len(first_bad) < 5:
                    first_bad.append(f"line {lineno}: checksum")
                continue
            ck_ok += 1
            fields = body.split(",")[1:]
            good = len(fields) in (5, 10) and all(
                re.fullmatch(pat, fields[i]) is not None for i, (_n, pat) in enumerate(_HRM_FIELDS[:len(fields)]))
            if not good:
                fmt_bad += 1
                if len(first_bad) < 5:
                    first_bad.append(f"line {lineno}: field format {s[:60]!r}")
            elif len(fields) >= 5:
                status[fields[4]] = status.get(fields[4], 0) + 1
    return {"lines": n_lines, "hrm_sentences": n_hrm, "checksum_ok": ck_ok, "checksum_bad": ck_bad,
            "checksum_missing": ck_missing, "checksum_pass_rate": (ck_ok / n_hrm) if n_hrm else None,
            "field_format_errors": fmt_bad, "over_82_chars": too_long, "talkers": talkers,
            "status_counts": status, "first_problems": first_bad}


def _item(id_: str, clause: str, title: str, status: str, reason: str, criterion: str | None = None,
          stats_: dict | None = None, rows: list | None = None, extra: dict | None = None) -> dict[str, Any]:
    return clean({"id": id_, "clause": clause, "title": title, "status": status, "reason": reason,
                  "criterion": criterion, "stats": stats_ or {}, "rows": rows or [], **(extra or {})})


def inclinometer_evidence(dut: Recording, ref: Recording, *, dut_path: str | None = None,
                          ref_path: str | None = None, steps_path: str | None = None,
                          options: InclinometerOptions | None = None,
                          identification: dict[str, Any] | None = None, dut_channel: str | None = None,
                          ref_channel: str | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
    """Build the inclinometer evidence (JSON-safe dict) and the plot arrays. See module docstring.

    dut_channel / ref_channel choose the heel channels (default ``heel``, else ``roll``), e.g. ``ref_roll`` to use
    the truth column of a simulated recording as the reference.
    """
    o = options or InclinometerOptions()
    if o.criterion not in ("max", "p95"):
        raise ImutoolError(f"criterion must be 'max' or 'p95' (got {o.criterion!r})")
    if o.align not in ("xcorr", "none"):
        raise ImutoolError(f"align must be 'xcorr' or 'none' (got {o.align!r})")
    h_dut = heel_of(dut, dut_path or "DUT", dut_channel)
    h_ref = heel_of(ref, ref_path or "reference", ref_channel)
    dch = dut_channel or ("heel" if "heel" in dut.channels else "roll")
    rch = ref_channel or ("heel" if "heel" in ref.channels else "roll")
    t = ref.time
    crit_txt = ("every sample/cycle |error| ≤ tolerance" if o.criterion == "max"
                else "95th percentile of |error|/tolerance ≤ 1 (MSC.1/Circ.1575 95 % bound)")
    angle_txt = f"max({o.angle_floor_deg:g}°, {o.angle_pct:g} % of reference reading); {crit_txt}"
    period_txt = f"max({o.period_floor_s:g} s, {o.period_pct:g} % of reference reading); {crit_txt}"

    def tola(v: Any) -> np.ndarray:
        return tol_angle(v, o.angle_floor_deg, o.angle_pct)

    # ---- time alignment -------------------------------------------------------------------------------------
    okd = np.isfinite(h_dut)
    if okd.sum() < 10 or np.isfinite(h_ref).sum() < 10:
        raise ImutoolError("DUT and reference need at least 10 finite heel samples each")
    overlap = (min(dut.time[-1], t[-1]) - max(dut.time[0], t[0]))
    if overlap <= 0:
        raise ImutoolError("the DUT and reference recordings do not overlap in time (check the clocks)")
    lag, lag_rms = best_lag(dut.time[okd], h_dut[okd], t, h_ref, o.max_lag_s)
    lag_at_edge = abs(abs(lag) - o.max_lag_s) < 1e-6
    shift = lag if o.align == "xcorr" else 0.0
    # DUT on the reference time base, the lag removed: x_al(t) = x(t + lag)
    d = interp_to(t, dut.time[okd] - shift, h_dut[okd])
    e = d - h_ref
    both = np.isfinite(e)
    corr = float(np.corrcoef(d[both], h_ref[both])[0, 1]) if both.sum() > 2 else float("nan")
    if both.sum() > 2:
        b1, b0 = np.polyfit(h_ref[both], d[both], 1)
    else:
        b1, b0 = float("nan"), float("nan")
    alignment = {
        "method": "cross-correlation: constant lag minimising RMS(DUT(t) − REF(t − lag)) (imutool.metrics.best_lag)",
        "lag_s": lag, "lag_positive_means": "DUT lags the reference", "rms_at_lag_deg": lag_rms,
        "search_range_s": o.max_lag_s, "lag_at_search_limit": bool(lag_at_edge),
        "applied": o.align == "xcorr",
        "note": ("lag removed before comparison (independent clocks assumed); use --align none to count "
                 "latency as error") if o.align == "xcorr" else "no lag removed (common clock assumed)",
        "correlation": corr,
        "linear_fit": {"offset_deg": b0, "scale_error": b1 - 1.0,
                       "model": "DUT = offset + (1 + scale_error) · REF on aligned samples"},
        "overlap_s": overlap,
    }
    warnings: list[str] = []
    if corr < 0:
        warnings.append("DUT and reference heel are anti-correlated: sign convention mismatch (HRM: + starboard)?")
    if overlap < 0.9 * ref.duration:
        warnings.append(f"the DUT covers only {overlap:.0f} s of the {ref.duration:.0f} s reference recording")
    if lag_at_edge:
        warnings.append(f"time lag at the search limit ±{o.max_lag_s} s: alignment unreliable (widen --max-lag)")

    items: list[dict[str, Any]] = []
    # ---- static steps (ISO 19697 §6.2) ----------------------------------------------------------------------
    if steps_path:
        steps = _read_steps(steps_path)
        step_src = f"steps file {os.path.basename(steps_path)}"
    else:
        steps = [(a, b, None) for a, b in plateaus(t, h_ref, o.step_band_deg, o.step_min_s, o.step_settle_s)]
        step_src = (f"plateaus detected in the reference (range ≤ {o.step_band_deg}° over 2 s, ≥ {o.step_min_s} s, "
                    f"first {o.step_settle_s} s ignored)")
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
        ee = d[mm] - (h_ref[mm] if rv is None else rv)
        tl = float(tola(rmean))
        st, info = judge(ee, tl, o.criterion)
        errs_static.append(ee)
        step_rows.append({"start_s": a, "end_s": b, "reference_deg": rmean, "dut_mean_deg": float(np.mean(d[mm])),
                          "error_mean_deg": float(np.mean(ee)), "error_std_deg": float(np.std(ee)),
                          "max_abs_error_deg": float(np.max(np.abs(ee))),
                          "tolerance_deg": tl, "n": int(mm.sum()), "status": st})
    tested = [r for r in step_rows if r["status"] in (PASS, FAIL)]
    n_stbd = sum(1 for r in tested if r["reference_deg"] > o.level_band_deg)
    n_port = sum(1 for r in tested if r["reference_deg"] < -o.level_band_deg)
    if not steps:
        st, why = NOT_TESTED, "no static steps (no steps file and no plateau found in the reference)"
    elif any(r["status"] == FAIL for r in tested):
        st, why = FAIL, f"{sum(r['status'] == FAIL for r in tested)} of {len(tested)} steps outside tolerance"
    elif n_stbd < o.min_steps_per_side or n_port < o.min_steps_per_side:
        st, why = INSUFFICIENT, (f"{n_stbd} starboard and {n_port} port steps; at least {o.min_steps_per_side} "
                                 "per side needed")
    else:
        st, why = PASS, f"all {len(tested)} steps within tolerance ({n_stbd} starboard, {n_port} port)"
    ee_all = np.concatenate(errs_static) if errs_static else np.array([])
    items.append(_item("static_heel", "ISO 19697 §6.2; MSC.363(92) accuracy (P3)", "Static actual heel angle", st,
                       why, angle_txt, stats(ee_all), step_rows,
                       {"source": step_src, "range_tested_deg": [min((r["reference_deg"] for r in tested),
                                                                     default=None),
                                                                 max((r["reference_deg"] for r in tested),
                                                                     default=None)]}))

    # ---- reference roll cycles -------------------------------------------------------------------------------
    rs_ref = roll_stats(t, h_ref, hysteresis_deg=o.hysteresis_deg)
    cyc = rs_ref.cycles
    outs, out_src = _dut_outputs(dut, h_dut, o)
    outs_al = {k: interp_to(t, dut.time - shift, v) for k, v in outs.items()}

    # ---- dynamic heel (§6.3) ---------------------------------------------------------------------------------
    dyn = ~static_mask & both
    dyn_s = float(dyn.sum() / ref.rate_hz) if ref.rate_hz > 0 else 0.0
    n_cyc = int(np.isfinite(cyc.period_s).sum())
    e_dyn = e[dyn]
    st, info = judge(e_dyn, tola(h_ref[dyn]), o.criterion)
    if not dyn.any():
        st, why = NOT_TESTED, "no data outside the static steps"
    elif dyn_s < o.min_dynamic_s or n_cyc < 2 * o.min_cycles:
        st, why = (FAIL if st == FAIL else INSUFFICIENT), (
            f"{dyn_s:.0f} s of motion with {n_cyc} roll half-cycles; at least {o.min_dynamic_s:g} s and "
            f"{2 * o.min_cycles} needed" + ("; tolerance exceeded" if st == FAIL else ""))
    else:
        why = (f"{info['n_exceed']} of {int(dyn.sum())} samples outside tolerance; worst |error|/tolerance "
               f"{info['worst_ratio']:.3f}, 95th percentile {info['p95_ratio']:.3f}")
    items.append(_item("dynamic_heel", "ISO 19697 §6.3; MSC.363(92) accuracy (P3)", "Dynamic actual heel angle", st,
                       why, angle_txt, stats(e_dyn), [], {"duration_s": dyn_s, "ratio": info}))

    # ---- amplitude port / starboard and roll period (§6.3, §6.5) --------------------------------------------
    # only excursions clear of the static steps are roll cycles (a step sequence also crosses zero)
    i_a = np.searchsorted(t, cyc.t_start)
    i_b = np.searchsorted(t, cyc.t_end, side="right")
    cs = np.concatenate([[0], np.cumsum(static_mask)])
    moving = (cs[i_b] - cs[i_a]) == 0
    prev_moving = np.concatenate([[False, False], moving[:-2]]) if len(cyc) >= 2 else np.zeros(len(cyc), bool)
    k_next = np.arange(len(cyc)) + 1
    valid_k = np.flatnonzero((k_next < len(cyc)) & np.isfinite(cyc.period_s) & moving & prev_moving)
    amp_rows: dict[int, list] = {PORT: [], STBD: []}
    per_rows = []
    for k in valid_k:
        s = int(cyc.side[k])
        t_s = 0.5 * (cyc.t_end[k] + cyc.t_end[k + 1])  # while the opposite excursion is under way
        j = min(int(np.searchsorted(t, t_s)), t.size - 1)
        name = "stbd" if s == STBD else "port"
        a_ref = float(cyc.amplitude_deg[k])
        a_dut = float(outs_al[f"amp_{name}"][j])
        amp_rows[s].append({"t_peak_s": float(cyc.t_peak[k]), "side": name, "reference_deg": a_ref,
                            "dut_deg": a_dut, "error_deg": a_dut - a_ref, "tolerance_deg": float(tola(a_ref))})
        p_ref = float(cyc.period_s[k])
        p_dut = float(outs_al[f"period_{name}"][j])
        per_rows.append({"t_peak_s": float(cyc.t_peak[k]), "side": name, "reference_s": p_ref, "dut_s": p_dut,
                         "error_s": p_dut - p_ref,
                         "tolerance_s": float(tol_period(p_ref, o.period_floor_s, o.period_pct))})
    for s, id_, title in ((STBD, "amplitude_stbd", "Roll amplitude to starboard"),
                          (PORT, "amplitude_port", "Roll amplitude to port")):
        rows = amp_rows[s]
        err = np.array([r["error_deg"] for r in rows])
        tl = np.array([r["tolerance_deg"] for r in rows])
        for r in rows:
            r["status"] = judge(np.array([r["error_deg"]]), r["tolerance_deg"], "max")[0]
        st, info = judge(err, tl, o.criterion, n_min=o.min_cycles)
        if st == NOT_TESTED:
            why = "no complete roll cycle on this side in the reference"
        elif st == INSUFFICIENT:
            why = f"{len(rows)} cycles; at least {o.min_cycles} needed"
            if info["n_exceed"]:
                st, why = FAIL, why + f"; {info['n_exceed']} outside tolerance"
        else:
            why = f"{info['n_exceed']} of {len(rows)} cycles outside tolerance"
        items.append(_item(id_, "ISO 19697 §6.3; MSC.363(92) accuracy (P3), display both sides (P6)", title, st, why,
                           angle_txt, stats(err), rows, {"source": out_src}))
    err = np.array([r["error_s"] for r in per_rows])
    tl = np.array([r["tolerance_s"] for r in per_rows])
    for r in per_rows:
        r["status"] = judge(np.array([r["error_s"]]), r["tolerance_s"], "max")[0]
    per_sides = {s: sum(1 for r in per_rows if r["side"] == s and np.isfinite(r["error_s"])) for s in ("port", "stbd")}
    st, info = judge(err, tl, o.criterion, n_min=1)
    if st != NOT_TESTED and min(per_sides.values()) < o.min_cycles:
        why = f"{per_sides['stbd']} starboard and {per_sides['port']} port periods; at least {o.min_cycles} per side"
        st = FAIL if info["n_exceed"] else INSUFFICIENT
    elif st == NOT_TESTED:
        why = "no roll period in the reference (needs two maxima on the same side)"
    else:
        why = f"{info['n_exceed']} of {len(per_rows)} periods outside tolerance"
    items.append(_item("roll_period", "ISO 19697 §6.5; MSC.363(92) accuracy (P4), definition §3 (P1)", "Roll period",
                       st, why, period_txt, stats(err), per_rows,
                       {"source": out_src, "definition": "time between successive maxima on the same side; port "
                        "and starboard tracked separately (imutool.roll)"}))

    # ---- long-term drift (§6.4) ------------------------------------------------------------------------------
    spans = [(a, b, rv) for a, b, rv in steps if b - a >= o.drift_min_s]
    if spans:
        a, b, rv = max(spans, key=lambda s: s[1] - s[0])
        m = (t >= a) & (t <= b) & both
        if m.sum() < 10 or t[m][-1] - t[m][0] < o.drift_min_s:  # the DUT must cover the hold
            spans = []
    if spans:
        rr = h_ref[m] if rv is None else np.full(m.sum(), rv)
        ee = d[m] - rr
        slope = float(np.polyfit(t[m] - t[m][0], ee, 1)[0]) * 3600.0 if m.sum() > 2 else float("nan")
        st, info = judge(ee, tola(rr), o.criterion)
        why = (f"{b - a:.0f} s hold at {float(np.mean(rr)):.2f}°; drift {slope:.3f} °/h; "
               f"{info['n_exceed']} samples outside tolerance")
        extra = {"duration_s": b - a, "drift_deg_per_h": slope, "start_s": a, "end_s": b}
    else:
        longest = max((b - a for a, b, _ in steps), default=0.0)
        st, why, ee, extra = NOT_TESTED, (f"no static hold ≥ {o.drift_min_s:g} s covered by DUT and reference "
                                          f"(longest reference hold {longest:.0f} s)"), np.array([]), {}
    items.append(_item("long_term", "ISO 19697 §6.4 (duration/limit not confirmed)", "Long-term heel (drift)", st, why,
                       angle_txt + " over the whole hold", stats(ee), [], extra))

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
        ee = dp[m] - rp[m]
        e_peak.append(ee)
        peak_rows.append({"side": name, "reference_deg": float(rp[last]), "dut_deg": float(dp[last]),
                          "error_deg": float(dp[last] - rp[last]), "tolerance_deg": float(tola(rp[last])),
                          "max_abs_error_deg": float(np.max(np.abs(ee)))})
    if not peak_rows:
        st, why, eall = NOT_TESTED, "the DUT provides no peak-hold output", np.array([])
    else:
        eall = np.concatenate(e_peak)
        st, info = judge(np.array([r["error_deg"] for r in peak_rows]),
                         np.array([r["tolerance_deg"] for r in peak_rows]), "max")
        why = ("final peak-hold values since the reset compared with the reference maxima; "
               + ("device's own peak hold" if own_peak else "peak hold derived by imutool from the DUT heel"))
        if not own_peak:
            why += "; reset at the start of the recording"
    items.append(_item("peak_hold", "ISO 19697 §6.10 (title only); IEC 61162-1 HRM (P7, C)", "Roll peak hold", st,
                       why, f"max({o.angle_floor_deg:g}°, {o.angle_pct:g} % of reading), 1° resolution (P7)",
                       stats(eall), peak_rows, {"source": "device output (HRM)" if own_peak else out_src,
                                                "reset_utc": rs_ref.resets_utc}))

    # ---- interface (§6.6) ------------------------------------------------------------------------------------
    is_nmea = dut_path is not None and os.path.splitext(dut_path)[1].lower() in (".nmea", ".log", ".txt",
                                                                                  ".nmea0183")
    if is_nmea:
        cap = hrm_capture_check(dut_path)
        rate = float(dut.rate_hz) if len(dut) > 1 else None
        cap["output_rate_hz"] = rate
        if cap["hrm_sentences"] == 0:
            st, why = FAIL, "no HRM sentence in the capture"
        elif cap["checksum_bad"] or cap["checksum_missing"] or cap["field_format_errors"] or cap["over_82_chars"]:
            st, why = FAIL, (f"{cap['checksum_bad']} bad and {cap['checksum_missing']} missing checksums, "
                             f"{cap['field_format_errors']} field-format errors, {cap['over_82_chars']} over 82 chars "
                             f"in {cap['hrm_sentences']} HRM sentences")
        else:
            st, why = PASS, (f"{cap['hrm_sentences']} HRM sentences, all checksums and field formats valid; output "
                             f"rate {rate:.2f} Hz (no confirmed rate requirement, P11)" if rate else "")
        items.append(_item("interface", "ISO 19697 §6.6; IEC 61162-1 HRM (§2.2 of standards.md)",
                           "Interface: HRM sentence capture", st, why,
                           "every HRM sentence: valid checksum, IEC 61162-1 field formats, ≤ 82 characters",
                           {"n": cap["hrm_sentences"]}, [], {"capture": cap, "meta": clean(dut.meta.get("nmea", {}))}))
    else:
        items.append(_item("interface", "ISO 19697 §6.6", "Interface: HRM sentence capture", NOT_TESTED,
                           "the DUT input is not an NMEA capture (give the raw HRM log as DUT to test the interface)"))

    not_tested = [f"{it['title']} ({it['clause']}): {it['reason']}" for it in items
                  if it["status"] in (NOT_TESTED, INSUFFICIENT)] + NOT_TESTED_ALWAYS
    ev = {
        "schema": "imutool-evidence/1",
        "report": "inclinometer",
        "title": "Electronic inclinometer: test evidence per IMO MSC.363(92) / ISO 19697",
        "generated_utc": now_utc(),
        "tool": tool_identity(),
        "scope": SCOPE,
        "identification": clean(identification or {}) | {
            "dut_device": dut.meta.get("device") or dut.meta.get("sensor"),
            "reference_device": ref.meta.get("device") or ref.meta.get("sensor"),
            "mounting": clean(dut.meta.get("mounting")), "calibration": clean(dut.meta.get("calibration")),
            "filter": clean(dut.meta.get("filter")),
        },
        "inputs": {"dut": input_record(dut_path, dut, dch, "nmea" if is_nmea else "recording"),
                   "reference": input_record(ref_path, ref, rch, "recording"),
                   "static_steps": input_record(steps_path, None, None, "steps") if steps_path else None},
        "conventions": {"angle_unit": "deg", "time_unit": "s",
                        "sign": "heel + starboard down, − port (IEC 61162-1 HRM, P8); port amplitude positive",
                        "frame": "vessel body FRD (x bow, y starboard, z down)",
                        "time_base": "reference time (s); DUT resampled linearly onto it"},
        "editions": EDITIONS,
        "criteria": [
            {"id": "angle", "text": f"heel angle and roll amplitude: max({o.angle_floor_deg:g}°, {o.angle_pct:g} % of "
             "reading)", "source": "MSC.363(92) annex, accuracy clause (P3)", "confidence": "B"},
            {"id": "period", "text": f"roll period: max({o.period_floor_s:g} s, {o.period_pct:g} % of reading)",
             "source": "MSC.363(92) annex, accuracy clause (P4)", "confidence": "B"},
            {"id": "statistic", "text": crit_txt, "source": "MSC.1/Circ.1575 Table C-1 (P12)" if o.criterion == "p95"
             else "imutool default (strictest reading)", "confidence": "A" if o.criterion == "p95" else "I"},
            {"id": "reading", "text": "the 'reading' in '% of reading' is the reference value",
             "source": "imutool choice", "confidence": "I"},
        ],
        "settings": clean(asdict(o)),
        "alignment": clean(alignment),
        "items": items,
        "overall": overall(items, REQUIRED),
        "not_tested": not_tested,
        "unconfirmed": UNCONFIRMED,
        "warnings": warnings,
    }
    plots = {"t": t, "ref": h_ref, "dut": d, "err": e, "tol": tola(h_ref), "static_mask": static_mask,
             "steps": step_rows, "amp_rows": amp_rows[STBD] + amp_rows[PORT], "per_rows": per_rows,
             "tol_angle": tola, "tol_period": lambda v: tol_period(v, o.period_floor_s, o.period_pct),
             "tol_angle_label": f"tolerance max({o.angle_floor_deg:g}°, {o.angle_pct:g} %)",
             "tol_period_label": f"tolerance max({o.period_floor_s:g} s, {o.period_pct:g} %)",
             "ref_peak_stbd": ref_ps, "ref_peak_port": ref_pp,
             "dut_peak_stbd": outs_al.get("peak_stbd"), "dut_peak_port": outs_al.get("peak_port")}
    return ev, plots
