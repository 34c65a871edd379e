"""Estimate vs truth: the one route behind ``imutool evaluate``, ``imutool batch evaluate`` and a Python user.

:func:`evaluate` compares an estimate recording with a reference (``ref_*`` truth columns; the estimate itself
by default): per angle RMSE, max, p95, MAE, lag and SNR (deg; heading errors wrapped to ±180°), quaternion
errors with the BROAD metrics (total, heading, inclination), heave (positive up, with the three "5 cm or 5 %"
readings) or position; optionally an error plot. A reference with only a quaternion gets its roll, pitch and
heading derived from it; a reference file without ``ref_*`` columns (another instrument's output, a
motion-capture log) is read as the reference as it is; ``align_heading`` removes a constant heading offset of
the reference frame (given, or estimated by the circular mean of the differences). :func:`run_evaluate` is the
route (a :class:`imutool.routes.RouteResult`). Times are shown as UTC clock time where the estimate has a date
(:mod:`imutool.clock`). Nothing is printed.
"""

from __future__ import annotations

import importlib
import os
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.atomic import atomic_path
from formats.errors import ImutoolError
from formats.frames import angle_diff_deg, quat_multiply, quat_to_euler
from formats.recording import require_samples
from imutool.clock import Clock
from imutool.loading import FLAGS, how_loaded, one_clock, reference_text, split_reference_options
from imutool.refframe import frame_warning, parse_ref_frame, reference_to_ned, vertical_disagreement
from imutool.routes import LOAD_OPTIONS, OnInput, RouteResult, load_input, load_reference

CHANNELS = ("angles", "quaternion", "heave", "position")
ANGLES = ("roll", "pitch", "heading")
MIN_REFERENCE_ROWS = 10
"""Reference rows within the estimate's span below which no comparison is made (as a report's window needs ten
samples): statistics of fewer describe the interpolation between them, not the estimate."""

EVALUATE_DEFAULTS: dict[str, Any] = {
    "channel": None,
    "max_lag_s": 0.0,
    "plot": None,
    "align_heading": None,
    "ref_frame": None,
    "ref_mounting": None,
    "start": None,
    "end": None,
}
"""What is compared and how, unless said: every channel both have, no lag search (s), no plot, no heading offset,
the reference taken as body → NED, the whole estimate. The defaults of :func:`evaluate` and :func:`run_evaluate`
(and of the ``imutool evaluate`` options)."""


def load_for_evaluation(path: str | os.PathLike) -> Recording:
    """Read ``path`` and put it in time order (duplicates dropped, backwards time sorted)."""
    path = os.fspath(path)
    rec = formats.read(path)
    rec, _ = rec.validated(duplicates="drop", backwards="sort", source=path)
    return rec


