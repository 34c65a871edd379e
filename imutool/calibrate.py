"""Calibration runs: the one route behind ``imutool calibrate mag|gyro|accel|deviation``, ``imutool batch`` and a
Python user.

Each function takes a path (loaded by :func:`imutool.loading.load_recording`; ``with_files`` — other files of
the same run, e.g. one CSV per sensor — are merged onto its clock) or a :class:`formats.Recording`, runs the fit
of :mod:`calibration`, writes the section (with provenance) into a calibration TOML and any plot or card, and
returns a :class:`CalibrationRun` (a :class:`imutool.routes.RouteResult`: the summary ``imutool calibrate ... --json``
prints, what loading each input did, and the fit). Nothing is printed; ``imutool batch 'calibrate mag'`` calls the
same functions. Units: magnetic field µT, rates rad/s (deg/s in
the summaries where named so), specific force m/s², headings and deviation deg.

    from imutool.calibrate import calibrate_mag
    run = calibrate_mag("sphere.csv", "cal.toml", plot="cal.png")
    run.fit.b, run.summary["residual_rms_uT"]
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from datetime import date, datetime, timezone
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.atomic import atomic_path
from formats.errors import ImutoolError
from formats.frames import angle_diff_deg
from imutool.loading import (
    FLAGS,
    how_loaded,
    load_recording,
    merge_with,
    reference_text,
    require_channels,
    split_reference_options,
)
from imutool.routes import LOAD_OPTIONS, OnInput, RouteResult, Stage, load_reference


@dataclass
class CalibrationRun(RouteResult):
    """What a calibration run produced: the :class:`imutool.routes.RouteResult` (``summary``: JSON-able figures;
    ``inputs``: what loading each file did; ``recording``: what was fitted), ``fit`` (the :mod:`calibration`
    result object) and for a deviation card the names of what was compared (``details``)."""

    fit: Any = None
    details: dict[str, Any] = field(default_factory=dict)


def _noting(inputs: list[dict[str, Any]], on_input: OnInput | None) -> OnInput:
    """An ``on_input`` that also keeps each input's report in ``inputs`` (the run's :attr:`RouteResult.inputs`)."""

    def noted(path: str, report: dict[str, Any]) -> None:
        inputs.append({"input": path, **report})
        if on_input is not None:
            on_input(path, report)

    return noted


def _check_load_options(load_options: dict[str, Any]) -> None:
    unknown = set(load_options) - set(LOAD_OPTIONS)
    if unknown:
        raise TypeError(f"unexpected keyword argument(s) {', '.join(sorted(unknown))}")


def check_toml_output(output: str | os.PathLike, append: bool = False) -> None:
    """A calibration file must be ``.toml``; with ``append`` an existing one must load cleanly (before any work)."""
    output = os.fspath(output)
    if not output.lower().endswith(".toml"):
        raise ImutoolError(f"the calibration file must be .toml: {output!r}")
    if append and os.path.exists(output):
        from calibration.file import load_calibration

        load_calibration(output)


def load_for_fit(
    source: str | os.PathLike | Recording,
    load_options: dict[str, Any] | None = None,
    with_files: tuple[str, ...] | list[str] = (),
    fitting: str | None = None,
    on_input: OnInput | None = None,
    strict: bool = False,
) -> Recording:
    """Read ``source`` (and ``with_files``, e.g. one CSV per sensor, merged onto its clock:
    :func:`imutool.loading.merge_with`). ``on_input(path, report)`` is called after the file is loaded; ``strict``: an
    input's warnings are an ImutoolError.

    ``fitting``: the section being estimated. Its parameters are in sensor axes and relative to raw data, so
    a ``mounting`` and a ``calibration_file`` that already holds that section are refused."""
    opts = {k: v for k, v in (load_options or {}).items() if v is not None}
    _check_load_options(opts)
    if fitting and opts.get("mounting"):
        raise ImutoolError(
            f"{fitting} calibration parameters are in sensor axes: calibrate without --mounting "
            "(store the mounting separately; it is applied after the calibration)"
        )
    if fitting and opts.get("calibration_file"):
        from calibration.file import load_calibration

        if fitting in load_calibration(opts["calibration_file"]):
            raise ImutoolError(
                f"--calibration {opts['calibration_file']} already has a [{fitting}] section: "
                f"the {fitting} fit needs raw data",
                path=opts["calibration_file"],
            )

    if with_files:
        opts["with_files"] = tuple(opts.get("with_files") or ()) + tuple(os.fspath(p) for p in with_files)
    if isinstance(source, Recording):
        if opts.get("with_files"):
            src = str(source.meta.get("source", "<recording>"))
            rec, _ = merge_with(
                source,
                src,
                list(opts["with_files"]),
                list(opts.get("with_offsets") or ()),
                list(opts.get("with_prefixes") or ()),
            )
            rec.meta["source"] = src
            return rec
        return source
    path = os.fspath(source)
    rec, report = load_recording(path, strict=strict, **opts)
    if on_input is not None and len(rec):
        on_input(path, report)
    return rec


def _source_name(source: str | os.PathLike | Recording) -> str:
    return str(source.meta.get("source", "")) if isinstance(source, Recording) else os.fspath(source)


def _read_for_fit(
    source: str | os.PathLike | Recording,
    kind: str,
    load_options: dict[str, Any] | None,
    with_files: tuple[str, ...] | list[str],
    on_input: OnInput | None,
    stage: Stage | None,
    strict: bool = False,
) -> Recording:
    """The reading stage of a calibration run: load (with the --with files), then require the ``kind`` channel."""
    _stage(stage, "reading")
    rec = load_for_fit(source, load_options, with_files, fitting=kind, on_input=on_input, strict=strict)
    _stage(stage, "fitting")
    require_channels(rec, [kind], _source_name(source))
    return rec


def _stage(stage: Stage | None, name: str) -> None:
    if stage is not None:
        stage(name)


# -- magnetometer ------------------------------------------------------------------------------------------------
def calibrate_mag(
    source: str | os.PathLike | Recording,
    output: str | os.PathLike,
    *,
    method: str = "sphere",
    kind: str = "auto",
    field_ut: float | None = None,
    min_coverage: float | None = None,
    grid_bands: int = 8,
    horizontal_field: float | None = None,
    bz_prior: float = 0.0,
    a33_prior: float | None = None,
    plot: str | os.PathLike | None = None,
    append: bool = False,
    sensor: str | None = None,
    with_files: tuple[str, ...] = (),
    strict: bool = False,
    on_input: OnInput | None = None,
    stage: Stage | None = None,
    **load_options: Any,
) -> CalibrationRun:
    """Hard/soft-iron fit ``m_true = A (m_meas − b)`` (b µT) of the magnetometer: ``sphere`` (full 3-D rotations;
    ``kind`` offset/diag/full/auto, ``field_ut`` scales A, ``min_coverage``, ``grid_bands``) or ``swing`` (the
    vessel turns in heading only: ``horizontal_field`` µT, ``bz_prior`` µT, ``a33_prior``). Writes section
    ``[mag]`` of ``output`` (merged into it with ``append``) and the before/after ``plot``."""
    from calibration.file import provenance, update_calibration

    input_path = _source_name(source)
    check_toml_output(output, append)
    inputs: list[dict[str, Any]] = []
    rec = _read_for_fit(source, "mag", load_options, with_files, _noting(inputs, on_input), stage, strict)
    m = rec.get("mag", "uT")
    if method == "sphere":
        from calibration.magnetometer import calibrate_sphere

        fit = calibrate_sphere(m, kind, field_ut, min_coverage, grid_bands)
    elif method == "swing":
        from calibration.swing import calibrate_swing

        acc = rec.get("accel", "m/s^2") if "accel" in rec.channels else None
        fit = calibrate_swing(m, acc, horizontal_ut=horizontal_field, bz_prior=bz_prior, a33_prior=a33_prior)
    else:
        raise ImutoolError(f"mag calibration method {method!r}: expected sphere or swing")
    section = fit.to_section()
    section["provenance"] = provenance(
        input_path,
        f"mag {method} ({fit.kind})",
        sensor or str(rec.meta.get("sensor", "")),
        fit.quality(),
        with_files=list(with_files) or None,
    )
    if plot:  # the plot first: a plot that fails leaves no calibration file behind (nor a plot)
        import matplotlib.pyplot as plt

        from calibration.magnetometer import before_after_figure

        fig = before_after_figure(m, fit, title=f"{os.path.basename(input_path)} ({method})")
        ext = str(plot).rsplit(".", 1)[-1].lower()
        try:
            with atomic_path(plot) as staged:
                fig.savefig(staged, format=ext if ext in ("png", "pdf", "svg") else "png", dpi=100)
                update_calibration(output, "mag", section, append)
        finally:
            plt.close(fig)
    else:
        update_calibration(output, "mag", section, append)
    from calibration.magnetometer import absent_information

    absent = absent_information(fit, field_given=field_ut is not None) if method == "sphere" else []
    summary = {
        "output": os.fspath(output),
        "method": method,
        "kind": fit.kind,
        "reason": fit.reason,
        "model": "m_true = A (m_meas - b)",
        "b_uT": np.round(fit.b, 4).tolist(),
        "b_std_uT": [None if not np.isfinite(v) else round(float(v), 4) for v in fit.b_std],
        "A": np.round(fit.A, 5).tolist(),
        "field_uT": round(fit.field_ut, 3),
        "residual_rms_uT": round(fit.residual_rms_ut, 4),
        "coverage": round(fit.coverage, 3),
        "raw_field_rel_std_pct": round(100 * fit.raw_rel_std, 3),
        "calibrated_field_rel_std_pct": round(100 * fit.cal_rel_std, 3),
        "samples": fit.n,
        "warnings": fit.warnings,
        "information_absent": absent,
    }
    if method == "swing":
        summary["unobservable"] = fit.extra["section"]["unobservable"]
    return CalibrationRun(summary, inputs, rec, fit=fit)


# -- gyro and accelerometer ----------------------------------------------------------------------------------------
def rest_options(
    window_s: float = 1.0, gyro_std_deg: float = 0.5, accel_std: float = 0.1, min_rest_s: float = 2.0
) -> dict[str, float]:
    """Rest-detection keywords of :mod:`calibration.inertial` from the user-facing units: moving-std window (s),
    gyro std (deg/s → rad/s), accel std (m/s²), shortest rest interval (s)."""
    return {
        "window_s": window_s,
        "gyro_std": float(np.radians(gyro_std_deg)),
        "accel_std": accel_std,
        "min_rest_s": min_rest_s,
    }


def calibrate_gyro(
    source: str | os.PathLike | Recording,
    output: str | os.PathLike,
    *,
    turns_deg: float | None = None,
    min_temp_range: float = 1.0,
    rest: dict[str, float] | None = None,
    append: bool = False,
    sensor: str | None = None,
    with_files: tuple[str, ...] = (),
    strict: bool = False,
    on_input: OnInput | None = None,
    stage: Stage | None = None,
    **load_options: Any,
) -> CalibrationRun:
    """Gyro bias (rad/s) over automatically detected rest intervals (``rest``: :func:`rest_options`), a
    temperature slope when the rests span ``min_temp_range`` °C, scale/misalignment from turns of ``turns_deg``.
    Writes section ``[gyro]`` of ``output``."""
    from calibration.file import provenance, update_calibration
    from calibration.inertial import calibrate_gyro as fit_gyro

    input_path = _source_name(source)
    check_toml_output(output, append)
    inputs: list[dict[str, Any]] = []
    rec = _read_for_fit(source, "gyro", load_options, with_files, _noting(inputs, on_input), stage, strict)
    acc = rec.get("accel", "m/s^2") if "accel" in rec.channels else None
    temp = rec["temp"] if "temp" in rec.channels else None
    cal = fit_gyro(
        rec.time,
        rec.get("gyro", "rad/s"),
        acc,
        temp,
        min_temp_range=min_temp_range,
        turns_deg=turns_deg,
        **(rest if rest is not None else rest_options()),
    )
    section = cal.to_section()
    section["provenance"] = provenance(
        input_path,
        "gyro static bias over rest intervals"
        + (" + temperature slope" if cal.temp_slope is not None else "")
        + (" + scale from turns" if cal.scale is not None else ""),
        sensor or str(rec.meta.get("sensor", "")),
        cal.quality,
    )
    update_calibration(output, "gyro", section, append)
    summary = {
        "output": os.fspath(output),
        "bias_rad_s": cal.bias.tolist(),
        "bias_deg_s": np.degrees(cal.bias).tolist(),
        "temp_slope_deg_s_per_degC": None if cal.temp_slope is None else np.degrees(cal.temp_slope).tolist(),
        "scale": None if cal.scale is None else cal.scale.tolist(),
        **cal.quality,
    }
    return CalibrationRun(summary, inputs, rec, fit=cal)


def calibrate_accel(
    source: str | os.PathLike | Recording,
    output: str | os.PathLike,
    *,
    kind: str = "auto",
    gravity: float | None = None,
    latitude: float | None = None,
    height: float = 0.0,
    min_poses: int = 6,
    rest: dict[str, float] | None = None,
    append: bool = False,
    sensor: str | None = None,
    with_files: tuple[str, ...] = (),
    strict: bool = False,
    on_input: OnInput | None = None,
    stage: Stage | None = None,
    **load_options: Any,
) -> CalibrationRun:
    """Accelerometer ``f = T (f_meas − b)`` (b m/s²) from six or more static poses detected automatically;
    gravity (m/s²) given, else WGS-84 normal gravity at ``latitude`` (deg) and ``height`` (m), else 9.80665.
    Writes section ``[accel]`` of ``output``; the summary's ``gravity_m_s2`` is the value used."""
    from calibration.file import provenance, update_calibration
    from calibration.inertial import calibrate_accel as fit_accel
    from calibration.inertial import normal_gravity

    input_path = _source_name(source)
    check_toml_output(output, append)
    inputs: list[dict[str, Any]] = []
    rec = _read_for_fit(source, "accel", load_options, with_files, _noting(inputs, on_input), stage, strict)
    if gravity is None:
        gravity = normal_gravity(latitude, height) if latitude is not None else 9.80665
    gyro = rec.get("gyro", "rad/s") if "gyro" in rec.channels else None
    cal = fit_accel(
        rec.time,
        rec.get("accel", "m/s^2"),
        gyro,
        gravity=gravity,
        kind=kind,
        min_poses=min_poses,
        **(rest if rest is not None else rest_options()),
    )
    section = cal.to_section()
    section["provenance"] = provenance(
        input_path,
        f"accel many-position |g| fit ({cal.kind})",
        sensor or str(rec.meta.get("sensor", "")),
        cal.quality,
        latitude_deg=latitude,
    )
    update_calibration(output, "accel", section, append)
    summary = {
        "output": os.fspath(output),
        "kind": cal.kind,
        "gravity_m_s2": gravity,
        "bias_m_s2": cal.bias.tolist(),
        "bias_std_m_s2": cal.bias_std.tolist(),
        "T": cal.T.tolist(),
        **cal.quality,
    }
    return CalibrationRun(summary, inputs, rec, fit=cal)


