"""Roll, pitch and heading over a whole recording: the one route behind ``imutool filter``, ``imutool batch
filter`` and a Python user.

:func:`run_filter` takes a path (any format imutool reads) or a :class:`formats.Recording` and the estimator's
parameters, runs the quaternion EKF (:mod:`imutool.attitude`), the low-pass baseline (:mod:`imutool.baseline`)
or the compass Kalman filter (:mod:`imutool.compass`), writes the estimate (format by the output's extension)
and returns it with the summary. A large CSV/Parquet input to the causal EKF is streamed in chunks (row groups
for Parquet) in bounded memory (:func:`stream_ekf`). Angles in the outputs are degrees; SI inside.

    from imutool.filtering import run_filter
    res = run_filter("roll.csv", "est.csv", smooth=True)      # or run_filter(rec) → res.recording
    res.summary["smoother_gain"]                              # causal vs smoothed RMSE when the input has truth
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.csv import in_background
from formats.errors import ImutoolError
from formats.parquet import parquet_info
from formats.units import factor_to_si
from imutool.attitude import (
    EkfParams,
    EkfStepper,
    SelfCheck,
    ekf_recording,
    mag_interval,
    nominal_dt,
    output_metadata,
    result_recording,
)
from imutool.attitude.aided import aided_result, velocity_is_fixes
from imutool.attitude.lever_estimate import LeverArmEstimate
from imutool.attitude.motion import ANALYSIS_MAX_S, MotionChoice, choose_motion, params_for_motion
from imutool.attitude.recording import (
    LOG_SPEED,
    add_aided_channels,
    clipped_nan,
    drop_clipped,
    flag_clipped,
    gnss_inputs,
    heading_channel,
    ship_lever_arm,
)
from imutool.baseline import lpf_attitude
from imutool.compass import CompassParams, compass_recording
from imutool.convert import STREAMABLE, chunk_writer, expected_rows
from imutool.filter_warm import warm_filter_kernels
from imutool.loading import LOAD_OPTIONS, ChunkChecks, load_recording, mapping_options, one_clock, read_input
from imutool.metrics import attitude_rmse
from imutool.progress import Progress, report

# one import stays inside its function: calibration (its fitting code loads scipy.optimize, about 1 s) in
# run_filter, for the compass's deviation card only

METHODS = ("ekf", "lpf", "accel", "compass")


@dataclass
class FilterResult:
    """What :func:`run_filter` produced.

    recording: the estimate (None when streamed: the rows went straight to the output file); summary: rows,
    method, the estimator's counters and self-check, ``warnings`` (also in the output's metadata), smoother gain;
    validation: what loading the input did (rows read/kept/dropped, samples bridged, warnings; for a stream, over
    all its chunks; empty for a Recording).
    """

    recording: Recording | None
    summary: dict[str, Any]
    validation: dict[str, Any] = field(default_factory=dict)

    @property
    def warnings(self) -> list[str]:
        return list(self.summary.get("warnings") or [])


# rows per chunk of a streamed run: a quarter of a million keeps the reader, the filter and the writer overlapped
# (the first chunk's parse and the last one's format are what no thread can hide) and the memory at ~450 MB for any
# length; 1 M rows (before 2026-12-06) held ~730 MB on a 2 M-row file for the same bytes out and no less time
STREAM_CHUNK_ROWS = 250_000


def streams(
    source: str | os.PathLike | Recording,
    output: str | os.PathLike | None = None,
    *,
    method: str = "ekf",
    smooth: bool = False,
    gnss: str | os.PathLike | None = None,
    stream_mb: float = 300.0,
    heading: str | os.PathLike | None = None,
) -> bool:
    """Whether :func:`run_filter` streams: causal EKF, no GNSS or heading file (those are attached in memory), an
    output file to stream into, and a CSV input larger than ``stream_mb`` MB, or a Parquet input whose data take
    more than that in memory (rows × columns × 8 bytes from its footer: Parquet compresses, a 0.3 GB file can hold
    2 GB of float64)."""
    if (
        isinstance(source, Recording)
        or output is None
        or method != "ekf"
        or smooth
        or gnss is not None
        or heading is not None
    ):
        return False
    kind = formats.kind_of(source)
    if kind not in STREAMABLE:
        return False
    size = os.path.getsize(source)
    if kind == "parquet":
        try:
            info = parquet_info(source)
            size = max(size, int(info["rows"]) * len(info["columns"]) * 8)
        except ImutoolError:
            pass  # unreadable: decided by the file size; reading it will say what is wrong
    return size > stream_mb * 1e6


IMU_CLOCK = ("gyro", "accel", "mag")  # the stream whose samples a many-clock input is filtered on (first present)


def run_filter(
    source: str | os.PathLike | Recording,
    output: str | os.PathLike | None = None,
    *,
    method: str = "ekf",
    params: Any = None,
    smooth: bool = False,
    lever_arm: Any = None,
    antenna_arm: Any = None,
    gnss: str | os.PathLike | None = None,
    use_gnss: bool = True,
    speed: float | str | None = None,
    heading: str | os.PathLike | None = None,
    cutoff_hz: float = 0.5,
    order: int = 2,
    compass: Any = None,
    params_file: str | None = None,
    chunk_rows: int = STREAM_CHUNK_ROWS,
    stream_mb: float = 300.0,
    strict: bool = False,
    progress: Progress | None = None,
    on_input: Callable[[str, dict[str, Any]], None] | None = None,
    **load_options: Any,
) -> FilterResult:
    """Estimate roll, pitch, heading (deg) from ``source``; write them to ``output`` when given.

    method: ``ekf`` (quaternion EKF with gyro-bias states; ``params`` an :class:`imutool.attitude.EkfParams`,
    ``smooth`` adds the zero-lag smoother (:func:`imutool.attitude.zero_lag_smooth`), ``lever_arm`` the sensor
    position from the centre of rotation, m, body FRD, ``antenna_arm`` the GNSS antenna's (default: the velocity
    is the centre's), ``gnss`` an NMEA/CSV file with sog (m/s)/cog (deg),
    ``use_gnss=False`` ignores sog/cog, ``speed`` the ship's speed through the water from its log (m/s, or a
    string with a unit: "15 kn"; used along the bow for a turn's centripetal acceleration where the input has no
    GNSS velocity), ``heading`` an NMEA (HDT/THS) or CSV file with heading_true (deg), a
    gyrocompass heading used instead of the magnetometer), ``lpf`` (Butterworth low-passed accelerometer tilt +
    magnetic heading, ``cutoff_hz``, ``order``), ``accel`` (unfiltered accelerometer tilt) or ``compass``
    (heading KF; ``compass`` an :class:`imutool.compass.CompassParams`; the deviation card of
    ``calibration_file`` is applied).

    A path is loaded by :func:`imutool.loading.load_recording` with ``load_options`` (columns, profile, topic,
    stamp, duplicates, backwards, mounting, calibration_file) and ``strict``; ``on_input(path, report)`` is called
    right after (the CLI prints the input warnings there). A large CSV/Parquet input to the causal EKF streams
    (see :func:`streams`; ``chunk_rows`` rows per chunk). With ``smooth`` and truth (``ref_q``/``ref_roll``) in
    the input the summary gets ``smoother_gain``: causal vs smoothed RMSE (deg). ``params_file`` is recorded in
    the output's metadata. ``progress(done, total)`` is called in samples.
    """
    unknown = set(load_options) - set(LOAD_OPTIONS)
    if unknown:
        raise TypeError(f"run_filter() got unexpected keyword argument(s) {', '.join(sorted(unknown))}")
    if method not in METHODS:
        raise ImutoolError(f"filter method {method!r}: expected one of {', '.join(METHODS)}")
    lever = _lever_arm(lever_arm)
    antenna = _lever_arm(antenna_arm, "antenna arm")
    log_speed = parse_speed(speed)
    if log_speed is not None and method != "ekf":
        raise ImutoolError(f"a log speed applies to the EKF (method ekf), not to method {method!r}")
    if method == "ekf":
        params = params if params is not None else EkfParams()
        if isinstance(source, Recording) or os.path.isfile(source):  # not for an input that will be refused
            csv_out = output is not None and os.fspath(output).lower().endswith(".csv")
            warm_filter_kernels(
                smooth, csv_out, heading is not None
            )  # a cold cache: later kernels compile beside (formats.jit.warm)
    if (
        not isinstance(source, Recording)
        and not load_options.get("with_files")  # merged in memory
        and streams(source, output, method=method, smooth=smooth, gnss=gnss, stream_mb=stream_mb, heading=heading)
    ):
        summary = stream_ekf(
            source,
            output,
            params,
            chunk_rows=chunk_rows,  # type: ignore[arg-type]
            use_gnss=use_gnss,
            lever_arm=lever,
            antenna_arm=antenna,
            strict=strict,
            progress=progress,
            log_speed=log_speed,
            **{k: load_options.get(k) for k in STREAM_OPTIONS},
        )
        validation = summary.pop("validation")
        if on_input is not None:
            on_input(os.fspath(source), validation)
        return FilterResult(None, summary, validation)
    validation: dict[str, Any] = {}
    if isinstance(source, Recording):
        rec = source
        name = str(rec.meta.get("source", "<recording>"))
    else:
        name = os.fspath(source)
        rec, validation = load_recording(name, strict=strict, **load_options)
        if on_input is not None and len(rec):
            on_input(name, validation)
    rec = one_clock(rec, IMU_CLOCK, [validation])  # many clocks: the IMU's own samples, the others held
    summary: dict[str, Any] = {"input": name, "output": None if output is None else os.fspath(output), "rows": len(rec)}
    if method == "ekf":
        if gnss is not None and use_gnss:
            rec = attach_gnss(rec, gnss)
        if heading is not None:
            rec = attach_heading(rec, heading)
        rec = with_log_speed(rec, log_speed)
        out, s = ekf_recording(
            rec, params, smooth=smooth, use_gnss=use_gnss, lever_arm=lever, progress=progress, antenna_arm=antenna
        )
        if smooth:
            gain = smoother_gain(rec, out, params, use_gnss=use_gnss, lever_arm=lever, antenna_arm=antenna)
            if gain is not None:
                s["smoother_gain"] = gain
        if params_file:
            out.meta["filter_params_file"] = params_file
    elif method in ("lpf", "accel"):
        out, s = lpf_attitude(rec, cutoff_hz if method == "lpf" else None, order)
        report(progress, len(rec), len(rec))
    else:
        dev = None
        if load_options.get("calibration_file"):
            from calibration import load_calibration  # scipy.optimize: only for a deviation card (see the top)

            dev = load_calibration(load_options["calibration_file"]).deviation
        out, s = compass_recording(rec, compass if compass is not None else CompassParams(), dev)
        report(progress, len(rec), len(rec))
    summary.update(s)
    if log_speed is not None and method == "ekf" and gnss_inputs(rec, use_gnss)[2] is None:
        summary["log_speed_mps"] = round(log_speed, 3)  # (used: no GNSS velocity in the input)
    if validation.get("rows_with_nan"):
        summary["input_rows_with_nan"] = validation["rows_with_nan"]
    if output is not None:
        formats.write(out, output)
    return FilterResult(out, summary, validation)


MAX_SPEED = 50.0  # m/s (97 kn): faster is not a ship's log


def parse_speed(speed: float | str | None) -> float | None:
    """A ship's speed through the water (m/s) from a number (m/s) or a string with a unit ("15 kn", "7.7 m/s");
    None stays None. Refused (ImutoolError): not a number, an unknown unit, negative or above MAX_SPEED."""
    if speed is None:
        return None
    text = str(speed).strip()
    num = text.rstrip("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ/ ")
    unit = text[len(num) :].strip() or "m/s"
    try:
        value = float(num) * factor_to_si(unit, "velocity")
    except (ValueError, KeyError, ImutoolError):
        raise ImutoolError(f"speed {speed!r}: expected a number in m/s or with a unit (15 kn, 7.7 m/s)") from None
    if not 0.0 <= value <= MAX_SPEED:
        raise ImutoolError(f"speed {speed!r}: expected 0 to {MAX_SPEED:g} m/s (a ship's log)")
    return value


def with_log_speed(rec: Recording, speed_mps: float | None) -> Recording:
    """``rec`` with a constant ``log_speed`` channel (m/s) when a speed is given and it has none (the filter
    takes it along the bow where there is no GNSS velocity)."""
    if speed_mps is None or LOG_SPEED in rec.channels:
        return rec
    out = Recording(rec.time, dict(rec.channels), dict(rec.units), dict(rec.meta), dict(rec.columns))  # shallow
    out.add(LOG_SPEED, np.full(len(rec), speed_mps), "m/s")
    return out


def _lever_arm(lever_arm: Any, what: str = "lever arm") -> np.ndarray | None:
    if lever_arm is None:
        return None
    v = np.asarray(lever_arm, dtype=float).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ImutoolError(f"{what} {lever_arm!r}: expected three finite numbers (m)")
    return v


def smoother_gain(
    rec: Recording,
    smoothed: Recording,
    params: Any,
    *,
    use_gnss: bool = True,
    lever_arm: np.ndarray | None = None,
    antenna_arm: np.ndarray | None = None,
) -> dict[str, Any] | None:
    """Causal vs smoothed attitude RMSE (deg) against the truth in ``rec`` (``ref_q`` or ``ref_roll``...); None
    without truth. Runs the causal EKF once more."""
    if "ref_q" not in rec.channels and "ref_roll" not in rec.channels:
        return None
    causal, _ = ekf_recording(rec, params, use_gnss=use_gnss, lever_arm=lever_arm, antenna_arm=antenna_arm)
    return {"causal_rmse_deg": attitude_rmse(causal, rec), "smoothed_rmse_deg": attitude_rmse(smoothed, rec)}


def _interp_angle_deg(t: np.ndarray, tf: np.ndarray, deg: np.ndarray) -> np.ndarray:
    """Angles (deg, finite, at increasing times ``tf`` s) interpolated onto ``t`` (s) the short way round:
    unwrapped, linear, back in [0, 360); NaN outside [tf[0], tf[-1]]."""
    return np.degrees(np.interp(t, tf, np.unwrap(np.radians(deg)), left=np.nan, right=np.nan)) % 360


HEADING_MAX_GAP_S = 5.0  # a gyrocompass feed is interpolated between fixes at most this far apart (s)


def _fixes_in_time_order(src: Recording, path: str, what: str, *values: np.ndarray) -> tuple[np.ndarray, ...]:
    """The rows of ``values`` that are all finite, sorted by time; of equal times the last one read. Refuses a file
    without a clock (NMEA without line time stamps or a sentence with a time of day: its sentence index would be
    taken for seconds) and
    one with fewer than two such fixes. Returns (times s, *values)."""
    if src.meta.get("time_source") == "index":
        raise ImutoolError(
            f"the {what} file has no clock (no line time stamps, no sentence with a time of day): its "
            "fixes cannot be placed on the IMU's time",
            path=path,
        )
    ok = np.isfinite(src.time)
    for v in values:
        ok &= np.isfinite(v)
    tf = src.time[ok]
    order = np.argsort(tf, kind="stable")
    tf = tf[order]
    last = np.append(tf[1:] != tf[:-1], True)  # of equal times, the last one read
    if last.sum() < 2:
        raise ImutoolError(f"fewer than two valid {what} fixes at distinct times", path=path)
    return (tf[last],) + tuple(np.asarray(v)[ok][order][last] for v in values)


def _blank_long_gaps(t: np.ndarray, tf: np.ndarray, val: np.ndarray, max_gap_s: float) -> np.ndarray:
    """``val`` (interpolated onto ``t`` from fixes at ``tf``) with NaN strictly between two fixes more than
    ``max_gap_s`` apart: a feed that stopped is not drawn as a straight line (a fix's own time is kept)."""
    j = np.clip(np.searchsorted(tf, t), 1, len(tf) - 1)
    inside = (t > tf[j - 1]) & (t < tf[j])
    return np.where(inside & ((tf[j] - tf[j - 1]) > max_gap_s), np.nan, val)


def attach_gnss(rec: Recording, path: str | os.PathLike, max_gap_s: float = np.inf) -> Recording:
    """A copy of ``rec`` with ``sog`` (m/s) and ``cog`` (deg) interpolated from an NMEA (RMC/VTG) or CSV file:
    fixes sorted by time (of equal times the last read), cog unwrapped, linear between fixes, NaN outside the
    file's time span and strictly between fixes more than ``max_gap_s`` (s) apart. Outages are bridged by default:
    the compensation's turn rate is the gyro's and a steady turn's course is linear in time, so a bridged course
    is close, while none leaves the whole centripetal acceleration in the tilt (ship-at-sea, an 8 s outage in the
    turn: roll RMS 0.09° bridged, 0.94° blanked). A file without a clock is refused."""
    path = os.fspath(path)
    g = formats.read(path)
    if "sog" not in g.channels or "cog" not in g.channels:
        raise ImutoolError(
            f"no sog/cog channels (have {', '.join(g.channels)}); need RMC/VTG or CSV columns sog (m/s), cog (deg)",
            path=path,
        )
    # the empty fixes are dropped before the course is unwrapped: one empty course must not void those after it
    tf, sog, cog = _fixes_in_time_order(
        g, path, "sog/cog", g.in_unit("sog", "m/s"), np.asarray(g.in_unit("cog", "deg"), float)
    )
    out = rec.copy()
    out.add(
        "sog", _blank_long_gaps(rec.time, tf, np.interp(rec.time, tf, sog, left=np.nan, right=np.nan), max_gap_s), "m/s"
    )
    out.add("cog", _blank_long_gaps(rec.time, tf, _interp_angle_deg(rec.time, tf, cog), max_gap_s), "deg")
    return out


def attach_heading(rec: Recording, path: str | os.PathLike, max_gap_s: float = HEADING_MAX_GAP_S) -> Recording:
    """A copy of ``rec`` with ``heading_true`` (deg, [0, 360)) interpolated from an NMEA (HDT/THS) or CSV file
    with a heading_true column: fixes sorted by time (of equal times the last read), unwrapped, linear between
    fixes, NaN outside the file's time span and strictly between fixes more than ``max_gap_s`` apart (a
    gyrocompass that stopped is not drawn as a straight line). THS fixes in mode S, M or V are dropped; a file
    without a clock is refused (:func:`_fixes_in_time_order`). The filter then takes its heading from it
    (at most once per ``heading_input_interval``) and not from the magnetometer."""
    path = os.fspath(path)
    h = formats.read(path)
    # NMEA's true heading (HDT, THS, HDG with deviation and variation) is read as channel "heading"; a CSV's
    # "heading" may be an estimate (imutool's own output has one), so a CSV must say heading_true
    ch = "heading_true" if "heading_true" in h.channels else "heading" if formats.kind_of(path) == "nmea" else None
    if ch is None or ch not in h.channels:
        raise ImutoolError(
            f"no true heading (have {', '.join(h.channels)}); need HDT/THS sentences or a CSV "
            "column heading_true (deg)",
            path=path,
        )
    hd = np.asarray(h.in_unit(ch, "deg"), float)
    if "ths_mode" in h.channels:  # THS: only autonomous (A) and estimated (E) headings are a ship's heading
        mode = np.asarray(h["ths_mode"], float)
        hd = np.where(np.isfinite(mode) & ~np.isin(mode, [ord("A"), ord("E")]), np.nan, hd)
    tf, hd = _fixes_in_time_order(h, path, "heading", hd)
    out = rec.copy()
    out.add("heading_true", _blank_long_gaps(rec.time, tf, _interp_angle_deg(rec.time, tf, hd), max_gap_s), "deg")
    return out


STREAM_OPTIONS = ("columns", "profile", "mounting", "calibration_file", "input_rate_hz", "time_column", "header_rows")
"""The load options a streamed run takes (the others have their defaults there: no --with, no sorting)."""


def _motion_lookahead(
    chunks: Iterable[Recording], params: Any
) -> tuple[Iterator[Recording], MotionChoice, list[Recording]]:
    """The first chunks held back until they span ``ANALYSIS_MAX_S`` (or the file ends), the motion chosen on their
    gyro (rad/s, rows whose time increases) — the same first span an in-memory run judges — then every chunk in
    order. One chunk of 1 M rows spans more than that at 200 Hz: usually nothing more is held."""
    it = iter(chunks)
    held: list[Recording] = []
    times: list[np.ndarray] = []
    rates: list[np.ndarray] = []
    for chunk in it:
        held.append(chunk)
        if len(chunk) and "gyro" in chunk.channels:
            times.append(np.asarray(chunk.time, dtype=np.float64))
            rates.append(np.asarray(chunk.in_unit("gyro", "rad/s"), dtype=np.float64).reshape(len(chunk), -1))
        if times and times[-1][-1] - times[0][0] >= ANALYSIS_MAX_S:
            break
    t = np.concatenate(times) if times else np.empty(0)
    g = np.concatenate(rates) if rates else np.empty((0, 3))
    if len(t):
        rising = t >= np.maximum.accumulate(t)
        rising[1:] &= np.diff(t) > 0
        t, g = t[rising], g[rising]
    choice = choose_motion(params, t, g) if g.shape[1:] == (3,) else choose_motion(params, t[:0], np.empty((0, 3)))
    return _held_then(held, it), choice, list(held)


def _held_then(held: list[Recording], rest: Iterator[Recording]) -> Iterator[Recording]:
    """The held chunks, each let go once given, then the rest (``itertools.chain`` would keep them all)."""
    while held:
        yield held.pop(0)
    yield from rest


def _stream_lever_arm(
    held: list[Recording],
    params: EkfParams,
    motion: MotionChoice,
    run_params: EkfParams,
    lever_arm: np.ndarray | None,
    use_gnss: bool,
    antenna_arm: np.ndarray | None,
) -> tuple[np.ndarray | None, LeverArmEstimate | None]:
    """:func:`imutool.attitude.recording.ship_lever_arm` on a stream's held-back first chunks (already checked):
    the same rows and inputs an in-memory run estimates from."""
    if lever_arm is not None or motion.kind != "ship" or not params.lever_arm_estimate or not held:
        return lever_arm, None
    accel, gyro, mags, sogs, cogs, vels, headings, times = [], [], [], [], [], [], [], []
    t0 = next((c.time[0] for c in held if len(c)), 0.0)
    for chunk in held:  # only the rows of the span (analysis_span: the first ANALYSIS_MAX_S; times increase)
        n = int(np.searchsorted(chunk.time - t0, ANALYSIS_MAX_S, side="right"))
        if n == 0:
            break
        times.append(chunk.time[:n])
        gyro.append(chunk.in_unit("gyro", "rad/s")[:n])
        accel.append(clipped_nan(chunk["accel"])[:n])  # the chunk's clipping, as the filter's pass finds it
        mag = chunk.channels.get("mag")
        mags.append(None if mag is None else mag[:n])
        sog, cog, vel = gnss_inputs(chunk, use_gnss)
        sogs.append(None if sog is None else sog[:n]), cogs.append(None if cog is None else cog[:n])
        heading = heading_channel(chunk)
        vels.append(None if vel is None else vel[:n]), headings.append(None if heading is None else heading[:n])

    def joined(parts: list) -> np.ndarray | None:
        return None if any(p is None for p in parts) else np.concatenate([np.asarray(p, float) for p in parts])

    time = np.concatenate(times)
    return ship_lever_arm(
        params, motion, None, time, joined(gyro), joined(accel), joined(mags), run_params,
        joined(sogs), joined(cogs), joined(vels), joined(headings), antenna_arm,
    )  # fmt: skip


class _Ahead:
    """An iterator that can tell whether another item follows (:meth:`at_end` takes it in advance)."""

    _NONE = object()

    def __init__(self, items: Iterable[Any]) -> None:
        self._it = iter(items)
        self._next: Any = self._NONE

    def __iter__(self) -> _Ahead:
        return self

    def __next__(self) -> Any:
        if self._next is not self._NONE:
            item, self._next = self._next, self._NONE
            return item
        return next(self._it)

    def at_end(self) -> bool:
        """True when no item follows (waits for the next one)."""
        if self._next is self._NONE:
            try:
                self._next = next(self._it)
            except StopIteration:
                return True
        return False


def stream_ekf(
    path: str | os.PathLike,
    output: str | os.PathLike,
    params: Any,
    *,
    chunk_rows: int = STREAM_CHUNK_ROWS,
    use_gnss: bool = True,
    lever_arm: np.ndarray | None = None,
    antenna_arm: np.ndarray | None = None,
    columns: str | None = None,
    profile: str | None = None,
    mounting: str | None = None,
    calibration_file: str | None = None,
    strict: bool = False,
    progress: Progress | None = None,
    input_rate_hz: float | None = None,
    time_column: str | None = None,
    header_rows: int | None = None,
    log_speed: float | None = None,
) -> dict[str, Any]:
    """Bounded-memory causal EKF over a large CSV/Parquet file: chunks streamed (Parquet by row groups), the
    filter state carried from chunk to chunk, rows appended to a .csv or .parquet output; returns the summary.

    Memory is O(chunk_rows), not O(file). Rows whose time is not after the previous row's are dropped (counted
    in ``dropped_non_increasing_rows``); streaming cannot sort. Each chunk gets the input checks of an
    in-memory run (:class:`imutool.loading.ChunkChecks`: absurd samples bridged, calibration, mounting,
    plausibility on the stretches an in-memory load samples, the > 1 % dropped-rows warning): their report,
    with the input's warnings, is the summary's ``validation``; the self-check's warnings are its ``warnings``.
    Both sets are written, at the end, into the output's metadata (``warnings``, ``validation``).
    """
    path, output = os.fspath(path), os.fspath(output)
    if params is None:
        params = EkfParams()
    total = expected_rows(path)
    checks = ChunkChecks(path, mounting=mounting, calibration_file=calibration_file, strict=strict, rows_expected=total)
    rows_read = duplicates = 0
    stepper: EkfStepper | None = None  # the EKF with its state carried from chunk to chunk
    aided_state = None  # the aided pass's state carried from chunk to chunk
    dt_nom = dt_mag = None  # the IMU's and the magnetometer's nominal intervals (s), from the first chunk with them
    t_last = -np.inf
    summary: dict[str, Any] = {
        "input": path,
        "output": output,
        "rows": 0,
        "method": "ekf (streamed)",
        "dropped_non_increasing_rows": 0,
    }
    # three stages overlap: the next chunk is parsed and the previous one formatted/written in background threads
    # while the EKF runs on this one (the compiled kernels release the GIL)
    kind = formats.kind_of(path)
    time_opts = {"rate_hz": input_rate_hz, "time_column": time_column, "header_rows": header_rows}
    if kind != "csv" and any(v is not None for v in time_opts.values()):
        read_input(path, **time_opts)  # the one-line refusal of a CSV-only option
    opts = {**mapping_options(path, columns, profile), **({"prefetch": True, **time_opts} if kind == "csv" else {})}
    self_checks: SelfCheck | None = None  # the filter's self-checks, fed chunk by chunk (as in memory: one chunk)
    # the output (CSV or Parquet) is converted and written by a background thread, and a Parquet input is read
    # one chunk ahead by another (the CSV reader prefetches by itself): one chunk more in memory for each
    writer = chunk_writer(output, background=True)
    chunks = formats.iter_chunks(path, chunk_rows=chunk_rows, **opts)
    if kind == "parquet":
        chunks = in_background(chunks)
    final: tuple[dict[str, Any], list[str]] | None = None  # (validation, the self-check's warnings) once known

    def finish(w: Any) -> tuple[dict[str, Any], list[str]]:
        """The run's validation and self-check, and the output's final metadata handed to the writer."""
        validation, input_warnings = checks.finish(
            rows_read, summary["rows"], duplicates=duplicates, skipped=int(summary.get("skipped_rows", 0) or 0)
        )
        validation["warnings"] = input_warnings
        if summary["rows"] == 0 or self_checks is None:
            raise ImutoolError("no data rows", path=path)
        checked = self_checks.report()
        summary.update(self_checks.totals)  # the filter's cumulative counters after the last chunk, then the checks
        summary.update(checked.summary)  # (the order of an in-memory run's summary)
        warnings = checked.warnings
        if "note" in summary.get("aided", {}):  # the gyro's bias instability widened (as an in-memory run says)
            warnings = [*warnings, summary["aided"]["note"]]
        if lever_est is not None:
            summary["lever_arm_estimate"] = lever_est.summary()
            warnings = [m for m in (lever_est.message(),) if m] + warnings
        everything = checks.meta_warnings(input_warnings, warnings)
        w.set_final_meta(
            {
                "validation": {k: v for k, v in validation.items() if k != "warnings"},
                # the keys known only at the end (the lever arm's went out with the first chunk)
                **{k: v for k, v in checked.metadata.items() if not k.startswith("lever_arm")},
                **({"warnings": everything} if everything else {}),
            }
        )
        return validation, warnings

    def prepared(chunks: Iterable[Recording]) -> Iterator[Recording]:
        """The chunks as the filter takes them: rows whose time increases, the input checks applied."""
        nonlocal rows_read, duplicates, t_last
        for chunk in chunks:
            rows_read += len(chunk)
            before = np.maximum.accumulate(np.concatenate([[t_last], chunk.time[:-1]]))
            keep = chunk.time > before
            if not keep.all():
                summary["dropped_non_increasing_rows"] += int((~keep).sum())
                duplicates += int((chunk.time == before).sum())
                chunk = chunk.select(keep)
            if chunk.meta.get("skipped_rows"):  # running total of malformed rows skipped by the reader
                summary["skipped_rows"] = chunk.meta["skipped_rows"]
                summary["skipped_rows_first"] = chunk.meta.get("skipped_rows_first")
            if len(chunk) == 0:
                continue
            t_last = float(chunk.time[-1])
            if chunk.multi_clock:  # many clocks: the IMU's own samples (others held within the chunk)
                chunk = one_clock(chunk, IMU_CLOCK)
                summary.setdefault("clock", chunk.meta.get("clock"))
            chunk = with_log_speed(checks.prepare(chunk), log_speed)
            for ch in ("gyro", "accel"):
                if ch not in chunk.channels:
                    raise ImutoolError(f"the EKF needs channel {ch!r}", path=path)
            yield chunk

    with writer as w:  # (a refusal from here on removes the output's temporary file)
        # the motion, and on a ship without a lever arm its estimate, of the same first span as in memory
        chunks, motion, held = _motion_lookahead(prepared(chunks), params)
        run_params = params_for_motion(params, motion)
        lever_arm, lever_est = _stream_lever_arm(held, params, motion, run_params, lever_arm, use_gnss, antenna_arm)
        held = []  # the estimate's copy of the list let go: each held chunk is freed once filtered
        chunks = _Ahead(chunks)
        for chunk in chunks:
            if dt_nom is None:
                dt_nom = nominal_dt(chunk.time)
                summary["motion"] = motion.summary()
                self_checks = SelfCheck(run_params, dt_nom, lever_arm, samples_expected=total)
                self_checks.motion = motion.kind
            sog, cog, vel = gnss_inputs(chunk, use_gnss)
            if "heading_true" in chunk.channels and getattr(params, "heading_input_latency", 0.0) > 0:
                raise ImutoolError(
                    "heading_input_latency reads the heading_true column later, past a chunk's end: "
                    "a streamed run cannot apply it (run in memory: --stream-mb above the file's size, "
                    "or give the heading as a file with --heading)",
                    path=path,
                )
            heading = heading_channel(chunk)  # deg, or None
            if dt_mag is None:
                dt_mag = mag_interval(chunk.time, chunk.channels.get("mag"))
            assert self_checks is not None  # made with the first chunk's nominal step
            accel, clipped_rows = drop_clipped(chunk["gyro"], chunk["accel"], self_checks, chunk.time)
            if stepper is None:  # the filter's set-up, once: the intervals of the first chunk
                stepper = EkfStepper(
                    run_params, dt_nominal=dt_nom, dt_mag=dt_mag, lever_arm=lever_arm, antenna_arm=antenna_arm,
                    keep_force=True,
                )  # fmt: skip
            elif stepper.dt_mag is None:
                stepper.dt_mag = dt_mag
            res = stepper.step(
                chunk.time, chunk["gyro"], accel, chunk.channels.get("mag"), sog, cog, heading_deg=heading,
                velocity_ne=vel,
            )  # fmt: skip
            flag_clipped(res, clipped_rows)
            self_checks.add(
                res,
                chunk["gyro"],
                mag_given="mag" in chunk.channels,
                gnss_used=vel is not None,
                heading_deg=heading,
                speed_used=sog is not None and vel is None,
            )
            aided = None
            aid = vel is not None and params.aided and lever_est is None  # as ekf_recording
            if aid and res.summary.get("velocity_aiding") and velocity_is_fixes(vel):
                res, aided, aided_state = aided_result(
                    chunk.time, chunk["gyro"], accel, vel, res, run_params, lever_arm, antenna_arm, dt_nom, aided_state
                )
                used = int(summary.get("aided", {}).get("rows_used", 0)) + int(aided.summary.get("rows_used", 0))
                summary["aided"] = {**aided.summary, "rows_used": used}  # the counters of the run so far
            est = result_recording(chunk, res, params)
            if aided is not None:
                add_aided_channels(est, aided)
            est.meta["motion"] = summary["motion"]
            # the metadata as far as known (the heading source is final at the end: set_final_meta below)
            est.meta.update(output_metadata(lever_arm, {"heading_source": self_checks.heading_source()}))
            if lever_est is not None:
                est.meta["lever_arm_estimate"] = lever_est.summary()
            summary["rows"] += len(chunk)
            # the input and the filter's arrays of this chunk let go before looking ahead (the next chunk taken
            # lets the reader parse one more): what is held is what was held before
            chunk = accel = res = sog = cog = vel = heading = clipped_rows = aided = None  # type: ignore[assignment]
            if chunks.at_end():  # the last chunk: the final metadata first, so its rows go straight behind them
                final = finish(w)
            w.write(est)
            report(progress, summary["rows"], total)
        if final is None:  # the stream ended in rows that were all dropped (or none at all)
            final = finish(w)
        validation, warnings = final
    if log_speed is not None and self_checks is not None and self_checks.speed_used:
        summary["log_speed_mps"] = round(log_speed, 3)
    summary["samples"] = summary["rows"]
    summary["validation"] = validation
    if warnings:
        summary["warnings"] = warnings
    if lever_arm is not None:
        summary["lever_arm_m"] = [float(x) for x in lever_arm]
    return summary