def evaluate(
    estimate: str | os.PathLike | Recording,
    reference: str | os.PathLike | Recording | None = None,
    *,
    channel: str | None = EVALUATE_DEFAULTS["channel"],
    max_lag_s: float = EVALUATE_DEFAULTS["max_lag_s"],
    plot: str | os.PathLike | None = EVALUATE_DEFAULTS["plot"],
    align_heading: float | str | None = EVALUATE_DEFAULTS["align_heading"],
    ref_frame: str | None = EVALUATE_DEFAULTS["ref_frame"],
    ref_mounting: str | None = EVALUATE_DEFAULTS["ref_mounting"],
    start: float | str | None = EVALUATE_DEFAULTS["start"],
    end: float | str | None = EVALUATE_DEFAULTS["end"],
) -> dict[str, Any]:
    """Compare ``estimate`` with ``reference`` (paths or Recordings; default: the estimate's own ``ref_*``).

    channel: ``angles`` (roll/pitch/heading vs ref_roll/ref_pitch/ref_heading, deg), ``quaternion`` (q vs
    ref_q), ``heave`` or ``position``; default angles plus quaternion when both have one. A reference file
    without any ``ref_*`` angle or quaternion is read as the reference as it is (its roll/pitch/heading/q);
    angles missing where a quaternion is there are derived from it (ZYX, body→NED). ``max_lag_s``: search a
    constant lag up to ± this many seconds. ``align_heading``: a constant heading offset (deg) added to the
    reference's heading (and its quaternion turned about down by it), or ``'auto'`` (the circular mean of
    estimate − reference heading, reported) — a motion-capture frame's x axis is not north. ``plot``: error plot
    (.png/.pdf). Every angle is compared on the circle (errors in (−180°, 180°]); roll and heading are left out
    where |pitch| > :data:`imutool.metrics.GIMBAL_PITCH_DEG` (Euler angles are singular there; the quaternion
    metrics cover those rows). ``ref_frame`` (``ned``, ``enu``, ``zup``) and ``ref_mounting`` (``REMAP[;R,P,Y]``)
    declare the reference's world and body axes: it is converted into body FRD → NED
    (:func:`imutool.refframe.reference_to_ned`; ``reference_frame`` in the summary); a reference whose vertical
    lies more than 20° from the estimate's gravity direction on average is warned about (``warnings``).
    ``start``/``end``: compare only that window of the estimate (s on its clock, or ISO 8601 UTC where it has a
    date; as a report's ``--start/--end``). Returns the summary dict (``span``: the compared times, with ISO UTC
    where dated).
    """
    if channel is not None and channel not in CHANNELS:
        raise ImutoolError(f"evaluate channel {channel!r}: expected one of {', '.join(CHANNELS)}")
    align = parse_align_heading(align_heading)
    ref_frame = parse_ref_frame(ref_frame)
    est_path = _name(estimate)
    est = estimate if isinstance(estimate, Recording) else load_for_evaluation(estimate)
    if start is not None or end is not None:
        from imutool.report.route import evaluated_window  # the reports' window (heavy package: only for a window)

        est = evaluated_window(est, start, end, est_path)
    if reference is None:
        ref, ref_path = est, None
    else:
        ref = reference if isinstance(reference, Recording) else load_for_evaluation(reference)
        ref_path = _name(reference)
        check_overlap(est, ref, est_path, ref_path)
    summary: dict[str, Any] = {"estimate": est_path, "reference": ref_path or est_path}
    notes: list[str] = []
    warnings: list[str] = []
    if channel not in ("heave", "position"):
        same = ref is est
        if not same:
            ref = as_reference(ref, notes)
        est = with_angles(est, "", notes)
        ref = with_angles(est if same else ref, "ref_", notes)
        if same:
            est = ref
        if ref_frame is not None or ref_mounting:
            ref, frame = reference_to_ned(ref, ref_frame, ref_mounting)
            if same:
                est = ref
        else:
            frame = reference_to_ned(ref)[1]
        angle = vertical_disagreement(est, ref)
        if angle is not None:
            frame["vertical_disagreement_deg"] = round(angle, 3)
        summary["reference_frame"] = frame
        w = frame_warning(angle, ref_frame is not None or bool(ref_mounting))
        if w:
            warnings.append(w)
        if align is not None:
            est, ref, summary["align_heading"] = align_reference_heading(est, ref, align)
    if channel in ("heave", "position", "quaternion") and (est.multi_clock or ref.multi_clock):
        drv = {"heave": "heave", "position": "pos", "quaternion": "q"}[channel]
        same = ref is est
        est = one_clock(est, (drv,))
        ref = est if same else one_clock(ref, (f"ref_{drv}", drv))
        notes += [
            f"{w}: {r.meta['clock']['note']}" for w, r in (("estimate", est), ("reference", ref)) if "clock" in r.meta
        ]
    if channel == "heave":
        signs = {
            "estimate": str(est.meta.get("heave_positive", "up")),
            "reference": str(ref.meta.get("heave_positive", "up")),
        }
        same = ref is est
        est = heave_up(est)
        ref = est if same else heave_up(ref)
        summary["heave"] = _external("imutool.heave", "evaluate_heave", "heave")(est, ref, max_lag_s)
        summary["heave"]["compared"] = (
            f"positive up (files: estimate {signs['estimate']}, reference {signs['reference']})"
        )
        heave_readings(est, ref, summary["heave"])
    elif channel == "position":
        summary["position"] = _external("imutool.ins", "evaluate_position", "position")(est, ref)
    else:
        if channel in (None, "angles"):
            ang = evaluate_angles(est, ref, max_lag_s)
            if ang:
                summary["angles"] = ang
            elif channel == "angles":
                raise ImutoolError(
                    "no angle to compare: need roll/pitch/heading in EST and ref_roll/ref_pitch/"
                    "ref_heading in the reference"
                )
        if channel == "quaternion" or (channel is None and "q" in est.channels and "ref_q" in ref.channels):
            summary["quaternion"] = evaluate_quaternion_rec(est, ref)
        if len(summary) - ("align_heading" in summary) - ("reference_frame" in summary) == 2:
            raise ImutoolError("nothing to compare: no matching estimate/ref_* channels", path=est_path)
    if notes:
        summary["derived"] = notes
    if warnings:
        summary["warnings"] = warnings
    summary["span"] = compared_span(est, ref)
    if plot:
        plot_errors(est, ref, os.fspath(plot))
        summary["plot"] = os.fspath(plot)
    return summary


