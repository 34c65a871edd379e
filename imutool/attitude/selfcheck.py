"""The EKF's self-checks: one accumulator (:class:`SelfCheck`, fed chunk by chunk, the same in memory and streamed)
over the reports (inconsistency spans, heading, new field, tilt, GNSS, heading source and lag, gyro scale), the
output metadata they compose (:func:`output_metadata`), and the per-sample flags by name (:class:`SampleFlag`).

To add a self-check: a report function here (summary keys, warning lines), fed from :meth:`SelfCheck.add` and
called from :meth:`SelfCheck.report`; both the in-memory (:func:`imutool.attitude.ekf_recording`) and the streamed
(:func:`imutool.filtering.stream_ekf`) runs then have it.
"""

from __future__ import annotations

import enum
from typing import Any, NamedTuple

import numpy as np

from formats.saturation import Clipping, clipping_warning
from imutool.attitude.layout import (
    F_ACC_REJ,
    F_ACC_USED,
    F_HDG_INCONSISTENT,
    F_HDG_USED,
    F_INCONSISTENT,
    F_MAG_NEW,
    F_MAG_REJ,
    F_MAG_USED,
    F_REST,
)
from imutool.attitude.params import EkfParams
from imutool.gyro_check import GyroScaleCheck
from imutool.heading_lag import HeadingLagTrack, heading_lag_check
from imutool.quaternion import vertical_rate


class SampleFlag(enum.IntFlag):
    """The bits of the filter's per-sample ``flags`` (uint16, :attr:`AttitudeResult.flags`; the kernels set them with
    the ``F_*`` constants of :mod:`~imutool.attitude.layout`, which these name)."""

    ACCEL_REJECTED = (
        F_ACC_REJ  #: the accelerometer was not used at this sample (a gate, a shock): column accel_rejected
    )
    MAG_REJECTED = F_MAG_REJ  #: the magnetometer was rejected by its gates (norm, dip, NIS): column mag_rejected
    REST = F_REST  #: the body was detected at rest (zero-rate update): column rest
    ACCEL_USED = F_ACC_USED  #: an accelerometer update was taken at this sample
    MAG_USED = F_MAG_USED  #: a magnetometer (heading or full) update was taken at this sample
    INCONSISTENT = F_INCONSISTENT  #: the accelerometer's windowed NIS or the tilt check failed: column inconsistent
    HEADING_USED = F_HDG_USED  #: an external heading (heading_true) update was taken at this sample
    MAG_NEW_FIELD = F_MAG_NEW  #: the magnetometer's reference was replaced by a new field at this sample
    HEADING_INCONSISTENT = F_HDG_INCONSISTENT  #: the heading's NIS failed here: column heading_inconsistent


def has_flag(flags: np.ndarray, flag: SampleFlag) -> np.ndarray:
    """Per sample: is ``flag`` set in ``flags`` (uint16)? A bool array."""
    return (np.asarray(flags).astype(np.uint16, copy=False) & np.uint16(flag)) > 0


def self_check(
    time: np.ndarray, flags: np.ndarray, max_spans: int = 20, n_total: int | None = None
) -> tuple[dict, list[str]]:
    """Summary of the innovation-consistency monitor: flagged share, time spans (s) and warnings to show.

    ``n_total``: number of samples the share refers to (default: len(flags)); a flag-0 row separates spans."""
    bad = has_flag(flags, SampleFlag.INCONSISTENT)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(np.int8), [0]])))
    spans = [(float(time[a]), float(time[b - 1])) for a, b in zip(edges[::2], edges[1::2], strict=True)]
    return inconsistency_report(spans, int(bad.sum()), len(bad) if n_total is None else n_total, max_spans)