def _meta_dict(value: Any) -> dict[str, Any]:
    """A metadata entry that is a table (a dict, or its JSON text as a CSV header carries it); else {}."""
    if isinstance(value, dict):
        return value
    if isinstance(value, str) and value.strip().startswith("{"):
        import json

        try:
            out = json.loads(value)
        except ValueError:
            return {}
        return out if isinstance(out, dict) else {}
    return {}


def calibrate_accel_bias(
    source: str | os.PathLike | Recording,
    output: str | os.PathLike,
    *,
    at: float | None = None,
    append: bool = False,
    sensor: str | None = None,
    strict: bool = False,
    on_input: OnInput | None = None,
    stage: Stage | None = None,
    **load_options: Any,
) -> CalibrationRun:
    """The accelerometer bias a GNSS-aided ``imutool filter`` run estimated (its output's ``accel_bias_x/y/z``, m/s²
    body FRD, at ``at`` s from the start, else at its last row) written as section ``[accel]`` of ``output``: the
    bias in sensor axes (a mounting the run applied is undone), T = I. Where the run's input was calibrated with an
    ``[accel]`` section (the output's metadata says so) the estimate is a residual: it is folded into that
    section, b ← b + T⁻¹ r, which needs ``append`` to that same file. Applied with ``--calibration``, the bias
    leaves the tilt of every estimator (the EKF alone carries b/g of it: 1 mg ≈ 0.057°)."""
    from calibration.file import load_calibration, provenance, update_calibration

    input_path = _source_name(source)
    check_toml_output(output, append)
    inputs: list[dict[str, Any]] = []
    _stage(stage, "reading")
    rec = load_for_fit(source, load_options, (), on_input=_noting(inputs, on_input), strict=strict)
    _stage(stage, "fitting")
    require_channels(rec, ["accel_bias"], input_path)
    ba = rec.get("accel_bias", "m/s^2") if rec.units.get("accel_bias") else rec["accel_bias"]
    sd = rec.channels.get("accel_bias_std")
    t = rec.time - rec.time[0]
    ok = np.flatnonzero(np.all(np.isfinite(ba), axis=1) & (t <= (np.inf if at is None else at)))
    if not ok.size:
        when = "" if at is None else f" up to {at} s"
        raise ImutoolError(f"no finite accel_bias row{when} (the aided filter did not run)", path=input_path)
    k = int(ok[-1])
    body = np.asarray(ba[k], dtype=float)
    std = np.asarray(sd[k], dtype=float) if sd is not None else np.full(3, np.nan)
    mount = _meta_dict(rec.meta.get("mounting"))
    c = np.asarray(mount.get("matrix_sensor_to_body", np.eye(3)), dtype=float)
    resid, resid_std = c.T @ body, np.abs(c.T) @ std  # body = C · sensor
    applied = [str(a) for a in _meta_dict(rec.meta.get("calibration")).get("applied", [])]
    fold = any(a.startswith("accel") for a in applied)
    note = ""
    if fold:
        old = load_calibration(output).sections.get("accel") if append and os.path.exists(output) else None
        if old is None:
            cal_file = _meta_dict(rec.meta.get("calibration")).get("file", "")
            raise ImutoolError(
                f"the filter run applied an [accel] calibration ({cal_file}): its estimate is a residual; append "
                "it to that file (--append -o that file) to fold it into the section",
                path=input_path,
            )
        tm = np.asarray(old.get("T", np.eye(3)), dtype=float)
        bias = np.asarray(old.get("bias", [0.0, 0.0, 0.0]), dtype=float) + np.linalg.solve(tm, resid)
        section = {**old, "bias": bias.tolist()}
        section.pop("provenance", None)
        note = "folded into the existing [accel] section: b + T⁻¹ r"
    else:
        tm = np.eye(3)
        bias = resid
        section = {"model": "f = T (f_meas - b)", "units": "b: m/s^2; T: 1", "kind": "offset", "T": tm.tolist()}
        section["bias"] = bias.tolist()
        if append and os.path.exists(output) and "accel" in load_calibration(output).sections:
            note = "replaced the file's [accel] section (the filter ran on uncalibrated accelerometer data)"
    section["bias_std"] = resid_std.tolist()
    quality = {"row_time_s": round(float(t[k]), 3), "estimate_body_m_s2": body.tolist()}
    if "aided" in rec.meta:
        quality["aided"] = str(rec.meta["aided"])[:500]
    section["provenance"] = provenance(
        input_path,
        "GNSS-aided filter's accelerometer-bias estimate",
        sensor or str(rec.meta.get("sensor", "")),
        quality,
    )
    update_calibration(output, "accel", section, append)
    summary = {
        "output": os.fspath(output),
        "row_time_s": round(float(t[k]), 3),
        "bias_m_s2": bias.tolist(),
        "bias_std_m_s2": resid_std.tolist(),
        "bias_mg": (bias / 9.80665e-3).tolist(),
        "mounting_undone": bool(mount),
        "folded": fold,
    }
    if note:
        summary["note"] = note
    return CalibrationRun(summary, inputs, rec, fit=None)


