"""The EKF's self-check reports: inconsistency spans, heading, new field, tilt, GNSS and heading source."""

from __future__ import annotations

import numpy as np

from imutool.attitude.layout import F_INCONSISTENT
from imutool.attitude.params import EkfParams


def self_check(
    time: np.ndarray, flags: np.ndarray, max_spans: int = 20, n_total: int | None = None
) -> tuple[dict, list[str]]:
    """Summary of the innovation-consistency monitor: flagged share, time spans (s) and warnings to show.

    ``n_total``: number of samples the share refers to (default: len(flags)); a flag-0 row separates spans."""
    bad = (np.asarray(flags) & F_INCONSISTENT) > 0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(np.int8), [0]])))
    spans = [(float(time[a]), float(time[b - 1])) for a, b in zip(edges[::2], edges[1::2], strict=True)]
    return inconsistency_report(spans, int(bad.sum()), len(bad) if n_total is None else n_total, max_spans)


def _spans_text(spans: list, shown: int = 5) -> str:
    """The first ``shown`` (start, end) spans in s for a warning line, "and N more" after them."""
    text = ", ".join(f"{a:.1f}–{b:.1f} s" for a, b in spans[:shown])
    return text + (f" and {len(spans) - shown} more" if len(spans) > shown else "")


def inconsistency_report(spans: list, n_flagged: int, n_total: int, max_spans: int = 20) -> tuple[dict, list[str]]:
    """The self-check's summary and warning from its flagged spans [(start, end) s] and sample counts."""
    share = float(n_flagged) / max(1, n_total)
    info: dict = {"inconsistent_samples": int(n_flagged), "inconsistent_share": round(share, 6)}
    if not n_flagged:
        return info, []
    info["inconsistent_spans_s"] = [[round(a, 3), round(b, 3)] for a, b in spans[:max_spans]]
    shown = _spans_text(spans)
    warn = (
        f"the attitude filter's self-check failed on {100 * share:.1f} % of samples ({shown}): its "
        "accelerometer/magnetometer innovations are far larger than its covariance allows, so the estimate "
        "is not trustworthy there (column 'inconsistent' = 1); sustained acceleration, a wrong mounting or "
        "units, or a diverging filter"
    )
    return info, [warn]


class FlagSpans:
    """Time spans (s) where a per-sample flag is set, fed chunk by chunk with O(spans) memory.

    Flagged samples less than ``join_s`` apart belong to one span; closed spans shorter than ``min_s`` are
    dropped as they close (a day of short rejections does not pile up)."""

    def __init__(self, min_s: float, join_s: float = 1.0) -> None:
        self.min_s, self.join_s = float(min_s), float(join_s)
        self.spans: list[list[float]] = []

    def add(self, time: np.ndarray, mask: np.ndarray) -> None:
        tf = np.asarray(time)[np.asarray(mask, bool)]
        if len(tf) == 0:
            return
        cut = np.flatnonzero(np.diff(tf) > self.join_s)
        for a, b in zip(np.concatenate([[0], cut + 1]), np.concatenate([cut, [len(tf) - 1]]), strict=True):
            if self.spans and tf[a] - self.spans[-1][1] <= self.join_s:
                self.spans[-1][1] = float(tf[b])
                continue
            if self.spans and self.spans[-1][1] - self.spans[-1][0] < self.min_s:
                self.spans.pop()
            self.spans.append([float(tf[a]), float(tf[b])])

    def long_spans(self) -> list[tuple[float, float]]:
        return [(a, b) for a, b in self.spans if b - a >= self.min_s]


def heading_check(spans: FlagSpans, max_spans: int = 20, params: EkfParams | None = None) -> tuple[dict, list[str]]:
    """Where the magnetometer was rejected for longer than ``spans.min_s`` (``mag_check_time``): summary and
    warning. The rejection keeps a disturbed field out of the heading, but there the heading is the gyro's
    alone and drifts with its bias and scale errors; the filter's σ does not show that drift in full."""
    long = spans.long_spans()
    if not long:
        return {}, []
    total = sum(b - a for a, b in long)
    info = {"mag_rejected_spans_s": [[round(a, 3), round(b, 3)] for a, b in long[:max_spans]]}
    shown = _spans_text(long)
    warn = (
        f"the magnetometer was rejected for {total:.0f} s in {len(long)} span(s) of more than "
        f"{spans.min_s:g} s ({shown}): the field there differs from the one at the start (a magnet or steel "
        "nearby, a new mounting or calibration?), so the heading is the gyro's alone and drifts with its "
        "bias (column 'mag_rejected' = 1)"
    )
    if params is not None and params.mag_new_time > 0:
        warn += (
            f"; a steady new field is taken as the reference only after it has held for "
            f"{params.mag_new_time:g} s while the sensor turned faster than {params.mag_new_min_rate:g} °/s, "
            "which a ship rolling at sea never does: on board the magnetometer stays rejected until the "
            "field it started with returns"
        )
    return info, [warn]