def run_evaluate(
    estimate: str | os.PathLike | Recording,
    reference: str | os.PathLike | Recording | None = None,
    *,
    channel: str | None = EVALUATE_DEFAULTS["channel"],
    max_lag_s: float = EVALUATE_DEFAULTS["max_lag_s"],
    plot: str | os.PathLike | None = EVALUATE_DEFAULTS["plot"],
    align_heading: float | str | None = EVALUATE_DEFAULTS["align_heading"],
    ref_frame: str | None = EVALUATE_DEFAULTS["ref_frame"],
    ref_mounting: str | None = EVALUATE_DEFAULTS["ref_mounting"],
    start: float | str | None = EVALUATE_DEFAULTS["start"],
    end: float | str | None = EVALUATE_DEFAULTS["end"],
    strict: bool = False,
    on_input: OnInput | None = None,
    **load_options: Any,
) -> RouteResult:
    """The route of ``imutool evaluate`` (and ``imutool batch evaluate``): :func:`evaluate` → its summary as a
    :class:`imutool.routes.RouteResult` (what ``--json`` prints, with ``validation``).

    A path ``estimate`` is loaded as every command's input (:func:`imutool.loading.load_recording` with
    ``load_options``: ``--columns ... --rate --time-column --header-rows --with``; ``strict``; ``on_input(path,
    report)`` after it); the reference is read as it is (:func:`load_for_evaluation`), or, given any of the
    reference's options (``ref_columns``, ``ref_profile``, ``ref_rate_hz``, ``ref_time_column``,
    ``ref_header_rows``, ``ref_with_files``, ``ref_with_offsets``, ``ref_start``:
    :data:`imutool.loading.REF_LOAD_OPTIONS`; a path only), loaded with them
    as an input is (time order as :func:`load_for_evaluation` puts it; ``reference_loading`` in the summary says
    how)."""
    load_options, ref_given = split_reference_options(load_options)
    unknown = set(load_options) - set(LOAD_OPTIONS)
    if unknown:
        raise TypeError(f"run_evaluate() got unexpected keyword argument(s) {', '.join(sorted(unknown))}")
    inputs: list[dict[str, Any]] = []
    if not isinstance(estimate, Recording):
        opts = {k: v for k, v in load_options.items() if v is not None}
        estimate = load_input(os.fspath(estimate), inputs, strict=strict, on_input=on_input, with_clock="own", **opts)[
            0
        ]
    loaded = None
    if ref_given:
        flags = ", ".join(sorted(reference_text(FLAGS[k]) for k in ref_given))
        if reference is None:
            raise ImutoolError(f"{flags}: say how to read a reference file; give the file with --reference")
        if isinstance(reference, Recording):
            raise TypeError("the reference's loading options apply to a file, not to a Recording already loaded")
        reference = load_reference(
            os.fspath(reference),
            inputs,
            strict=strict,
            on_input=on_input,
            duplicates="drop",
            backwards="sort",
            with_clock="own",
            **ref_given,
        )[0]
        loaded = how_loaded(reference, ref_given, reference=True)
    summary = evaluate(
        estimate,
        reference,
        channel=channel,
        max_lag_s=max_lag_s,
        plot=plot,
        align_heading=align_heading,
        ref_frame=ref_frame,
        ref_mounting=ref_mounting,
        start=start,
        end=end,
    )
    if loaded is not None:
        summary["reference_loading"] = loaded
    return RouteResult(summary, inputs)