# -- deviation card --------------------------------------------------------------------------------------------
REF_NAMES = (
    "heading_mag",
    "ref_heading_mag",
    "heading",
    "ref_heading",
    "cog",
    "course",
    "bearing",
    "true_heading",
    "heading_true",
)
MAG_REFS = ("heading_mag", "ref_heading_mag")
CARD_KEYS = ("vessel", "compass", "place", "date", "latitude", "longitude", "conditions", "adjuster")
CARD_OUTPUTS = (".pdf", ".png", ".svg", ".toml", ".txt")


def _angle_interp(t: np.ndarray, ts: np.ndarray, a_deg: np.ndarray) -> np.ndarray:
    ok = np.isfinite(a_deg)
    ts, a = ts[ok], np.unwrap(np.radians(a_deg[ok]))
    out = np.degrees(np.interp(t, ts, a)) % 360.0
    out[(t < ts[0]) | (t > ts[-1])] = np.nan
    return out


def card_info(path: str | os.PathLike | None) -> dict[str, Any]:
    """Header fields of the card from a TOML file (keys: vessel, compass, place, date, latitude, longitude,
    conditions, adjuster; at the top level or in a [card] table)."""
    if not path:
        return {}
    import tomllib

    path = os.fspath(path)
    try:
        with open(path, "rb") as fh:
            d = tomllib.load(fh)
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise ImutoolError(f"--card-info: {e}", path=path) from None
    d = d.get("card", d)
    unknown = sorted(set(d) - set(CARD_KEYS))
    if unknown:
        raise ImutoolError(f"--card-info: unknown keys {', '.join(unknown)} (known: {', '.join(CARD_KEYS)})", path=path)
    return {k: (v.isoformat() if hasattr(v, "isoformat") else v) for k, v in d.items()}