def new_field_check(times: list[float], params: EkfParams, max_times: int = 20) -> tuple[dict, list[str]]:
    """Where the magnetometer's reference field was replaced (``times``, s: the samples flagged F_MAG_NEW):
    summary and warning. A field the gates rejected stayed within those gates of itself for ``mag_new_time`` s
    while the body turned (``mag_new_first_time`` before the first reference held while turning): the sensor moved
    to another field, or the field where the recording started was the disturbed one. The heading follows the
    new field from there; were it a magnet riding with the sensor, that would be wrong, so it is said."""
    if not times:
        return {}, []
    shown = ", ".join(f"{t:.1f}" for t in times[:max_times]) + (" …" if len(times) > max_times else "")
    info = {"mag_new_field_s": [round(float(t), 3) for t in times[:max_times]]}
    warn = (
        f"the magnetometer's reference field was replaced {len(times)} time(s), at t = {shown} s: a field its "
        f"gates rejected held steady for {params.mag_new_first_time:g} s ({params.mag_new_time:g} s once a "
        f"reference had held) while the sensor turned faster than {params.mag_new_min_rate:g} °/s, so the "
        "sensor moved to another field or the field at the start was disturbed; the heading follows the new "
        "field from there. If a magnet or steel moved with the sensor then, or the magnetometer is not "
        "calibrated (imutool calibrate mag), the heading after that time is wrong (--param mag_new_time=0 "
        "keeps the first field)"
    )
    return info, [warn]


def tilt_check(summary: dict, params: EkfParams) -> list[str]:
    """The warning of the vertical's self-check, from a run summary's ``tilt_check_samples`` and
    ``tilt_check_max_deg`` (the largest tilt checked, flagged or not; both cumulative, so a streamed run's last
    chunk gives the whole run's).

    The innovation check compares the filter with its own low-passed accelerometer, which rotates with the same gyro:
    a gyro in the wrong unit or with a reversed axis can leave both wrong together and the innovations small. The
    world-frame mean of the specific force does not rotate with the gyro's error, and over tilt_check_window it is
    vertical whatever the motion (|Δv| / τ: 3 m/s over 20 s is 0.9°); the window restarts after a gap. Measured
    (20 s; none flagged at 3°): intact ship-roll ≤ 0.42°, ship-at-sea ≤ 2.05° with lever arm and SOG/COG and
    ≤ 2.45° for the bridge sensor given neither (its inclination is then 2° off), the 16 BROAD trials ≤ 1.23°; a gyro
    ×3 on ship-roll 4.3° at most, an x axis reversed 8.4°."""
    n = int(summary.get("tilt_check_samples", 0) or 0)
    if not n:
        return []
    return [
        f"the estimate's vertical disagrees with gravity on {n} samples: the specific force in the world frame, "
        f"low-passed over {params.tilt_check_window:g} s (its mean is vertical when the velocity is bounded), "
        f"tilts up to {summary.get('tilt_check_max_deg', 0.0):.1f}° from it (limit √({params.tilt_check_deg:g}²"
        " + (3 σ)²), σ of the estimate's tilt); a gyro in the wrong unit or scale, a reversed or swapped axis, "
        "or an acceleration the filter was not told of (a turn without SOG/COG, a lever arm not given)"
    ]


def gnss_heading_check(used_gnss: bool, mag_used: bool) -> list[str]:
    """The SOG/COG turn compensation turns the course into body axes with the filter's heading. Without a
    magnetometer nothing holds that heading (it starts at 0° and drifts with the gyro bias), so the compensation
    can add the error it is there to remove: one warning line then, none otherwise. Measured on `imutool simulate
    ship-at-sea` seeds 0 / 1 / 3 (lever arm + SOG/COG, roll RMS after the first minute): 0.19° with the
    magnetometer; without it 1.75 / 1.16 / 0.21° (max 4.9°), right only where the ship happened to head near 0°
    at the start; lever arm alone without a magnetometer 1.20 / 1.15 / 1.19°. ``mag_used``: any magnetometer
    update taken in the run (a `mag` column that is all NaN, or ``mag_mode = "off"``, holds no heading either)."""
    if not used_gnss or mag_used:
        return []
    return [
        "SOG/COG turn compensation without a magnetometer heading: the course is turned into body axes with a "
        "heading nothing holds (starts at 0°, drifts with the gyro bias), so the compensation can add roll "
        "error instead of removing it (simulated bridge sensor: 0.2–1.8° roll RMS, max 4.9°, against 0.19° "
        "with a magnetometer); give the magnetometer or a gyrocompass heading (--heading, channel heading_true), "
        "or drop SOG/COG (--no-gnss)"
    ]


def heading_source_report(
    heading_given: bool, mag_given: bool, heading_updates: int, params: EkfParams, duration_s: float = 0.0
) -> tuple[dict, list[str]]:
    """Where the heading came from (summary ``heading_source``, ``heading_input_updates``), and one warning
    where an external heading was given (a ``heading_true`` channel or --heading) but held no usable value, or
    covered less than half of the run's ``duration_s`` (s): the magnetometer is then not used either, so the
    heading is the gyro's alone there."""
    if heading_given:
        out = {
            "heading_source": "heading_true (external; magnetometer not used)",
            "heading_input_updates": int(heading_updates),
        }
        if heading_updates and duration_s > 0 and params.heading_input_interval > 0:
            share = heading_updates * params.heading_input_interval / duration_s
            if share < 0.5:
                return out, [
                    f"the external heading (heading_true) was used {heading_updates} times over "
                    f"{duration_s:.0f} s: it covers about {100 * min(share, 1):.0f} % of the run; in between "
                    "the heading is the gyro's alone (the magnetometer is not used when one is given)"
                ]
        if heading_updates == 0:
            return out, [
                "heading_true (external heading) holds no valid value in the run: the magnetometer is not "
                "used when one is given, so the heading is the gyro's alone (drop the column or fix the "
                "heading feed)"
            ]
        return out, []
    return {"heading_source": "magnetometer" if mag_given and params.mag_mode != "off" else "none (gyro)"}, []
