"""Heading-device evidence (e.g. a digital magnetic compass used as a THD) per ISO 22090-2 / IMO MSC.116(73).

``heading_evidence(dut, ref, ...)`` → ``(evidence, plots)`` like the inclinometer report. Items (standards.md §3):

* static error at ≥ 4 (preferably 8) equidistant headings: limit ±1.0° (MSC.116(73) §4.3.2.2, A; ISO 22090-2
  §5.3 ±1.0° 95 %, B);
* dynamic error while rolling/pitching at a constant heading: amplitude ±1.5°, and an error above ±0.5° must have
  a frequency below 0.033 Hz (MSC.116(73) §4.3.2.3, A);
* follow-up error by rate-of-turn band: ±0.5° up to 10 °/s, ±1.5° from 10 to 20 °/s (MSC.116(73) §4.3.2.4, A);
* interface: checksums and 0.1° resolution of HDG/HDT/THS (transmission + resolution error < ±0.2°, §4.3.2.1, A).

Heading error = wrap180(DUT − reference) in degrees; rate of turn from the reference (°/s, + clockwise).
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from formats import Recording
from formats.errors import ImutoolError
from formats.frames import angle_diff_deg
from formats.nmea import checksum
from imutool.metrics import best_lag

from .common import (
    ALIGN,
    CRITERION,
    FAIL,
    INSUFFICIENT,
    MAX_LAG_S,
    NOT_TESTED,
    PASS,
    SCOPE,
    channel_on,
    clean,
    input_record,
    item,
    judge,
    now_utc,
    overall,
    own_samples,
    plateaus,
    set_clock,
    stats,
    tool_identity,
)

EDITIONS = [
    {
        "document": "IMO MSC.116(73)",
        "edition": "Performance standards for transmitting heading devices (THDs)",
        "role": "static, dynamic, follow-up and transmission limits §4.3.2",
        "confidence": "A",
    },
    {
        "document": "ISO 22090-2",
        "edition": "2014 (geomagnetic principles), excerpt of §6.4 only",
        "role": "static test at ≥ 4 equidistant headings, ±1.0° (95 %)",
        "confidence": "B",
    },
    {
        "document": "IEC 61162-1",
        "edition": "HDG/HDT/THS as reproduced in public sources",
        "role": "interface",
        "confidence": "B",
    },
]

UNCONFIRMED = [
    {
        "id": "ISO22090-2-5.5",
        "text": "ISO 22090-2 §5.5 follow-up limit: not seen; MSC.116(73) §4.3.2.4 figures used.",
        "confidence": "B",
    },
    {"id": "ISO22090-2-5.6", "text": "Card settling time limit (§5.6): not found; not tested.", "confidence": "-"},
    {
        "id": "ISO22090-2-5.3",
        "text": "The ±1.0° (95 %) static figure is stated for the compass-card type; applied "
        "here to the DMC as the closest figure.",
        "confidence": "B",
    },
    {
        "id": "A.382",
        "text": "The magnetic sensing part must also meet A.382(X) and be tested separately: not covered.",
        "confidence": "A",
    },
]

NOT_TESTED_ALWAYS = [
    "Settling test (ISO 22090-2 card settling, limit not found).",
    "Operating latitude range (MSC.116(73) §1.3: 70°S-70°N) and magnetic environment: not in the data.",
    "Magnetic sensing part per A.382(X) / ISO 449: separate test, not covered.",
    "Environmental and EMC tests (IEC 60945): external laboratory reports.",
]

REQUIRED = ("static", "dynamic", "follow_up_10", "follow_up_20", "interface")


@dataclass
class HeadingOptions:
    """Tuning constants of the heading report (deg, °/s, s)."""

    static_limit_deg: float = 1.0  # MSC.116(73) §4.3.2.2
    dynamic_limit_deg: float = 1.5  # §4.3.2.3
    dynamic_small_deg: float = 0.5  # above this the error frequency must be < dynamic_max_freq_hz
    dynamic_max_freq_hz: float = 0.033
    follow_low_deg: float = 0.5  # ≤ 10 °/s
    follow_high_deg: float = 1.5  # 10-20 °/s
    band_split_dps: float = 10.0
    band_max_dps: float = 20.0
    band_margin: float = 0.05  # a nominal 20 °/s turn measures 20 ± noise: the bands reach 5 % beyond their edge
    follow_up_test_dps: float = 20.0  # ISO 22090-2 follow-up test rate: the fast band must reach it
    follow_up_test_frac: float = 0.95  # ... to within 5 %
    turn_min_dps: float = 1.0  # |rate of turn| above this = turning
    rot_window_s: float = 1.0  # smoothing of the reference rate of turn
    follow_up_relative: bool = True  # follow-up error = error − static error at that heading (I)
    criterion: str = CRITERION  # max | p95
    align: str = ALIGN  # none (common clock: lag counts as follow-up error) | xcorr
    max_lag_s: float = MAX_LAG_S
    min_headings: int = 4
    step_band_deg: float = 0.2
    step_min_s: float = 10.0
    step_settle_s: float = 2.0
    min_band_s: float = 5.0
    min_dynamic_s: float = 30.0
    min_roll_range_deg: float = 2.0  # motion needed for the dynamic test (peak-to-peak roll)
    roll_window_s: float = 20.0  # window over which the roll range is measured


def heading_of(rec: Recording, channel: str | None, path: str) -> tuple[np.ndarray, str]:
    """Heading series (deg) and the channel used: ``channel`` or the first of heading, heading_true, heading_mag."""
    names = [channel] if channel else ["heading", "heading_true", "heading_mag", "heading_sensor"]
    for n in names:
        if n in rec.channels:
            a = rec.get(n, "deg") if rec.units.get(n) else rec[n]
            return np.asarray(a, float), n
    raise ImutoolError(
        f"needs a heading channel ({', '.join(names)}); has {', '.join(rec.channels) or 'none'}", path=path
    )


def heading_capture_check(path: str) -> dict[str, Any]:
    """Checksums and heading resolution (decimals) of HDG/HDT/THS/HDM sentences in a capture."""
    n = ok = bad = 0
    types: dict[str, int] = {}
    decimals: dict[int, int] = {}
    with open(path, errors="replace") as f:
        for raw in f:
            line = raw.strip()
            k = line.find("$")
            if k < 0:
                continue
            s = line[k:]
            typ = s[3:6]
            if typ not in ("HDG", "HDT", "THS", "HDM"):
                continue
            n += 1
            types[typ] = types.get(typ, 0) + 1
            body, star, cks = s[1:].partition("*")
            if not star or cks[:2].upper() != checksum(body):
                bad += 1
                continue
            ok += 1
            f1 = body.split(",")[1] if "," in body else ""
            if f1:
                d = len(f1.split(".")[1]) if "." in f1 else 0
                decimals[d] = decimals.get(d, 0) + 1
    return {
        "heading_sentences": n,
        "types": types,
        "checksum_ok": ok,
        "checksum_bad": bad,
        "checksum_pass_rate": ok / n if n else None,
        "decimals": {str(k): v for k, v in decimals.items()},
    }


def _moving_mean(x: np.ndarray, w: int) -> np.ndarray:
    """Centred moving mean of x over w samples (as ``np.convolve(..., mode="same")``) of the finite samples only:
    a missing sample is left out (NaN where the window holds none), never counted as 0."""
    ok = np.isfinite(x)
    k = np.ones(w)
    num = np.convolve(np.where(ok, x, 0.0), k, mode="same")
    den = np.convolve(ok.astype(float), k, mode="same")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.maximum(den, 1.0), np.nan)


def _dut_roll(dut: Recording, t: np.ndarray) -> np.ndarray:
    """The DUT's roll (deg) on the reference times t: as :func:`.common.channel_on` from its own samples; a
    single-clock DUT by plain linear interpolation (ends held), as before many clocks."""
    if dut.multi_clock:
        return channel_on(dut, "roll", t)
    return np.interp(t, dut.time, np.asarray(dut["roll"], float))


def _unwrap_deg(h: np.ndarray) -> np.ndarray:
    ok = np.isfinite(h)
    out = np.full_like(h, np.nan)
    out[ok] = np.degrees(np.unwrap(np.radians(h[ok])))
    return out


def heading_evidence(
    dut: Recording,
    ref: Recording,
    *,
    dut_path: str | None = None,
    ref_path: str | None = None,
    dut_channel: str | None = None,
    ref_channel: str | None = None,
    dut_correction_deg: float = 0.0,
    options: HeadingOptions | None = None,
    identification: dict[str, Any] | None = None,
    test_info: dict[str, Any] | None = None,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Build the heading-device evidence (JSON-safe dict) and plot arrays (see module docstring).

    dut_correction_deg is added to the DUT heading first (e.g. magnetic variation, E +, to compare a magnetic
    DUT with a true-heading gyro).
    """
    from .testinfo import empty_test_info, missing_fields

    o = options or HeadingOptions()
    tinfo = test_info or empty_test_info()
    if o.criterion not in ("max", "p95"):
        raise ImutoolError(f"criterion must be 'max' or 'p95' (got {o.criterion!r})")
    if o.align not in ("xcorr", "none"):
        raise ImutoolError(f"align must be 'xcorr' or 'none' (got {o.align!r})")
    _, dch = heading_of(dut, dut_channel, dut_path or "DUT")
    _, rch = heading_of(ref, ref_channel, ref_path or "reference")
    same_file = dut_path and ref_path and os.path.realpath(dut_path) == os.path.realpath(ref_path)
    if (same_file or dut is ref) and dch == rch and dut_correction_deg == 0.0:
        raise ImutoolError(
            f"the reference is the DUT itself (same file, channel {dch!r}): a device cannot be its own reference",
            path=ref_path,
        )
    # many clocks: each heading on its own samples (another sentence's row is not a missing heading); the
    # platform roll is taken from its own samples onto the reference heading's times
    dut_all, ref_all = dut, ref
    dut, ref = own_samples(dut, dch), own_samples(ref, rch)
    h_dut, _ = heading_of(dut, dch, dut_path or "DUT")
    h_ref, _ = heading_of(ref, rch, ref_path or "reference")
    h_dut = (h_dut + dut_correction_deg) % 360.0
    t = ref.time
    okd = np.isfinite(h_dut)
    if okd.sum() < 10 or np.isfinite(h_ref).sum() < 10:
        raise ImutoolError("DUT and reference need at least 10 finite heading samples each")
    overlap = min(dut.time[-1], t[-1]) - max(dut.time[0], t[0])
    if overlap <= 0:
        raise ImutoolError("the DUT and reference recordings do not overlap in time (check the clocks)")
    # remove the mean (circular) error first so a constant offset does not bias the lag during one-way turns
    d0 = np.interp(t, dut.time[okd], _unwrap_deg(h_dut[okd]), left=np.nan, right=np.nan)
    e0 = angle_diff_deg(d0, h_ref)
    e0 = e0[np.isfinite(e0)]
    mean_err = float(np.degrees(np.angle(np.mean(np.exp(1j * np.radians(e0)))))) if e0.size else 0.0
    lag, lag_rms = best_lag(dut.time[okd], (h_dut[okd] - mean_err) % 360.0, t, h_ref, o.max_lag_s, wrap_deg=True)
    shift = lag if o.align == "xcorr" else 0.0
    u_dut = _unwrap_deg(h_dut[okd])
    d = np.interp(t, dut.time[okd] - shift, u_dut, left=np.nan, right=np.nan) % 360.0
    e = angle_diff_deg(d, h_ref)
    both = np.isfinite(e)
    u_ref = _unwrap_deg(h_ref)
    dt = float(np.median(np.diff(t)))
    w = max(1, int(round(o.rot_window_s / dt)))
    ur = _moving_mean(u_ref, w)  # a missing heading is left out of the mean, never taken as 0°
    rot = np.gradient(ur, t)
    rot[~np.isfinite(u_ref)] = np.nan
    rot[:w] = np.nan  # moving-average edge effects
    rot[-w:] = np.nan
    crit_txt = "every sample |error| ≤ limit" if o.criterion == "max" else "95th percentile |error| ≤ limit"
    alignment = {
        "method": "cross-correlation of wrapped heading (imutool.metrics.best_lag, wrap_deg)",
        "lag_s": lag,
        "lag_positive_means": "DUT lags the reference",
        "rms_at_lag_deg": lag_rms,
        "mean_error_removed_for_lag_deg": mean_err,
        "applied": o.align == "xcorr",
        "search_range_s": o.max_lag_s,
        "note": (
            "lag removed (independent clocks): latency is NOT assessed by the follow-up test"
            if o.align == "xcorr"
            else "no lag removed (common clock): latency counts as error"
        ),
        "dut_correction_deg": dut_correction_deg,
        "overlap_s": overlap,
    }
    warnings: list[str] = []
    if o.align == "xcorr":
        warnings.append("time lag removed before comparison: the follow-up error does not include the DUT latency")
    items: list[dict[str, Any]] = []

    # ---- static error at equidistant headings --------------------------------------------------------------
    # platform roll (deg), from the reference, else the DUT, on the reference heading's times (from the roll's own
    # samples): separates static from rolling holds
    roll = channel_on(ref_all, "roll", t)
    if roll is None and "roll" in dut_all.channels:
        roll = _dut_roll(dut_all, t)
    spans = plateaus(t, u_ref, o.step_band_deg, o.step_min_s, o.step_settle_s)
    if roll is not None:

        def still(a: float, b: float) -> bool:
            r = roll[(t >= a) & (t <= b)]
            r = r[np.isfinite(r)]
            return r.size == 0 or float(np.ptp(r)) < o.min_roll_range_deg

        spans = [(a, b) for a, b in spans if still(a, b)]
    static_mask = np.zeros(t.size, bool)
    rows = []
    errs = []
    for a, b in spans:
        m = (t >= a) & (t <= b)
        static_mask |= m
        mm = m & both
        if not mm.any():
            continue
        ee = e[mm]
        st, _ = judge(ee, o.static_limit_deg, o.criterion)
        errs.append(ee)
        hdg = float(np.degrees(np.angle(np.mean(np.exp(1j * np.radians(h_ref[mm])))))) % 360.0
        rows.append(
            {
                "heading_deg": hdg,
                "start_s": a,
                "end_s": b,
                "n": int(mm.sum()),
                "error_mean_deg": float(ee.mean()),
                "max_abs_error_deg": float(np.abs(ee).max()),
                "p95_abs_error_deg": float(np.percentile(np.abs(ee), 95)),
                "limit_deg": o.static_limit_deg,
                "status": st,
            }
        )
    # distinct headings (within 5°) and the largest circular gap
    hd = sorted({round(r["heading_deg"] / 5.0) * 5.0 % 360.0 for r in rows})
    gap = float(max(np.diff(np.concatenate([hd, [hd[0] + 360.0]])))) if hd else 360.0
    max_gap = 1.1 * 360.0 / o.min_headings
    ee_all = np.concatenate(errs) if errs else np.array([])
    if not rows:
        st, why = NOT_TESTED, "no static heading (no plateau in the reference heading)"
    elif any(r["status"] == FAIL for r in rows):
        nf = sum(r["status"] == FAIL for r in rows)
        st, why = FAIL, f"{nf} of {len(rows)} headings outside ±{o.static_limit_deg}°"
    elif len(hd) < o.min_headings or gap > max_gap:
        st, why = (
            INSUFFICIENT,
            (
                f"{len(hd)} distinct headings, largest gap {gap:.0f}°; ≥ {o.min_headings} "
                f"equidistant headings (gap ≤ {max_gap:.0f}°) needed"
            ),
        )
    else:
        st, why = (
            PASS,
            (
                f"{len(hd)} distinct headings (largest gap {gap:.0f}°), all within ±{o.static_limit_deg}°"
                + ("" if len(hd) >= 8 else "; 8 headings are preferable")
            ),
        )
    items.append(
        item(
            "static",
            "MSC.116(73) §4.3.2.2 (A); ISO 22090-2 §6.4/§5.3 (B)",
            "Static heading error",
            st,
            why,
            f"|error| ≤ {o.static_limit_deg}° at each heading; {crit_txt}",
            stats(ee_all),
            rows,
            {"distinct_headings": len(hd), "largest_gap_deg": gap, "unit": "deg", "source": "device heading"},
        )
    )

    # ---- follow-up by rate-of-turn band --------------------------------------------------------------------
    turning = both & ~static_mask & (np.abs(rot) >= o.turn_min_dps)
    # follow-up error isolates turning: the static error at the current heading (interpolated around the circle
    # between the static test headings) is removed when follow_up_relative and static headings exist (I)
    e_fu = e
    fu_note = "raw heading error (no static headings to remove)"
    if o.follow_up_relative and len(rows) >= 2:
        order = np.argsort([r["heading_deg"] for r in rows])
        xp = np.array([rows[i]["heading_deg"] for i in order])
        fp = np.array([rows[i]["error_mean_deg"] for i in order])
        e_fu = e - np.interp(h_ref, xp, fp, period=360.0)
        fu_note = "heading error minus the static error at that heading (interpolated between static headings)"
    elif not o.follow_up_relative:
        fu_note = "raw heading error (static error included)"
    # latency from the follow-up error: e_fu ≈ −rate·latency... sign: DUT(t) = ref(t − L) → error ≈ −rate·L
    mt = turning & np.isfinite(e_fu) & np.isfinite(rot)
    if mt.sum() > 10 and o.follow_up_relative and len(rows) >= 2:
        alignment["latency_from_follow_up_s"] = float(-np.sum(e_fu[mt] * rot[mt]) / np.sum(rot[mt] ** 2))
        alignment["latency_method"] = (
            "least squares of the follow-up error on the reference rate of turn: "
            "error = −rate · latency (static error by heading removed)"
        )
    # band by the largest |rate| within ± rot_window_s: the start of an abrupt turn belongs to the faster band
    from scipy.ndimage import maximum_filter1d

    arot = maximum_filter1d(np.nan_to_num(np.abs(rot)), 2 * w + 1, mode="nearest")
    arot[~np.isfinite(rot)] = np.nan
    top = o.band_max_dps * (1 + o.band_margin)
    for id_, lo, hi, lim, nominal in (
        ("follow_up_10", o.turn_min_dps, o.band_split_dps, o.follow_low_deg, o.band_split_dps),
        ("follow_up_20", o.band_split_dps, top, o.follow_high_deg, o.band_max_dps),
    ):
        m = turning & (arot > lo) & (arot <= hi)
        secs = float(m.sum() * dt)
        st, jinfo = judge(e_fu[m], lim, o.criterion)
        st_raw, jraw = judge(e[m], lim, o.criterion)
        fast_s = float((m & (arot >= o.follow_up_test_frac * o.follow_up_test_dps)).sum() * dt)
        if not m.any():
            st, why = NOT_TESTED, f"no turn at {lo:g}-{hi:g} °/s in the reference"
        elif secs < o.min_band_s:
            st = FAIL if st == FAIL else INSUFFICIENT
            why = f"{secs:.1f} s of turning in the band; ≥ {o.min_band_s:g} s needed"
        else:
            why = (
                f"{secs:.1f} s of turning, max |rate| {float(np.nanmax(arot[m])):.1f} °/s: {jinfo['n_exceed']} of "
                f"{int(m.sum())} samples beyond ±{lim}° (static error removed); raw error: {jraw['n_exceed']} "
                f"beyond, max {float(np.nanmax(np.abs(e[m]))):.2f}°"
            )
            if id_ == "follow_up_20" and st == PASS and fast_s < o.min_band_s:
                st = INSUFFICIENT
                why += (
                    f"; the ISO 22090-2 follow-up test turns at {o.follow_up_test_dps:g} °/s: ≥ {o.min_band_s:g} s "
                    f"at ≥ {o.follow_up_test_frac * o.follow_up_test_dps:g} °/s needed ({fast_s:.1f} s)"
                )
        items.append(
            item(
                id_,
                "MSC.116(73) §4.3.2.4 (A); ISO 22090-2 follow-up test at 20 °/s (B)",
                f"Follow-up error, rate of turn {lo:g}-{nominal:g} °/s",
                st,
                why,
                f"|error| ≤ {lim}°; {crit_txt}",
                stats(e_fu[m]),
                [],
                {
                    "unit": "deg",
                    "duration_s": secs,
                    "error_definition": fu_note,
                    "raw_error_stats": stats(e[m]),
                    "raw_status": st_raw if m.any() else NOT_TESTED,
                    "source": "device heading",
                    "seconds_at_test_rate": fast_s,
                },
            )
        )
    fast = turning & (arot > top)
    if fast.any():
        warnings.append(f"{fast.sum() * dt:.1f} s of turning faster than {o.band_max_dps:g} °/s: reported, not judged")

    # ---- dynamic error (rolling/pitching at a constant heading) --------------------------------------------
    quiet = both & ~static_mask & (np.abs(rot) < o.turn_min_dps)
    secs = float(quiet.sum() * dt)
    extra: dict[str, Any] = {"duration_s": secs, "unit": "deg", "source": "device heading"}
    if roll is None:
        st, why, ed = NOT_TESTED, "no roll channel: motion at constant heading cannot be verified", np.array([])
    else:
        from scipy.ndimage import maximum_filter1d, minimum_filter1d

        win = max(3, int(round(o.roll_window_s / dt)))
        fin = np.isfinite(roll)  # a missing roll is left out of the window's range, never taken as 0°
        rolling = (
            maximum_filter1d(np.where(fin, roll, -np.inf), win, mode="nearest")
            - minimum_filter1d(np.where(fin, roll, np.inf), win, mode="nearest")
        ) >= o.min_roll_range_deg
        m = quiet & np.isfinite(roll) & rolling
        secs = float(m.sum() * dt)
        extra["duration_s"] = secs
        rr = float(np.ptp(roll[m])) if m.any() else 0.0
        ed = e[m]
        extra["roll_range_deg"] = rr
        if not m.any() or rr < o.min_roll_range_deg:
            st, why = NOT_TESTED, f"no rolling at constant heading (roll range {rr:.1f}° < {o.min_roll_range_deg}°)"
        else:
            amp = float(np.max(np.abs(ed)))
            x = ed - ed.mean()
            win_h = np.hanning(x.size)
            spec = np.abs(np.fft.rfft(x * win_h))
            fr = np.fft.rfftfreq(x.size, dt)
            k = 1 + int(np.argmax(spec[1:])) if x.size > 4 else 0
            f_dom = float(fr[k]) if k else float("nan")
            osc = float(2.0 * spec[k] / win_h.sum()) if k else 0.0  # sine amplitude at the dominant frequency
            half_pp = osc
            extra.update({"amplitude_deg": amp, "oscillation_amplitude_deg": osc, "dominant_freq_hz": f_dom})
            st, info = judge(ed, o.dynamic_limit_deg, o.criterion)
            freq_bad = osc > o.dynamic_small_deg and f_dom >= o.dynamic_max_freq_hz
            if st == PASS and freq_bad:
                st = FAIL
            why = (
                f"{secs:.0f} s at constant heading, roll range {rr:.1f}°: max |error| {amp:.2f}°, oscillation "
                f"±{half_pp:.2f}° at {f_dom:.3f} Hz" + ("; oscillation > 0.5° faster than 0.033 Hz" if freq_bad else "")
            )
            if secs < o.min_dynamic_s and st != FAIL:
                st, why = INSUFFICIENT, why + f"; ≥ {o.min_dynamic_s:g} s needed"
    items.append(
        item(
            "dynamic",
            "MSC.116(73) §4.3.2.3 (A)",
            "Dynamic error (rolling at constant heading)",
            st,
            why,
            f"|error| ≤ {o.dynamic_limit_deg}°; oscillations > ±{o.dynamic_small_deg}° slower than "
            f"{o.dynamic_max_freq_hz} Hz",
            stats(ed),
            [],
            extra,
        )
    )

    # ---- interface ----------------------------------------------------------------------------------------------
    is_nmea = dut_path is not None and os.path.splitext(dut_path)[1].lower() in (".nmea", ".log", ".txt", ".nmea0183")
    if is_nmea:
        cap = heading_capture_check(dut_path)
        coarse = sum(v for k, v in cap["decimals"].items() if int(k) < 1)
        if cap["heading_sentences"] == 0:
            st, why = FAIL, "no HDG/HDT/THS sentence in the capture"
        elif cap["checksum_bad"] or coarse:
            st, why = FAIL, f"{cap['checksum_bad']} bad checksums, {coarse} headings with < 0.1° resolution"
        else:
            st, why = PASS, f"{cap['heading_sentences']} sentences, checksums valid, resolution ≤ 0.1°"
        items.append(
            item(
                "interface",
                "MSC.116(73) §4.3.2.1 (A), §4.4",
                "Interface and resolution",
                st,
                why,
                "valid checksums; heading resolution 0.1° (transmission + resolution < ±0.2°)",
                {"n": cap["heading_sentences"]},
                [],
                {"capture": cap},
            )
        )
    else:
        items.append(
            item(
                "interface",
                "MSC.116(73) §4.3.2.1",
                "Interface and resolution",
                NOT_TESTED,
                "the DUT input is not an NMEA capture",
            )
        )

    not_tested = [
        f"{it['title']} ({it['clause']}): {it['reason']}" for it in items if it["status"] in (NOT_TESTED, INSUFFICIENT)
    ] + NOT_TESTED_ALWAYS
    ev = {
        "schema": "imutool-evidence/1",
        "report": "heading",
        "title": "Heading device: test evidence per ISO 22090-2 / IMO MSC.116(73)",
        "generated_utc": now_utc(),
        "tool": tool_identity(),
        "scope": SCOPE,
        "test_record": clean(dict(tinfo)),
        "test_record_missing": missing_fields(tinfo),
        "identification": clean(identification or {})
        | {
            "dut_device": dut.meta.get("device") or dut.meta.get("sensor"),
            "reference_device": ref.meta.get("device") or ref.meta.get("sensor"),
            "mounting": clean(dut.meta.get("mounting")),
            "calibration": clean(dut.meta.get("calibration")),
        },
        "inputs": {
            "dut": input_record(dut_path, dut, dch, "nmea" if is_nmea else "recording"),
            "reference": input_record(ref_path, ref, rch, "recording"),
            "static_steps": None,
        },
        "conventions": {
            "angle_unit": "deg",
            "time_unit": "s",
            "sign": "heading clockwise from north in [0, 360); error = wrap180(DUT − reference); rate of "
            "turn + clockwise (°/s)",
            "frame": "NED (heading about the down axis)",
            "time_base": "reference time (s): the reference heading's own samples"
            + (f" (stream {ref.meta['stream']} of a many-clock log)" if ref.meta.get("stream") else "")
            + "; the DUT heading"
            + (f" (stream {dut.meta['stream']})" if dut.meta.get("stream") else "")
            + " resampled (unwrapped, linear) onto them; the platform roll from its own samples onto them",
        },
        "editions": EDITIONS,
        "criteria": [
            {
                "id": "static",
                "text": f"static error ≤ ±{o.static_limit_deg}°",
                "source": "MSC.116(73) §4.3.2.2",
                "confidence": "A",
            },
            {
                "id": "static_95",
                "text": "±1.0° (95 %) at ≥ 4 equidistant headings",
                "source": "ISO 22090-2 §6.4/§5.3",
                "confidence": "B",
            },
            {
                "id": "dynamic",
                "text": f"dynamic error ≤ ±{o.dynamic_limit_deg}°; > ±{o.dynamic_small_deg}° only below "
                f"{o.dynamic_max_freq_hz} Hz",
                "source": "MSC.116(73) §4.3.2.3",
                "confidence": "A",
            },
            {
                "id": "follow_up",
                "text": f"±{o.follow_low_deg}° up to {o.band_split_dps:g} °/s, ±{o.follow_high_deg}° "
                f"{o.band_split_dps:g}-{o.band_max_dps:g} °/s",
                "source": "MSC.116(73) §4.3.2.4",
                "confidence": "A",
            },
            {
                "id": "follow_up_error",
                "text": fu_note,
                "source": "imutool choice (MSC.116(73) names the follow-up error without a measurement recipe here)",
                "confidence": "I",
            },
            {
                "id": "statistic",
                "text": crit_txt,
                "source": "imutool default (strictest)" if o.criterion == "max" else "ISO 22090-2 95 % figure",
                "confidence": "I" if o.criterion == "max" else "B",
            },
        ],
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
        "err_fu": e_fu,
        "rot": rot,
        "static_mask": static_mask,
        "static_rows": rows,
        "turn_mask": turning,
        "err_raw": e,
        "static_limit_deg": o.static_limit_deg,
        "follow_low_deg": o.follow_low_deg,
        "follow_high_deg": o.follow_high_deg,
        "band_split_dps": o.band_split_dps,
        "band_max_dps": o.band_max_dps,
    }
    set_clock(ev, plots, ref)
    return ev, plots