def parse_align_heading(value: float | str | None) -> float | str | None:
    """``--align-heading``: None, ``'auto'`` or a finite number of degrees."""
    if value is None or (isinstance(value, str) and not value.strip()):
        return None
    if isinstance(value, str) and value.strip().lower() == "auto":
        return "auto"
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not np.isfinite(v):
        raise ImutoolError(f"--align-heading {value!r}: expected a heading offset in degrees or 'auto'")
    return v


def as_reference(ref: Recording, notes: list[str]) -> Recording:
    """A reference file that has no ``ref_*`` angle or quaternion (another instrument's output, a motion-capture
    log): its roll/pitch/heading/q read as ref_roll/ref_pitch/ref_heading/ref_q."""
    names = (*ANGLES, "q")
    if any(f"ref_{n}" in ref.channels for n in names) or not any(n in ref.channels for n in names):
        return ref
    out = ref.copy()
    used = [n for n in names if n in ref.channels]
    for n in used:
        out.add(f"ref_{n}", ref[n], ref.units.get(n))
    notes.append(f"the reference file has no ref_* columns: its {', '.join(used)} used as the reference")
    return out


def with_angles(rec: Recording, prefix: str, notes: list[str]) -> Recording:
    """``rec`` with the roll/pitch/heading (deg) it lacks derived from its quaternion ``<prefix>q`` (ZYX Euler of
    body→NED; heading in [0, 360)). ``prefix``: ``''`` (estimate) or ``'ref_'`` (reference)."""
    q = f"{prefix}q"
    missing = [n for n in ANGLES if f"{prefix}{n}" not in rec.channels]
    if q not in rec.channels or not missing or np.shape(rec[q])[1:] != (4,):
        return rec
    out = rec.copy()
    angles = dict(zip(ANGLES, (np.degrees(a) for a in quat_to_euler(rec[q])), strict=True))
    for n in missing:
        out.add(f"{prefix}{n}", angles[n], "deg")
    notes.append(f"{', '.join(prefix + n for n in missing)} derived from {q} (ZYX Euler of body→NED, deg)")
    return out


def align_reference_heading(
    est: Recording, ref: Recording, offset: float | str
) -> tuple[Recording, Recording, dict[str, Any]]:
    """The reference with a constant heading offset (deg) added to ref_heading and ref_q turned about down by it;
    ``'auto'``: the offset is the circular mean of estimate heading − reference heading (on the estimate's
    times). Returns (estimate, reference, what was done). The estimate is the reference when they are one."""
    from imutool.metrics import interp_to, unwrap_deg

    if "ref_heading" not in ref.channels and "ref_q" not in ref.channels:
        raise ImutoolError("--align-heading: the reference has no heading (ref_heading or ref_q)")
    info: dict[str, Any] = {}
    if offset == "auto":
        if "heading" not in est.channels or "ref_heading" not in ref.channels:
            raise ImutoolError("--align-heading auto: needs a heading in the estimate and in the reference")
        r = interp_to(est.time, ref.time, unwrap_deg(ref["ref_heading"]))
        d = np.radians(angle_diff_deg(est["heading"], r))
        d = d[np.isfinite(d)]
        if d.size == 0:
            raise ImutoolError("--align-heading auto: the estimate and the reference headings do not overlap")
        c, s = float(np.mean(np.cos(d))), float(np.mean(np.sin(d)))
        value = float(np.degrees(np.arctan2(s, c)))
        info = {
            "offset_deg": round(value, 4),
            "how": f"auto: circular mean of estimate − reference heading over {d.size} samples",
            "resultant_length": round(float(np.hypot(c, s)), 4),  # 1: a constant offset; near 0: no common one
            "circular_std_deg": round(
                float(np.degrees(np.sqrt(max(0.0, -2.0 * np.log(max(np.hypot(c, s), 1e-12)))))), 3
            ),
        }
    else:
        value = float(offset)
        info = {"offset_deg": value, "how": "given (--align-heading)"}
    info["applied_to"] = "reference heading + offset; reference quaternion turned about down by the offset"
    same = ref is est
    out = ref.copy()
    if "ref_heading" in out.channels:
        out.add("ref_heading", (np.asarray(ref["ref_heading"], float) + value) % 360.0, "deg")
    if "ref_q" in out.channels:
        h = np.radians(value) / 2.0
        qz = np.array([np.cos(h), 0.0, 0.0, np.sin(h)])
        out.channels["ref_q"] = quat_multiply(qz, np.asarray(ref["ref_q"], float))
    out.meta["heading_alignment"] = info
    return (out if same else est), out, info