def swing_date(date_opt: str | None, *recs: Any) -> Any:
    """Date of the swing: ``date_opt`` (YYYY-MM-DD), else the real time of a recording (metadata start time /
    Unix time axis); None when neither says."""
    from formats.nmea import utc_offset_s

    if date_opt:
        try:
            return date.fromisoformat(date_opt.strip()[:10])
        except ValueError:
            raise ImutoolError(f"--date {date_opt!r}: expected YYYY-MM-DD") from None
    for r in recs:
        if r is None or len(r) == 0:
            continue
        off = utc_offset_s(r)
        if off is not None:
            return datetime.fromtimestamp(float(r.time[0]) + off, tz=timezone.utc)
    return None


def deviation_card(
    source: str | os.PathLike | Recording,
    outputs: str | os.PathLike | tuple[str, ...] | list[str],
    *,
    reference: str | os.PathLike | None = None,
    reference_column: str | None = None,
    reference_kind: str = "auto",
    variation: float | None = None,
    position: str | None = None,
    date: str | None = None,
    vessel: str | None = None,
    compass: str | None = None,
    place: str | None = None,
    conditions: str | None = None,
    adjuster: str | None = None,
    info: str | os.PathLike | dict[str, Any] | None = None,
    max_deviation: float = 5.0,
    time_offset: float = 0.0,
    heading_column: str | None = None,
    min_speed: float = 2.0,
    min_span: float = 270.0,
    append: bool = True,
    sensor: str | None = None,
    with_files: tuple[str, ...] = (),
    strict: bool = False,
    on_input: OnInput | None = None,
    stage: Stage | None = None,
    **load_options: Any,
) -> CalibrationRun:
    """Deviation card δ(ψ) = A + B sinψ + C cosψ + D sin2ψ + E cos2ψ (deg; magnetic = compass + δ) from the
    compass heading of ``source`` (``heading_column``, else 'heading', else the tilt-compensated magnetometer)
    against reference headings (``reference`` file: NMEA HDT/THS/HDM..., or a CSV column; default a reference
    column of the input). The reference file is read as it is, or, given any of its own options (``ref_columns``
    ... ``ref_start``, :data:`imutool.loading.REF_LOAD_OPTIONS`), loaded with them as an input is (the summary's
    ``reference_loading`` says how).

    A true reference needs the ``variation`` (deg, E +), or a ``position`` ('LAT,LON'; default the first fix of
    an NMEA reference) and a ``date`` for the World Magnetic Model. ``time_offset`` s is added to the reference
    times; a GNSS course is used only at ``sog`` ≥ ``min_speed`` kn; compass headings covering less than
    ``min_span`` deg are refused. Header fields from ``info`` (dict or TOML path) overridden by the keywords.
    ``outputs`` (one or a list): .pdf/.png/.svg card plot, .txt text card, .toml section [deviation] (merged
    with ``append``).
    ``details`` of the result: compass_source, reference_source, reference_column, reference_kind, variation,
    variation_source.
    """
    from calibration.deviation import card_text, card_warnings, fit_deviation, plot_card
    from calibration.file import provenance, update_calibration
    from calibration.swing import heading_from_mag, roll_pitch_from_accel
    from calibration.wmm import parse_position, position_from_nmea, wmm_variation

    input_path = _source_name(source)
    reference = os.fspath(reference) if reference else None
    load_options, ref_given = split_reference_options(load_options)
    if ref_given and not reference:
        flags = ", ".join(sorted(reference_text(FLAGS[k]) for k in ref_given))
        raise ImutoolError(f"{flags}: say how to read a reference file; give the file with --reference")
    outputs = [os.fspath(outputs)] if isinstance(outputs, (str, os.PathLike)) else [os.fspath(o) for o in outputs]
    for o in outputs:
        if not o.lower().endswith(CARD_OUTPUTS):
            raise ImutoolError(
                f"output {o!r}: use .pdf/.png/.svg (card plot), .txt (text card) or .toml (calibration file)"
            )
    info = dict(info) if isinstance(info, dict) else card_info(info)
    _stage(stage, "reading")
    inputs: list[dict[str, Any]] = []
    noted = _noting(inputs, on_input)
    rec = load_for_fit(source, load_options, with_files, on_input=noted, strict=strict)  # mounting, mag cal. ok
    _stage(stage, "fitting")
    # compass heading
    if heading_column or "heading" in rec.channels:
        col = heading_column or "heading"
        require_channels(rec, [col], input_path)
        compass_hdg = np.asarray(rec[col], dtype=float) % 360.0
        src = f"column {col}"
    else:
        require_channels(rec, ["mag"], input_path)
        m = rec.get("mag", "uT")
        if "accel" in rec.channels:
            r, p = roll_pitch_from_accel(rec.get("accel", "m/s^2"))
            compass_hdg = heading_from_mag(m, r, p)
            src = "mag, tilt-compensated with accel"
        else:
            compass_hdg = heading_from_mag(m)
            src = "mag (assumed level)"
    # reference
    loaded = None
    if reference and ref_given:  # the reference's own options: loaded as an input is (time order kept by sorting)
        ref_rec = load_reference(
            reference, [], strict=strict, on_input=noted, duplicates="drop", backwards="sort", **ref_given
        )[0]
        loaded = how_loaded(ref_rec, ref_given, reference=True)
        rsrc = reference
    elif reference:
        ref_rec = formats.read(reference)
        rsrc = reference
    else:
        ref_rec, rsrc = rec, input_path
    if reference_column:
        names = [reference_column] if reference_column in ref_rec.channels else []
    else:
        own = heading_column or "heading"  # the compass column itself is no reference
        names = [n for n in REF_NAMES if n in ref_rec.channels and (reference or n != own)]
    if not names:
        raise ImutoolError(
            f"no reference heading column (looked for {reference_column or ', '.join(REF_NAMES)}; "
            f"has {', '.join(ref_rec.channels)})",
            path=rsrc,
        )
    rname = names[0]
    rvals = np.asarray(ref_rec[rname], dtype=float)
    rt = ref_rec.time + time_offset
    if "sog" in ref_rec.channels and rname in ("cog", "course"):
        rvals = np.where(np.asarray(ref_rec["sog"]) >= min_speed, rvals, np.nan)
    kind = reference_kind if reference_kind != "auto" else ("magnetic" if rname in MAG_REFS else "true")
    # position and date (header; WMM variation for a true reference)
    lat = lon = None
    pos_src = None
    if position:
        lat, lon = parse_position(position)
        pos_src = "--position"
    elif info.get("latitude") is not None and info.get("longitude") is not None:
        lat, lon = float(info["latitude"]), float(info["longitude"])
        pos_src = "--card-info"
    log_day = None
    for cand in ([reference] if reference else []) + [input_path]:
        if (
            cand
            and not cand.lower().endswith((".csv", ".parquet", ".bag", ".db3", ".mcap", ".toml"))
            and os.path.exists(cand)
        ):
            plat, plon, log_day = position_from_nmea(cand)
            if lat is None and plat is not None:
                lat, lon, pos_src = plat, plon, f"first fix in {os.path.basename(cand)}"
            break
    when = swing_date(date or info.get("date"), rec, ref_rec if reference else None) or log_day
    var_src = "given with --variation" if variation is not None else None
    notes: list[str] = []
    if kind == "true" and variation is None:
        if lat is None or when is None:
            miss = " and ".join(
                x
                for x, v in (
                    ("a position (--position LAT,LON or RMC/GGA in the reference log)", lat),
                    ("a date (--date)", when),
                )
                if v is None
            )
            raise ImutoolError(
                f"the reference {os.path.basename(rsrc)}:{rname} is TRUE heading: give --variation "
                f"(deg, E +), or {miss} for the World Magnetic Model — without it the card would "
                "carry the variation as deviation"
            )
        v = wmm_variation(lat, lon, when)
        variation = v.deg
        var_src = v.source()
        if v.warning:
            notes.append(v.warning)
    comp_ref = "true − variation" if kind == "true" else "magnetic"
    if ref_rec is rec:
        ref_at = rvals
        comp_at = compass_hdg
    elif np.count_nonzero(np.isfinite(rvals)) < len(rec) // 2:
        comp_at = _angle_interp(rt, rec.time, compass_hdg)  # sparse bearings: compass at the reference times
        ref_at = rvals
    else:
        comp_at = compass_hdg
        ref_at = _angle_interp(rec.time, rt, rvals)
    if kind == "true":
        ref_at = ref_at - variation
    card = fit_deviation(comp_at, ref_at, min_span_deg=min_span, limit_deg=max_deviation)
    card.warnings = notes + card_warnings(card, max_deviation)
    header = {
        **info,
        "vessel": vessel or info.get("vessel"),
        "compass": compass or info.get("compass"),
        "place": place or info.get("place"),
        "conditions": conditions or info.get("conditions"),
        "adjuster": adjuster or info.get("adjuster"),
        "date": (when.isoformat()[:10] if hasattr(when, "isoformat") else None),
        "latitude": lat,
        "longitude": lon,
        "position_source": pos_src,
        "variation": variation,
        "variation_source": var_src,
        "reference": f"{os.path.basename(rsrc)}:{rname} ({kind}; magnetic = {comp_ref}); compass from {src}",
    }
    card.header = {k: v for k, v in header.items() if v not in (None, "")}
    summary: dict[str, Any] = {
        "compass_heading": src,
        "reference": f"{rsrc}:{rname} ({kind})",
        "variation_deg": variation,
        "variation_source": var_src,
        "coefficients_deg": {n: round(float(getattr(card, n)), 4) for n in "ABCDE"},
        "std_deg": {k: round(v, 4) for k, v in card.std.items()},
        "residual_rms_deg": round(card.quality["residual_rms_deg"], 4),
        "max_abs_deviation_deg": round(card.max_abs_deg(), 3),
        "samples": card.quality["n"],
        "outputs": list(outputs),
        "header": card.header,
        "warnings": card.warnings,
        "card_15deg": [[p, round(d, 2)] for p, d, _ in card.table(15.0)],
    }
    if loaded is not None:
        summary["reference_loading"] = loaded
    if card.invertible():
        summary["magnetic_to_compass_15deg"] = [[m, round(p, 2)] for m, _, p in card.table_magnetic(15.0)]
    for o in outputs:
        if o.lower().endswith(".toml"):
            section = card.to_section()
            section["provenance"] = provenance(
                input_path,
                "deviation least squares",
                sensor or str(rec.meta.get("sensor", "")),
                card.quality,
                reference=f"{rsrc}:{rname} ({kind})",
                variation_deg=variation,
                variation_source=var_src,
                compass_heading=src,
            )
            update_calibration(o, "deviation", section, append)
        elif o.lower().endswith(".txt"):
            with atomic_path(o) as tmp:
                tmp.write_text(card_text(card), encoding="utf-8")
        else:
            ok = np.isfinite(comp_at) & np.isfinite(ref_at)
            plot_card(
                card,
                o,
                comp_at[ok],
                angle_diff_deg(ref_at[ok], comp_at[ok]),
                title=f"Deviation card — {card.header.get('vessel') or os.path.basename(input_path)}",
            )
    details = {
        "compass_source": src,
        "reference_source": rsrc,
        "reference_column": rname,
        "reference_kind": kind,
        "variation": variation,
        "variation_source": var_src,
    }
    return CalibrationRun(summary, inputs, rec, fit=card, details=details)