def _spans_text(spans: list, shown: int = 5, n_spans: int | None = None) -> str:
    """The first ``shown`` (start, end) spans in s for a warning line, "and N more" after them (``n_spans``: how many
    there are, where ``spans`` holds only the first ones)."""
    n = len(spans) if n_spans is None else n_spans
    text = ", ".join(f"{a:.1f}–{b:.1f} s" for a, b in spans[:shown])
    return text + (f" and {n - shown} more" if n > shown else "")


def inconsistency_report(
    spans: list, n_flagged: int, n_total: int, max_spans: int = 20, n_spans: int | None = None
) -> tuple[dict, list[str]]:
    """The self-check's summary and warning from its flagged spans [(start, end) s] and sample counts; ``n_spans``
    the number of spans where ``spans`` holds only the first ones (default: len(spans))."""
    share = float(n_flagged) / max(1, n_total)
    info: dict = {"inconsistent_samples": int(n_flagged), "inconsistent_share": round(share, 6)}
    if not n_flagged:
        return info, []
    info["inconsistent_spans_s"] = [[round(a, 3), round(b, 3)] for a, b in spans[:max_spans]]
    shown = _spans_text(spans, n_spans=n_spans)
    warn = (
        f"the attitude filter's self-check failed on {100 * share:.1f} % of samples ({shown}): its "
        "accelerometer innovations (or the tilt check) are far larger than its covariance allows, so roll and "
        "pitch are not trustworthy there (column 'inconsistent' = 1); sustained acceleration, a wrong mounting "
        "or units, or a diverging filter"
    )
    return info, [warn]


