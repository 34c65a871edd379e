"""The route behind ``imutool heave`` and ``imutool batch heave``: read the input, compute the heave with
:mod:`imutool.heave` (or :mod:`imutool.gnss_heave` from a GNSS height), write the heave recording and, if asked,
the PASHR/TSS1 log (:func:`imutool.nmea_out.write_log`).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.errors import ImutoolError
from formats.jit.warm import CSV_WRITER, warm_in_background
from imutool.heave import (
    GNSS_METHOD,
    HEAVE_CHANNELS,
    HEAVE_KERNELS,
    ROUTE_METHODS,
    TILT_GAIN,
    _bank_kernel,
    _evaluate_at_reference,
    heave_recording,
    refuse_unused_cutoff,
)
from imutool.loading import one_clock
from imutool.metrics import interp_to
from imutool.nmea_out import write_log
from imutool.routes import LOAD_OPTIONS, OnInput, RouteResult, Stage, read_source

NMEA_HEAVE_SENTENCES = ("PASHR", "TSS1")


NMEA_CARRIED = ("roll", "pitch", "heading", "heading_true", "sog", "cog", "lat", "lon")  # input channels NMEA uses


NMEA_META = ("start_utc", "utc_start", "start_time_utc", "scenario", "sensor")  # the input's clock and identity


def heave_positive_down(out: Recording) -> None:
    """Flip every heave column of ``out`` (m, m/s) in place to positive DOWN and say so in its metadata."""
    for name in HEAVE_CHANNELS:
        if name in out.channels:
            out.add(name, -out[name], out.units.get(name))
    out.meta["heave_positive"] = "down"
    out.meta["heave"] = str(out.meta.get("heave", "m")).replace("positive UP", "positive DOWN")


def run_heave(
    source: str | os.PathLike | Recording,
    output: str | os.PathLike | None = None,
    *,
    method: str = "realtime",
    vertical: list[str] | tuple[str, ...] | None = None,
    vertical_sign: str = "up",
    attitude: str = "auto",
    lever_arm: Any = None,
    tilt_gain: float = TILT_GAIN,
    nmea: str | os.PathLike | None = None,
    nmea_sentences: str | list[str] | tuple[str, ...] = "PASHR",
    nmea_rate: float | None = None,
    nmea_baud: int = 4800,
    heave_positive: str = "up",
    height_window_s: float | None = None,
    gnss_fix: str = "rtk",
    gnss_lever_arm: Any = None,
    gnss_reference: bool = True,
    strict: bool = False,
    on_input: OnInput | None = None,
    stage: Stage | None = None,
    **options: Any,
) -> RouteResult:
    """Heave of ``source`` (a path, loaded as every command loads it, or a Recording) written to ``output``: the
    route behind ``imutool heave`` and ``imutool batch heave``.

    ``method`` (:data:`METHODS`) and ``options`` (harmonics, cutoff, cutoff_ratio, order, delayed_cutoff,
    window_s, hop_s, min_window_s, fmin, fmax, bandwidth, meas_noise, residual_noise: :func:`estimate_heave`);
    ``vertical``: single vertical accelerometer channels (averaged; a name also matches in lower case) with
    ``vertical_sign``; else the 3-axis accel rotated with ``attitude`` (auto, q, ekf, tilt, ref), ``lever_arm``
    (m, body FRD) and ``tilt_gain`` (1/s). ``nmea``: also write PASHR and/or TSS1 (``nmea_sentences``) there at
    ``nmea_rate`` Hz fitting ``nmea_baud`` (:func:`imutool.nmea_out.write_log`). ``heave_positive``: ``up``
    (imutool) or ``down``: every heave column and sentence flips, the headers say so.

    GNSS height (a ``gnss_height`` channel: GGA, PTNL,GGK/PJK; :mod:`imutool.gnss_heave`): with ``method``
    ``gnss``, or when the input has no accelerometer, the heave is the detrended height (``height_window_s``,
    None = 10 dominant periods within 60–600 s; ``gnss_fix`` rtk/fixed/any; ``gnss_lever_arm`` the monitoring
    point relative to the antenna, m body FRD, applied with the input's roll/pitch). With an accelerometer and
    ``gnss_reference``, the height heave becomes ``ref_heave`` (where the input has none) and the summary's
    ``gnss_reference`` compares the two. ``load_options`` of a path:
    columns, profile, topic, stamp, duplicates, backwards, mounting, calibration_file (in ``options`` too).
    Returns the output recording and the summary (rows, heave_positive, the estimator's figures, ``nmea``).
    """
    load_options = {k: options.pop(k) for k in LOAD_OPTIONS if k in options}
    if method in ROUTE_METHODS:  # before reading: a --cutoff no band-pass would use
        refuse_unused_cutoff(method, options.get("cutoff"))
    inputs: list[dict[str, Any]] = []
    if isinstance(source, Recording) or os.path.isfile(source):
        # a cold cache: a second process compiles the heave kernels and the CSV writer while this one compiles the
        # CSV reader (formats.jit.warm)
        csv_out = output is not None and os.fspath(output).lower().endswith(".csv")
        warm_in_background(_bank_kernel, HEAVE_KERNELS + ((CSV_WRITER,) if csv_out else ()))
    if stage is not None:
        stage("reading")
    rec, name, _ = read_source(source, inputs, strict=strict, on_input=on_input, **load_options)
    cols = None
    if vertical:
        cols = [c if c in rec.channels else c.lower() if c.lower() in rec.channels else c for c in vertical]
    # many clocks: the accelerometer's own samples (or the GNSS height's for a heave from height)
    gnss_only = method == GNSS_METHOD or not (cols or "accel" in rec.channels)
    rec = one_clock(rec, ("gnss_height",) if gnss_only else (*(cols or ()), "accel"), inputs)
    arm = None if lever_arm is None else np.asarray(lever_arm, dtype=float).reshape(-1)
    has_accel = bool(cols) or "accel" in rec.channels
    height_only = method == GNSS_METHOD or (not has_accel and "gnss_height" in rec.channels)
    if stage is not None:
        stage(f"heave ({GNSS_METHOD if height_only else method})")
    if height_only:
        from imutool.gnss_heave import height_heave  # noqa: PLC0415

        if lever_arm is not None:
            raise ImutoolError("--lever-arm is the IMU's; for a heave from GNSS height give --gnss-lever-arm")
        refuse_unused_cutoff(GNSS_METHOD, options.get("cutoff"))
        out, summary = height_heave(rec, window_s=height_window_s, fix=gnss_fix, lever_arm=gnss_lever_arm)
        if method != GNSS_METHOD:
            summary["method_note"] = f"no accelerometer in the input: heave from gnss_height (not {method})"
    else:
        out, summary = heave_recording(
            rec,
            method=method,
            vertical=cols,
            vertical_sign=vertical_sign,
            attitude="tiltonly" if attitude == "tilt" else attitude,
            lever_arm=arm,
            tilt_gain=tilt_gain,
            **options,
        )
        if gnss_reference and "gnss_height" in rec.channels:
            summary["gnss_reference"] = _gnss_reference(out, rec, height_window_s, gnss_fix, gnss_lever_arm)
    nmea_info = None
    if nmea:
        names = nmea_sentences.split(",") if isinstance(nmea_sentences, str) else nmea_sentences
        sents = [x.strip().upper() for x in names if x.strip()]
        bad = [x for x in sents if x not in NMEA_HEAVE_SENTENCES]
        if bad:
            raise ImutoolError(f"--nmea-sentences: {', '.join(bad)} not heave sentences (PASHR, TSS1)")
        nrec = out.copy()
        for ch in NMEA_CARRIED:
            if ch in rec.channels and ch not in nrec.channels:
                nrec.add(ch, rec[ch], rec.units.get(ch))
        for key in NMEA_META:
            if rec.meta.get(key) and key not in nrec.meta:
                nrec.meta[key] = rec.meta[key]
        nmea_info = write_log(
            nrec,
            os.fspath(nmea),
            sents,
            rate_hz=nmea_rate,
            baud=nmea_baud,
            source=name,
            heave_positive=heave_positive,
            heading_ref="true",
        )
    if heave_positive == "down":  # every heave column flips; the header says so
        heave_positive_down(out)
    else:
        out.meta["heave_positive"] = "up"
    if stage is not None:
        stage("writing")
    if output is not None:
        formats.write(out, output)
    summary = {
        "input": name,
        "output": None if output is None else os.fspath(output),
        "rows": len(out),
        "heave_positive": heave_positive,
        **summary,
    }
    if nmea_info is not None:
        summary["nmea"] = nmea_info
    return RouteResult(summary, inputs, out)


def _gnss_reference(out: Recording, rec: Recording, window_s: float | None, fix: str, lever_arm: Any) -> dict[str, Any]:
    """The heave from ``rec``'s gnss_height as ``out``'s ``ref_heave`` (unless it has one) and the comparison."""
    from imutool.gnss_heave import height_heave  # noqa: PLC0415

    href, hs = height_heave(rec, window_s=window_s, fix=fix, lever_arm=lever_arm)
    hv = np.where(href["settled"] > 0, href["heave"], np.nan)
    info: dict[str, Any] = {"window_s": hs["window_s"], "fix_filter": hs["fix_filter"]}
    if "ref_heave" not in out.channels:
        out.add("ref_heave", interp_to(out.time, href.time, hv), "m")
        out.meta["ref_heave"] = f"heave from gnss_height (detrended over {hs['window_s']:g} s, {hs['fix_filter']})"
        info["ref_heave"] = "added"
    try:
        info.update(_evaluate_at_reference(out, href.time, hv, f"gnss_height detrended over {hs['window_s']:g} s", 0.0))
    except ImutoolError as e:
        info["not_compared"] = str(e)
    return info