# -- show ----------------------------------------------------------------------------------------------------------
SHOW_FORMS = ("text", "c", "fusion", "matlab", "python", "json", "magneto")


def show_calibration(path: str | os.PathLike, form: str = "text") -> str:
    """A calibration file as text (``form='text'``: every section with its provenance, then the deviation card)
    or as paste-ready code (:data:`SHOW_FORMS`: C for x-io Fusion, MATLAB, Python/numpy, JSON, Magneto's
    printout); what ``imutool calibrate show`` prints."""
    from calibration.crosswalk import render
    from calibration.deviation import card_text
    from calibration.file import load_calibration

    path = os.fspath(path)
    cal = load_calibration(path)
    if form == "magneto":
        from calibration.magnetometer import crosswalk

        mg = cal.mag()
        if mg is None:
            raise ImutoolError("no [mag] section to convert", path=path)
        return crosswalk(mg[0], mg[1], form)
    if form != "text":
        return render(cal, form)
    lines = [f"calibration file {path}: sections {', '.join(cal.sections)}"]
    for name, sec in cal.sections.items():
        prov = sec.get("provenance", {})
        lines.append(f"[{name}] {sec.get('model', '')}")
        for k, v in sec.items():
            if k in ("provenance", "model", "card_15deg", "magnetic_to_compass_15deg", "header", "warnings"):
                continue
            lines.append(f"  {k} = {v}")
        if prov:
            lines.append(
                f"  provenance: {prov.get('method', '')}; {prov.get('input', '')} "
                f"sha256 {str(prov.get('input_sha256', ''))[:12]}…; {prov.get('date_utc', '')}; "
                f"sensor {prov.get('sensor', '') or '?'}"
            )
    dev = cal.deviation
    if dev is not None:
        lines += ["", card_text(dev)]
    return "\n".join(lines) + "\n"