# a ship's sustained turn, said when no speed is given: the heading's rate over TURN_SMOOTH_S s beyond TURN_RATE
# deg/s for at least TURN_MIN_S s (a seaway's yaw, ±1.5° at 12 s, stays below; a course change at 1 °/s is a turn)
TURN_RATE, TURN_SMOOTH_S, TURN_MIN_S = 0.5, 20.0, 30.0
# the smoothed rate is evaluated every TURN_STEP_S (its spans are reported to 0.1 s) and at every sample between two
# evaluations that disagree, so a turn's start and end are those of the sample-by-sample rate (0 s: every sample)
TURN_STEP_S = 0.05


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
    """Velocity aiding turns the GNSS velocity into body axes with the filter's heading. Without a magnetometer or
    gyrocompass nothing holds that heading (it starts at 0° and drifts with the gyro bias), so the filter then uses
    only the speed, along the bow: the turn's centripetal term, not the sway or surge (:func:`run_ekf`). One
    warning line then, none otherwise. Measured on `imutool simulate ship-at-sea` seeds 0 / 1 / 3 (lever arm +
    SOG/COG, roll RMS after the first minute): 0.09–0.11° with the magnetometer; without it, the velocity turned
    with the unheld heading gave 2.99 / 2.36 / 0.19° (max 5.8°); along the bow (now), see docs/attitude.md.
    ``mag_used``: any heading update taken in the run (a `mag` column that is all NaN, or ``mag_mode = "off"``,
    holds no heading either)."""
    if not used_gnss or mag_used:
        return []
    return [
        "GNSS velocity without a heading (no magnetometer heading, no gyrocompass): the velocity cannot be turned "
        "into body axes, so only the speed is used, along the bow (the turn's centripetal acceleration); the "
        "sway and surge in it are not removed — give the magnetometer or a gyrocompass heading (--heading, "
        "channel heading_true) for full velocity aiding"
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


class RunSpans:
    """Runs of consecutive flagged samples, fed chunk by chunk (a run open at a chunk's end goes on into the next):
    the first ``keep`` (start, end) in s, and how many there are. The same spans as :func:`self_check` of the whole
    run at once, in O(keep) memory."""

    def __init__(self, keep: int = 20) -> None:
        self.keep = keep
        self.spans: list[list[float]] = []
        self.count = 0
        self.open = False  # the last sample added was flagged
        self.n_flagged = 0

    def add(self, time: np.ndarray, bad: np.ndarray) -> None:
        bad = np.asarray(bad, bool)
        if len(bad) == 0:
            return
        self.n_flagged += int(bad.sum())
        edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if a == 0 and self.open:  # continues the run open at the previous chunk's end
                if self.count <= self.keep:
                    self.spans[-1][1] = float(time[b - 1])
                continue
            self.count += 1
            if self.count <= self.keep:
                self.spans.append([float(time[a]), float(time[b - 1])])
        self.open = bool(bad[-1])


class SelfCheckReport(NamedTuple):
    """What :meth:`SelfCheck.report` gives: the summary's self-check keys, the warning lines (in this order:
    inconsistency, heading source, heading lag, magnetometer rejection, new field, tilt, GNSS, gyro scale) and the
    output's metadata keys (:func:`output_metadata`)."""

    summary: dict[str, Any]
    warnings: list[str]
    metadata: dict[str, Any]


class SelfCheck:
    """Every self-check of one filter run, fed chunk by chunk (:meth:`add`; in memory: one chunk), reported once
    (:meth:`report`). O(spans) memory: a streamed day keeps no per-sample array.

    ``params`` the run's parameters; ``dt_nominal`` (s) the IMU's nominal step (the gyro-scale check's gap
    threshold); ``lever_arm`` (m, body FRD) as given to the filter, or None; ``max_spans`` spans kept per report;
    ``samples_expected`` a stream's samples when known (the gyro-scale check spreads its budget over them)."""

    def __init__(
        self,
        params: EkfParams,
        dt_nominal: float,
        lever_arm: np.ndarray | None = None,
        max_spans: int = 20,
        samples_expected: int | None = None,
    ) -> None:
        self.params, self.lever_arm, self.max_spans = params, lever_arm, max_spans
        self.inconsistent = RunSpans(max_spans)
        self.heading_inconsistent = RunSpans(max_spans)  # the heading's own check (magnetometer / heading input)
        self.n_samples = 0
        self.mag_spans = FlagSpans(params.mag_check_time)  # long magnetometer rejections
        self.new_fields: list[float] = []  # times the magnetometer's reference was replaced (s)
        self.gnss_used = self.mag_used = False  # SOG/COG given; a heading update (mag or external) taken
        self.speed_used = False  # a speed without a course (--speed) given
        self.heading_given = self.mag_given = False  # a heading_true / mag channel in the input
        self.heading_updates = 0
        self.lag = HeadingLagTrack()  # the heading input's lag against the gyro
        self.scale = GyroScaleCheck(
            gap_dt=params.gap_factor * dt_nominal, gravity=params.gravity, samples_expected=samples_expected
        )
        self._scale_tail: tuple[np.ndarray, ...] | None = None  # what the next chunk's scale check starts from
        self._scale_buf: tuple[np.ndarray, ...] | None = None  # the tail and the next chunk, joined
        self.totals: dict[str, Any] = {}  # the filter's cumulative counters, from the last chunk
        self.t_first = self.t_last = np.nan
        self.motion = "handheld"  # the motion model's choice (imutool/attitude/motion.py): set by the caller
        self.turns = FlagSpans(TURN_MIN_S)  # sustained turns of a ship (the heading's rate, smoothed)
        self.turn_rate_max = 0.0  # deg/s, the largest smoothed rate of turn within them
        self._turn_tail: tuple[np.ndarray, np.ndarray] | None = None  # the last TURN_SMOOTH_S of headings
        self.clipped: dict[str, int] = {"accel": 0, "gyro": 0}  # samples at a range limit (formats.saturation)
        self.clip_limits: dict[str, set[float]] = {"accel": set(), "gyro": set()}
        self.clip_first: dict[str, float] = {}  # the time of the first clipped sample (s)

    def _add_turns(self, time: np.ndarray, q: np.ndarray, gyro: np.ndarray, bias: np.ndarray) -> None:
        """The rate of turn (deg/s): the bias-corrected gyro about the world vertical (a magnetic disturbance that
        drags the heading is no turn), averaged over TURN_SMOOTH_S; beyond TURN_RATE it is a turn (kept as spans;
        chunks joined by the last TURN_SMOOTH_S of the integrated angle).

        The angle is integrated at every sample; its average rate is evaluated every TURN_STEP_S and, between two
        evaluations that a sample between could disagree with, at every sample (:func:`_turning`, a bound on the
        rate's change): the spans' ends and the largest rate are those of the rate at every sample
        (tests/test_motion.py), at about half of the cost."""
        t = np.asarray(time, dtype=np.float64)
        om = np.asarray(gyro, dtype=np.float64) - bias
        if not np.isfinite(om).all():  # (nan_to_num itself, on every row, cost more than the rest of this check)
            om = np.nan_to_num(om)
        psi = vertical_rate(q, om)  # rad/s about the world vertical (NED: + clockwise)
        step = np.diff(t, prepend=t[0] if self._turn_tail is None else self._turn_tail[0][-1])
        np.degrees(psi, out=psi)
        psi *= np.clip(step, 0.0, None, out=step)
        np.cumsum(psi, out=psi)
        if self._turn_tail is not None:
            psi += self._turn_tail[1][-1]
            t = np.concatenate([self._turn_tail[0], t])
            psi = np.concatenate([self._turn_tail[1], psi])
        n_tail = 0 if self._turn_tail is None else len(self._turn_tail[0])
        if len(t) < 2:
            return
        turning, rate_max = _turning(t, psi, n_tail)
        if rate_max is not None:
            self.turn_rate_max = max(self.turn_rate_max, rate_max)
        self.turns.add(t[n_tail:], turning)
        keep = t >= t[-1] - TURN_SMOOTH_S
        self._turn_tail = (t[keep], psi[keep])

    def add_clipping(self, time: np.ndarray, accel: Clipping, gyro: Clipping) -> None:
        """One chunk's clipped samples (:func:`formats.saturation.clipped`), accelerometer and gyro."""
        for name, clip in (("accel", accel), ("gyro", gyro)):
            if clip.count:
                self.clipped[name] += clip.count
                self.clip_limits[name].update(round(v, 4) for axis in clip.limits for v in axis)
                self.clip_first.setdefault(name, float(time[np.argmax(clip.mask)]))

    def add(
        self,
        res: Any,
        gyro: np.ndarray,
        *,
        mag_given: bool,
        gnss_used: bool,
        heading_deg: np.ndarray | None = None,
        speed_used: bool = False,
    ) -> None:
        """One chunk of the run, in time order: ``res`` its :class:`~imutool.attitude.AttitudeResult` (with the
        force: ``keep_force``), ``gyro`` (N,3) rad/s as filtered, ``mag_given`` a magnetometer channel in the
        input, ``gnss_used`` SOG/COG used, ``heading_deg`` (N,) the external heading as it came (deg), or None,
        ``speed_used`` a speed without a course (the log's: ``--speed``) used along the bow."""
        flags = res.flags
        if len(res.time):
            if not np.isfinite(self.t_first):
                self.t_first = float(res.time[0])
            self.t_last = float(res.time[-1])
        self.n_samples += len(res.time)
        self.inconsistent.add(res.time, has_flag(flags, SampleFlag.INCONSISTENT))
        self.heading_inconsistent.add(res.time, has_flag(flags, SampleFlag.HEADING_INCONSISTENT))
        if self.params.mag_check_time > 0:
            self.mag_spans.add(res.time, has_flag(flags, SampleFlag.MAG_REJECTED))
        self.new_fields += [float(x) for x in res.time[has_flag(flags, SampleFlag.MAG_NEW_FIELD)]]
        self.mag_used = self.mag_used or bool(np.any(has_flag(flags, SampleFlag.MAG_USED | SampleFlag.HEADING_USED)))
        self.gnss_used = self.gnss_used or gnss_used
        self.speed_used = self.speed_used or speed_used
        self.mag_given = self.mag_given or mag_given
        self.heading_updates += int(np.count_nonzero(has_flag(flags, SampleFlag.HEADING_USED)))
        if heading_deg is not None:
            self.heading_given = True
            self.lag.add(res.time, heading_deg, res.q, gyro, res.bias)
        self._add_scale(res.time, gyro, res.bias, res.force)
        if self.motion == "ship" and not (gnss_used or speed_used) and len(res.time):
            self._add_turns(res.time, res.q, gyro, res.bias)
        for k, v in res.summary.items():  # the state carries cumulative counters (and the tilt check's maximum)
            if isinstance(v, bool):  # a switch (gnss_compensation): on if on in any chunk
                self.totals[k] = bool(self.totals.get(k, False)) or v
            elif isinstance(v, (int, float, np.number)):
                self.totals[k] = v.item() if isinstance(v, np.generic) else v

    def _add_scale(self, *arrays: np.ndarray) -> None:
        """Feed the gyro-scale check (time, gyro, bias, force) so that its pairs of consecutive windows span chunk
        edges as in one run: each chunk goes in behind the last complete window of the one before (and the window
        that followed it, still open), which the check pairs again from there (its windows are cut from the first
        sample of what it is given, each ``window`` s long: :func:`imutool.gyro_check.pair_discrepancy_kernel`)."""
        overlap = 0
        if self._scale_tail is not None:  # behind the tail, in buffers kept from chunk to chunk (no new pages)
            overlap = len(self._scale_tail[0])
            n = overlap + len(arrays[0])
            if self._scale_buf is None or len(self._scale_buf[0]) < n:
                self._scale_buf = tuple(np.empty((n, *np.shape(a)[1:])) for a in arrays)
            joined = []
            for buf, a, b in zip(self._scale_buf, self._scale_tail, arrays, strict=True):
                buf[:overlap] = a
                buf[overlap:n] = b
                joined.append(buf[:n])
            arrays = tuple(joined)
        self.scale.add(*arrays)
        self.scale.seen -= overlap  # the samples carried over were counted with their own chunk
        i = self.scale.last_window_start  # where the kernel's last complete window starts
        self._scale_tail = tuple(np.array(a[i:], dtype=np.float64) for a in arrays)

    def heading_source(self) -> str:
        """Where the heading comes from, as far as the run has gone (final after the last chunk)."""
        return heading_source_report(self.heading_given, self.mag_given, self.heading_updates, self.params)[0][
            "heading_source"
        ]

    def report(self) -> SelfCheckReport:
        """The summary keys, warnings and output metadata of every check over what was added."""
        params, summary, warnings = self.params, {}, []
        duration = self.t_last - self.t_first if np.isfinite(self.t_first) else 0.0
        check, inconsistency = inconsistency_report(
            [tuple(s) for s in self.inconsistent.spans],
            self.inconsistent.n_flagged,
            self.n_samples,
            self.max_spans,
            n_spans=self.inconsistent.count,
        )
        warnings += inconsistency
        hdg = self.heading_inconsistent
        if hdg.n_flagged:
            share = hdg.n_flagged / max(1, self.n_samples)
            summary["heading_inconsistent_share"] = round(share, 6)
            summary["heading_inconsistent_spans_s"] = [[round(a, 3), round(b, 3)] for a, b in hdg.spans]
            warnings.append(
                f"the heading's self-check failed on {100 * share:.1f} % of samples "
                f"({_spans_text([tuple(s) for s in hdg.spans], n_spans=hdg.count)}): the magnetometer's (or the "
                "heading input's) innovations are far larger than its σ allows — a magnetic disturbance or an "
                "uncalibrated magnetometer; the heading is not trustworthy there (column 'heading_inconsistent' = 1)"
                + ("" if params.mag_mode == "full" else ", roll and pitch are not affected (mag_mode heading)")
            )
        source, more = heading_source_report(self.heading_given, self.mag_given, self.heading_updates, params, duration)
        summary.update(source)
        warnings += more
        if self.heading_given:  # how late the feed is against the gyro, measured on the feed as it came
            lag, more = heading_lag_check(self.lag.measure(), params.heading_input_latency)
            summary.update(lag)
            warnings += more
        summary.update(check)
        if params.mag_check_time > 0:
            check, more = heading_check(self.mag_spans, self.max_spans, params=params)
            summary.update(check)
            warnings += more
        check, more = new_field_check(self.new_fields, params, self.max_spans)
        summary.update(check)
        warnings += more
        warnings += tilt_check(self.totals, params)
        warnings += gnss_heading_check(self.gnss_used, self.mag_used)
        turns = [sp for sp in self.turns.spans if sp[1] - sp[0] >= TURN_MIN_S]  # the last one may still be short
        if turns and not (self.gnss_used or self.speed_used):
            summary["turns_without_speed_s"] = [[round(a, 1), round(b, 1)] for a, b in turns[:20]]
            warnings.append(
                f"{len(turns)} turn(s) without any speed input ({_spans_text(turns)}, up to "
                f"{self.turn_rate_max:.1f} °/s): a turn's centripetal acceleration (speed × rate of turn) reads as "
                "roll, 0.1° per m/s of speed per °/s of turn (8 m/s at 3 °/s: 2.4°); give the ship's velocity "
                "(sog/cog or vel_n/vel_e columns, --gnss FILE) or the log's speed (--speed)"
            )
        check, more = self.scale.report()
        summary.update(check)
        warnings += more
        for name, unit in (("accel", "m/s^2"), ("gyro", "rad/s")):
            if self.clipped[name]:
                summary[f"{name}_clipped_samples"] = self.clipped[name]
                warnings.append(
                    clipping_warning(name, self.clip_limits[name], self.clipped[name], unit)
                    + f", the first at {self.clip_first[name]:.2f} s"
                )
        meta = output_metadata(self.lever_arm, summary)
        return SelfCheckReport(summary, warnings, meta)


def _turn_window(t: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each sample index ``at``: the first sample j of the TURN_SMOOTH_S before it, the span t[at] − t[j] (s)
    and whether it is full (≥ 0.9 TURN_SMOOTH_S: the first seconds have no rate yet)."""
    ta = t[at]
    j = np.searchsorted(t, ta - TURN_SMOOTH_S, side="left")
    span = ta - t[j]
    return j, span, span >= 0.9 * TURN_SMOOTH_S


def _turn_rate(t: np.ndarray, psi: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The heading's rate (deg/s) over the TURN_SMOOTH_S before each sample ``at`` (indices into t, s, and psi, the
    integrated angle, deg); 0 where less than 0.9 TURN_SMOOTH_S of samples lie before it."""
    j, span, full = _turn_window(t, at)
    return np.where(full, (psi[at] - psi[j]) / np.where(full, span, 1.0), 0.0)


def _turning(t: np.ndarray, psi: np.ndarray, start: int) -> tuple[np.ndarray, float | None]:
    """Per sample from ``start`` on: is the rate of :func:`_turn_rate` beyond TURN_RATE; and the largest such rate
    (deg/s; None where none is) — the same as the rate evaluated at every sample, at a fraction of the cost.

    The rate is evaluated every TURN_STEP_S, and at every sample between two evaluations a and b wherever a sample
    between them could differ: r = A/S (A the angle turned over the window, S its span ≥ 0.9 TURN_SMOOTH_S), and for
    any k between a and b, |A_k − A_a| ≤ ΔA = (c_b − c_a) + (c_jb − c_ja) with c the cumulative |turned angle| and j
    the window's first sample, |S_k − S_a| ≤ ΔS = (t_b − t_a) + (t_jb − t_ja) and S_k ≥ S_min = t_a − t_jb, so
    |r_k − r_a| ≤ (ΔA + |r_a| ΔS) / S_min = m. An interval is evaluated at every sample where the ends disagree,
    either end's |r| lies within m of TURN_RATE, S_min < 0.9 TURN_SMOOTH_S (a sample between may have no full
    window: the first seconds, a gap), or max(|r_a|, |r_b|) + m reaches the largest evaluated rate; elsewhere every
    sample between is on its ends' side."""
    n = len(t) - start
    if n <= 0:
        return np.zeros(0, dtype=bool), None
    mean_dt = (t[-1] - t[start]) / max(1, n - 1)
    d = max(1, int(TURN_STEP_S / mean_dt)) if mean_dt > 0 else 1
    at = np.arange(start, len(t), d)
    if at[-1] != len(t) - 1:
        at = np.append(at, len(t) - 1)
    j, span, full = _turn_window(t, at)
    rate = np.abs(np.where(full, (psi[at] - psi[j]) / np.where(full, span, 1.0), 0.0))
    hit = rate >= TURN_RATE
    turning = np.repeat(hit[:-1], np.diff(at))  # each evaluation holds to the next, unless refined below
    turning = np.append(turning, hit[-1])
    best = float(rate[hit].max()) if hit.any() else None
    if len(at) > 1:
        c = np.empty(len(psi))  # the cumulative |angle turned| (deg)
        c[0] = 0.0
        np.cumsum(np.abs(np.diff(psi)), out=c[1:])
        d_angle = (c[at[1:]] - c[at[:-1]]) + (c[j[1:]] - c[j[:-1]])
        d_span = (t[at[1:]] - t[at[:-1]]) + (t[j[1:]] - t[j[:-1]])
        s_min = t[at[:-1]] - t[j[1:]]
        partial = s_min < 0.9 * TURN_SMOOTH_S
        top = np.maximum(rate[:-1], rate[1:])
        # the bound, widened by rounding's share (the rates' last bits)
        m = (d_angle + top * d_span) / np.where(partial, 1.0, s_min) * (1.0 + 1e-9) + 1e-12
        near = np.minimum(np.abs(rate[:-1] - TURN_RATE), np.abs(rate[1:] - TURN_RATE)) <= m
        refine = (hit[:-1] != hit[1:]) | near | partial
        if best is not None:
            refine |= top + m >= best  # a larger rate could lie between
        lo, hi = at[:-1][refine] + 1, at[1:][refine]
        counts = hi - lo
        if counts.sum() > 0:
            inside = np.repeat(lo - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())
            r_in = np.abs(_turn_rate(t, psi, inside))
            turning[inside - start] = r_in >= TURN_RATE
            if (r_in >= TURN_RATE).any():
                best = max(best or 0.0, float(r_in[r_in >= TURN_RATE].max()))
    return turning, best


LEVER_ARM_FRAME = "body FRD, sensor relative to the centre of rotation"


def output_metadata(lever_arm: np.ndarray | None, summary: dict[str, Any]) -> dict[str, Any]:
    """The attitude filter's own keys in an output's metadata, in the memory and streamed outputs alike: the lever
    arm (m) and its frame where one was given, where the heading came from (``summary["heading_source"]``, as far as
    known) and the heading input's measured lag (s; where the summary has it, None when it could not be measured)."""
    meta: dict[str, Any] = {}
    if lever_arm is not None:
        meta["lever_arm_m"] = [float(x) for x in np.asarray(lever_arm, float).reshape(3)]
        meta["lever_arm_frame"] = LEVER_ARM_FRAME
    meta["heading_source"] = summary["heading_source"]
    if "heading_input_lag_s" in summary:
        meta["heading_input_lag_s"] = summary["heading_input_lag_s"]
    return meta