def compared_span(est: Recording, ref: Recording) -> dict[str, Any]:
    """The times both recordings cover (recording s; ISO UTC beside them where the estimate has a date)."""
    clock = Clock.of(est)
    t0 = max(float(est.time[0]), float(ref.time[0])) if len(est) and len(ref) else float("nan")
    t1 = min(float(est.time[-1]), float(ref.time[-1])) if len(est) and len(ref) else float("nan")
    out: dict[str, Any] = {"start_s": t0, "end_s": t1, "duration_s": t1 - t0, "shown_as": clock.unit}
    if clock.dated:
        out["start_utc"], out["end_utc"] = clock.iso(t0), clock.iso(t1)
    out["text"] = f"{clock.text(t0)} … {clock.text(t1)} {clock.unit}" + (f" ({clock.date()})" if clock.dated else "")
    return out


def check_overlap(est: Recording, ref: Recording, est_path: str, ref_path: str) -> None:
    """A reference that can be compared with the estimate: each a recording with a duration
    (:func:`formats.recording.require_samples`), time spans that overlap, and at least :data:`MIN_REFERENCE_ROWS`
    reference rows within the estimate's span (an ImutoolError naming the reference otherwise)."""
    require_samples(len(ref), _distinct_times(ref), ref_path)
    require_samples(len(est), _distinct_times(est), est_path)
    start = max(float(est.time[0]), float(ref.time[0]))
    end = min(float(est.time[-1]), float(ref.time[-1]))
    if not end > start:
        raise ImutoolError(
            f"the reference ({ref.time[0]:.6g} … {ref.time[-1]:.6g} s) does not overlap the estimate "
            f"{os.path.basename(est_path)} ({est.time[0]:.6g} … {est.time[-1]:.6g} s) in time: same clock?",
            path=ref_path,
        )
    inside = int(np.count_nonzero((ref.time >= est.time[0]) & (ref.time <= est.time[-1])))
    if inside < MIN_REFERENCE_ROWS:
        raise ImutoolError(
            f"the reference has {inside} row(s) within the estimate's span ({est.time[0]:.6g} … {est.time[-1]:.6g} "
            f"s): a comparison needs at least {MIN_REFERENCE_ROWS} (fewer describe the interpolation between them, "
            "not the estimate)",
            path=ref_path,
        )


def _distinct_times(rec: Recording) -> int:
    """Rows at different times, counted up to two (what :func:`formats.recording.require_samples` asks)."""
    t = rec.time[np.isfinite(rec.time)]
    return 0 if not len(t) else (1 if np.ptp(t) == 0 else 2)


def _name(x: str | os.PathLike | Recording) -> str:
    return str(x.meta.get("source", "<recording>")) if isinstance(x, Recording) else os.fspath(x)


def evaluate_angles(est: Recording, ref: Recording, max_lag_s: float) -> dict[str, Any]:
    """Roll/pitch/heading of ``est`` vs ref_roll/ref_pitch/ref_heading of ``ref`` (deg, compared on the circle;
    SNR against the raw accelerometer/magnetometer angles of ``ref`` when it has the sensor channels). Roll and
    heading leave out the rows where either pitch is beyond :data:`imutool.metrics.GIMBAL_PITCH_DEG` (``excluded``
    counts them)."""
    from imutool.metrics import GIMBAL_PITCH_DEG, evaluate_angle, interp_to, unwrap_deg

    sensors = ref.on_clock("accel") if ref.multi_clock and "accel" in ref.channels else ref
    raw = _raw_angles(sensors)
    pitches = [x.series(n) if n in x.channels else None for x, n in ((est, "pitch"), (ref, "ref_pitch"))]
    out: dict[str, Any] = {}
    for name in ("roll", "pitch", "heading"):
        if name not in est.channels or f"ref_{name}" not in ref.channels:
            continue
        # many clocks: each angle on its own samples (never another stream's row as a missing sample)
        te, e = est.series(name)
        tr, rv = ref.series(f"ref_{name}")
        gimbal = None
        if name != "pitch" and all(p is not None for p in pitches):
            pe, pr = (p[1] if np.array_equal(p[0], te) else interp_to(te, p[0], p[1]) for p in pitches)
            with np.errstate(invalid="ignore"):
                g = (np.abs(pr) > GIMBAL_PITCH_DEG) | (np.abs(np.asarray(pe, float)) > GIMBAL_PITCH_DEG)
            gimbal = g if g.any() else None
        r = raw.get(name)
        if r is not None:
            r = interp_to(te, sensors.time, unwrap_deg(r))
        st = evaluate_angle(te, e, tr, rv, max_lag_s=max_lag_s, raw=r, exclude=gimbal)
        out[name] = {k: (round(v, 5) if isinstance(v, float) else v) for k, v in st.items()}
    return out


def evaluate_quaternion_rec(est: Recording, ref: Recording) -> dict[str, Any]:
    """q of ``est`` vs ref_q of ``ref`` (interpolated onto the estimate's times): BROAD total, heading and
    inclination errors (deg), over the ``movement`` rows when a movement label is there."""
    from imutool.metrics import evaluate_quaternion, interp_to

    if "q" not in est.channels:
        raise ImutoolError("the estimate has no quaternion (qw..qz)")
    if "ref_q" not in ref.channels:
        raise ImutoolError("the reference has no ref_qw..ref_qz columns")
    qr = ref["ref_q"]
    if _apart(est, ref) and (est.multi_clock or len(ref) != len(est) or not np.array_equal(ref.time, est.time)):
        qr = interp_to(est.time, ref.time, qr)
        qr = qr / np.linalg.norm(qr, axis=1, keepdims=True)
    mask = None
    for src in (est, ref):
        if "movement" in src.channels:
            mv = src["movement"] if src is est else np.round(interp_to(est.time, ref.time, ref["movement"]))
            mask = np.nan_to_num(mv) > 0
            break
    out = evaluate_quaternion(est["q"], qr, mask)
    out["rows"] = "movement rows" if mask is not None else "all rows"
    return out


def _apart(est: Recording, ref: Recording) -> bool:
    """Whether the reference's channels must be interpolated onto the estimate's rows: another recording, or one
    of many clocks (a ``--with`` file's truth on its own rows, :func:`imutool.loading.merge_with`)."""
    return ref is not est or est.multi_clock


def _raw_angles(ref) -> dict[str, np.ndarray]:
    """Unfiltered angles (deg) from the reference file's sensor channels (accel tilt, tilt-compensated mag)."""
    if "accel" not in ref.channels:
        return {}
    from imutool.baseline import accel_tilt, tilt_compensated_heading

    roll, pitch = accel_tilt(ref["accel"])
    out = {"roll": np.degrees(roll), "pitch": np.degrees(pitch)}
    if "mag" in ref.channels:
        out["heading"] = np.degrees(tilt_compensated_heading(ref["mag"], roll, pitch))
    return out


def _external(module: str, func: str, what: str):
    try:
        mod = importlib.import_module(module)
        return getattr(mod, func)
    except (ImportError, AttributeError):
        raise ImutoolError(f"{what} evaluation is not available in this build ({module}:{func} missing)") from None


_HEAVE_COLUMNS = ("heave", "heave_delayed", "heave_rate", "heave_rate_delayed", "ref_heave", "ref_heave_rate")


def heave_up(rec: Recording) -> Recording:
    """The recording with every heave column positive up (metadata ``heave_positive: down`` → negated copy)."""
    if str(rec.meta.get("heave_positive", "up")).lower() != "down":
        return rec
    out = rec.copy()
    for name in _HEAVE_COLUMNS:
        if name in out.channels:
            out.add(name, -out[name], out.units.get(name))
    out.meta["heave_positive"] = "up"
    return out


def heave_readings(est: Recording, ref: Recording, out: dict[str, Any]) -> None:
    """Add the three "5 cm or 5 %" readings (imutool.metrics.heave_accuracy) to each evaluated heave channel."""
    from imutool.metrics import heave_accuracy

    rname = next(
        (n for n in ("ref_heave", "heave") if n in ref.channels and (ref is not est or n == "ref_heave")), None
    )
    if rname is None:
        return
    for ch, flag in (("heave", "settled"), ("heave_delayed", "settled_delayed")):
        if isinstance(out.get(ch), dict) and ch in est.channels and "not_evaluated" not in out[ch]:
            mask = np.asarray(est[flag]) > 0.5 if flag in est.channels else None
            out[ch]["readings"] = heave_accuracy(
                est.time, est[ch], ref.time, ref[rname], lag_s=float(out[ch].get("lag_s", 0.0)), mask=mask
            )


def plot_errors(est: Recording, ref: Recording, path: str) -> None:
    """Estimate and reference per angle, and the error with the filter's ±2σ band, into ``path`` (.png/.pdf)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from imutool.metrics import interp_to, unwrap_deg

    names = [n for n in ("roll", "pitch", "heading") if n in est.channels and f"ref_{n}" in ref.channels]
    if not names:
        raise ImutoolError("nothing to plot: no roll/pitch/heading with ref_* columns")
    clock = Clock.of(est)
    fig, axes = plt.subplots(len(names), 2, figsize=(12, 2.8 * len(names)), squeeze=False, sharex=True)
    for i, n in enumerate(names):
        rows = est.own_rows(n)  # many clocks: the estimate's own samples (another stream's rows are not gaps)
        x = clock.x(est.time[rows])  # seconds from the start; dated: UTC clock ticks
        r = interp_to(est.time[rows], ref.time, unwrap_deg(ref[f"ref_{n}"]))
        e = angle_diff_deg(est[n][rows], r)  # on the circle: no ±360° spikes where an angle crosses ±180° or north
        r = r % 360 if n == "heading" else angle_diff_deg(r)
        axes[i, 0].plot(x, r, "k-", lw=1, label="reference")
        axes[i, 0].plot(x, est[n][rows], "C0-", lw=0.8, label="estimate")
        axes[i, 0].set_ylabel(f"{n} (deg)")
        axes[i, 0].legend(loc="upper right", fontsize=8)
        axes[i, 1].plot(x, e, "C3-", lw=0.8)
        if f"{n}_std" in est.channels:
            s = est[f"{n}_std"][rows]
            axes[i, 1].fill_between(x, -2 * s, 2 * s, color="0.8", label="±2σ (filter)")
            axes[i, 1].legend(loc="upper right", fontsize=8)
        axes[i, 1].set_ylabel(f"{n} error (deg)")
    for ax in axes[-1]:
        clock.axis(ax)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=path.rsplit(".", 1)[-1].lower() if "." in path else "png", dpi=100)
    plt.close(fig)
