"""``imutool calibrate``: magnetometer (sphere or heading swing), deviation card, gyro, accelerometer, show."""

from __future__ import annotations

import os
from typing import Any

import click
import numpy as np

import formats
from formats.errors import ImutoolError
from imutool.cli.common import emit_summary, input_options, load_input, output_options, require_channels, safe_outputs

_IN_KEYS = ("columns", "profile", "topic", "stamp", "duplicates", "backwards", "mounting", "calibration_file")


def _load(path: str, opts: dict[str, Any], extra: tuple[str, ...] = (), fitting: str | None = None) -> Any:
    """Read INPUT (and --with files merged onto its clock; each read with the same foreign-CSV options).

    ``fitting``: the section being estimated. Its parameters are in sensor axes and relative to raw data, so
    --mounting and a --calibration file that already holds that section are refused."""
    if fitting and opts.get("mounting"):
        raise ImutoolError(f"{fitting} calibration parameters are in sensor axes: calibrate without --mounting "
                           "(store the mounting separately; it is applied after the calibration)")
    if fitting and opts.get("calibration_file"):
        from calibration.file import load_calibration

        if fitting in load_calibration(opts["calibration_file"]):
            raise ImutoolError(f"--calibration {opts['calibration_file']} already has a [{fitting}] section: "
                               f"the {fitting} fit needs raw data", path=opts["calibration_file"])
    rec, _ = load_input(path, **{k: opts.get(k) for k in _IN_KEYS if opts.get(k) is not None})
    if extra:
        others = []
        for p in extra:
            r, _ = load_input(p, **{k: opts.get(k) for k in _IN_KEYS if k not in ("columns",)
                                    and opts.get(k) is not None})
            others.append(r)
        src = rec.meta.get("source", path)
        rec = formats.merge([rec, *others], rec)
        rec.meta["source"] = src
    return rec


def _check_toml_out(output: str, append: bool = False) -> None:
    if not output.lower().endswith(".toml"):
        raise ImutoolError(f"the calibration file must be .toml: {output!r}")
    if append and os.path.exists(output):  # --append merges: the file must load cleanly before any work is done
        from calibration.file import load_calibration

        load_calibration(output)


def _with_option(f):
    return click.option("--with", "with_files", multiple=True, type=click.Path(exists=True),
                        help="Another file of the same run (e.g. the accelerometer CSV when each sensor has its "
                             "own file), merged onto INPUT's clock. Repeatable.")(f)


@click.group("calibrate", epilog="Example: imutool calibrate mag sphere.csv -o cal.toml --plot cal.png")
def calibrate_group() -> None:
    """Calibrate magnetometer (sphere or ship swing), deviation card, gyro and accelerometer.

    Results go into one TOML calibration file (sections mag, gyro, accel, deviation, mounting, each with
    provenance). Every command that reads sensor data applies it with --calibration cal.toml.
    Magnetometer model: m_true = A (m_meas − b), b hard iron (µT), A soft iron (symmetric).
    """


# -- mag -------------------------------------------------------------------------------------------------------
@calibrate_group.command("mag", epilog="Example: imutool calibrate mag sphere.csv -o cal.toml --plot cal.png   |   "
                                       "imutool calibrate mag swing.csv -o cal.toml --method swing")
@click.argument("input_path", metavar="INPUT")
@click.option("-o", "--output", required=True, help="Calibration file (.toml).")
@click.option("--method", type=click.Choice(["sphere", "swing"]), default="sphere", show_default=True,
              help="sphere: full 3-D rotations (bench); swing: the vessel turns in heading only (2-D fit).")
@click.option("--kind", type=click.Choice(["auto", "offset", "diag", "full"]), default="auto", show_default=True,
              help="Sphere fit: offset = hard iron only; diag = + axis scale; full = + symmetric soft iron; auto "
                   "= simplest within 5% of the best residual.")
@click.option("--field", "field_ut", type=float, default=None,
              help="Expected field strength (µT) to scale A; default: det A = 1 (volume preserving).")
@click.option("--min-coverage", type=float, default=None,
              help="Refuse below this sphere coverage (0–1); default offset 0.25, diag 0.45, full 0.60.")
@click.option("--grid-bands", type=int, default=8, show_default=True,
              help="Equal-area coverage grid: bands in z (× twice as many longitude sectors).")
@click.option("--horizontal-field", type=float, default=None,
              help="Swing: horizontal field (µT) to scale A; default det A_xy = 1.")
@click.option("--bz-prior", type=float, default=0.0, show_default=True,
              help="Swing: vertical hard iron (µT), unobservable in a swing.")
@click.option("--a33-prior", type=float, default=None,
              help="Swing: vertical soft-iron scale; default √det A_xy.")
@click.option("--plot", default=None, help="Before/after plot (.png/.pdf).")
@click.option("--append", is_flag=True, help="Merge into an existing calibration file (else a new file).")
@click.option("--sensor", default=None, help="Sensor id for the provenance (default: from the input metadata).")
@_with_option
@input_options
@output_options
@safe_outputs("output", "plot", append="append")
def mag_cmd(input_path: str, output: str, method: str, kind: str, field_ut: float | None,
            min_coverage: float | None, grid_bands: int, horizontal_field: float | None, bz_prior: float,
            a33_prior: float | None, plot: str | None, append: bool, sensor: str | None,
            with_files: tuple[str, ...], as_json: bool, quiet: bool, **io: Any) -> None:
    """Hard/soft-iron calibration of the magnetometer in INPUT."""
    from calibration.file import provenance, update_calibration

    _check_toml_out(output, append)
    steps = _steps(quiet)
    steps.stage("reading")
    rec = _load(input_path, io, with_files, fitting="mag")
    steps.stage("fitting")
    require_channels(rec, ["mag"], input_path)
    m = rec.get("mag", "uT")
    if method == "sphere":
        from calibration.magnetometer import calibrate_sphere

        fit = calibrate_sphere(m, kind, field_ut, min_coverage, grid_bands)
    else:
        from calibration.swing import calibrate_swing

        acc = rec.get("accel", "m/s^2") if "accel" in rec.channels else None
        fit = calibrate_swing(m, acc, horizontal_ut=horizontal_field, bz_prior=bz_prior, a33_prior=a33_prior)
    section = fit.to_section()
    section["provenance"] = provenance(input_path, f"mag {method} ({fit.kind})",
                                       sensor or str(rec.meta.get("sensor", "")), fit.quality(),
                                       with_files=list(with_files) or None)
    update_calibration(output, "mag", section, append)
    if plot:
        from calibration.magnetometer import plot_before_after

        plot_before_after(m, fit, plot, title=f"{os.path.basename(input_path)} ({method})")
    summary = {"output": output, "method": method, "kind": fit.kind, "reason": fit.reason,
               "model": "m_true = A (m_meas - b)", "b_uT": np.round(fit.b, 4).tolist(),
               "b_std_uT": [None if not np.isfinite(v) else round(float(v), 4) for v in fit.b_std],
               "A": np.round(fit.A, 5).tolist(),
               "field_uT": round(fit.field_ut, 3), "residual_rms_uT": round(fit.residual_rms_ut, 4),
               "coverage": round(fit.coverage, 3), "raw_field_rel_std_pct": round(100 * fit.raw_rel_std, 3),
               "calibrated_field_rel_std_pct": round(100 * fit.cal_rel_std, 3), "samples": fit.n,
               "warnings": fit.warnings}
    if method == "swing":
        summary["unobservable"] = fit.extra["section"]["unobservable"]
    lines = [f"mag calibration ({method}, kind {fit.kind}) → {output}", f"  {fit.reason}",
             "  model  m_true = A (m_meas − b)",
             f"  b (µT) = {np.array2string(fit.b, precision=3)} ± {np.array2string(fit.b_std, precision=3)}",
             "  A      = " + np.array2string(fit.A, precision=5).replace("\n", "\n           "),
             f"  field {fit.field_ut:.2f} µT, residual {fit.residual_rms_ut:.3g} µT RMS, coverage "
             f"{100 * fit.coverage:.0f}%",
             f"  {'|m|' if method == 'sphere' else 'horizontal |m_h|'} relative std: raw {100 * fit.raw_rel_std:.2f}%"
             f" → calibrated {100 * fit.cal_rel_std:.2f}%"]
    if method == "swing":
        lines.append(f"  not observable in a swing: {summary['unobservable']}")
    lines += [f"  warning: {w}" for w in fit.warnings]
    steps.close()
    emit_summary(summary, as_json, quiet, lines)


# -- deviation -------------------------------------------------------------------------------------------------
_REF_NAMES = ("heading_mag", "ref_heading_mag", "heading", "ref_heading", "cog", "course", "bearing", "true_heading",
              "heading_true")
_MAG_REFS = ("heading_mag", "ref_heading_mag")


def _angle_interp(t: np.ndarray, ts: np.ndarray, a_deg: np.ndarray) -> np.ndarray:
    ok = np.isfinite(a_deg)
    ts, a = ts[ok], np.unwrap(np.radians(a_deg[ok]))
    out = np.degrees(np.interp(t, ts, a)) % 360.0
    out[(t < ts[0]) | (t > ts[-1])] = np.nan
    return out


_CARD_KEYS = ("vessel", "compass", "place", "date", "latitude", "longitude", "conditions", "adjuster")


def _card_info(path: str | None) -> dict[str, Any]:
    """Header fields of the card from a TOML file (keys: vessel, compass, place, date, latitude, longitude,
    conditions, adjuster)."""
    if not path:
        return {}
    import tomllib

    try:
        with open(path, "rb") as fh:
            d = tomllib.load(fh)
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise ImutoolError(f"--card-info: {e}", path=path) from None
    d = d.get("card", d)
    unknown = sorted(set(d) - set(_CARD_KEYS))
    if unknown:
        raise ImutoolError(f"--card-info: unknown keys {', '.join(unknown)} (known: {', '.join(_CARD_KEYS)})",
                           path=path)
    return {k: (v.isoformat() if hasattr(v, "isoformat") else v) for k, v in d.items()}


def _swing_date(date_opt: str | None, *recs: Any) -> Any:
    """Date of the swing: --date, else the real time of a recording (metadata start time / Unix time axis)."""
    from datetime import date, datetime, timezone

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


@calibrate_group.command("deviation", epilog="Example: imutool calibrate deviation swing.csv --reference gnss.nmea "
                                             "-o card.pdf -o card.txt -o cal.toml --vessel 'MV Aurora'")
@click.argument("input_path", metavar="INPUT")
@click.option("-o", "--output", "outputs", multiple=True, required=True,
              help="Card (.pdf/.png/.svg plot + text; .txt text card) and/or calibration file (.toml, section "
                   "[deviation]). Repeatable.")
@click.option("--reference", default=None, type=click.Path(exists=True),
              help="Reference headings: NMEA log (HDT/THS/HDM...), CSV (heading, cog or bearing column). "
                   "Default: a reference column of INPUT (ref_heading).")
@click.option("--reference-column", default=None,
              help=f"Column with the reference heading (deg); default the first of {', '.join(_REF_NAMES)}.")
@click.option("--reference-kind", type=click.Choice(["auto", "true", "magnetic"]), default="auto",
              show_default=True, help="Whether the reference is true or magnetic heading (auto: magnetic for "
                                      "heading_mag / ref_heading_mag, else true).")
@click.option("--variation", type=float, default=None,
              help="Magnetic variation (declination), deg, east positive: magnetic = true − variation. A true "
                   "reference without it is refused unless --position (or a position in the reference log) and "
                   "a date give it from the World Magnetic Model (needs imutool[wmm]).")
@click.option("--position", default=None, metavar="LAT,LON",
              help="Where the swing was done (decimal deg, N/E +): latitude for the card, and the WMM variation "
                   "when --variation is not given. Default: first RMC/GGA fix of the reference log.")
@click.option("--date", "date_opt", default=None, metavar="YYYY-MM-DD",
              help="Date of the swing (card header, WMM). Default: the recording's real start time.")
@click.option("--vessel", default=None, help="Card header: vessel name.")
@click.option("--compass", "compass_name", default=None, help="Card header: compass (make, model, serial).")
@click.option("--place", default=None, help="Card header: place of the swing.")
@click.option("--conditions", default=None, help="Card header: swing conditions (loading, trim, heel, weather...).")
@click.option("--adjuster", default=None, help="Card header: compass adjuster's name (the card keeps a signature "
                                                "line).")
@click.option("--card-info", default=None, type=click.Path(exists=True, dir_okay=False),
              help="TOML with the header fields (vessel, compass, place, date, latitude, longitude, conditions, "
                   "adjuster); options override it.")
@click.option("--max-deviation", type=float, default=5.0, show_default=True,
              help="Warn above this |deviation| (deg): compass to be adjusted (ISO 25862 as quoted: 5° in service).")
@click.option("--time-offset", type=float, default=0.0, show_default=True,
              help="Seconds added to the reference times to align them with INPUT.")
@click.option("--heading-column", default=None,
              help="Compass heading column of INPUT (deg); default: 'heading' if present, else from mag (+ accel "
                   "tilt compensation, after --calibration).")
@click.option("--min-speed", type=float, default=2.0, show_default=True,
              help="With a GNSS course-over-ground reference and a 'sog' column (kn): use rows at or above this.")
@click.option("--min-span", type=float, default=270.0, show_default=True,
              help="Refuse if the compass headings cover less of the circle (deg). Whatever it says, headings "
                   "that cannot separate the A–E harmonics are refused.")
@click.option("--append/--new", default=True, show_default=True,
              help="Merge [deviation] into an existing .toml (or write a new one).")
@click.option("--sensor", default=None, help="Sensor id for the provenance.")
@_with_option
@input_options
@output_options
@safe_outputs("outputs", append="append")
def deviation_cmd(input_path: str, outputs: tuple[str, ...], reference: str | None, reference_column: str | None,
                  reference_kind: str, variation: float | None, position: str | None, date_opt: str | None,
                  vessel: str | None, compass_name: str | None, place: str | None, conditions: str | None,
                  adjuster: str | None, card_info: str | None, max_deviation: float, time_offset: float,
                  heading_column: str | None, min_speed: float, min_span: float, append: bool, sensor: str | None,
                  with_files: tuple[str, ...], as_json: bool, quiet: bool, **io: Any) -> None:
    """Deviation card δ(ψ) = A + B sinψ + C cosψ + D sin2ψ + E cos2ψ from compass vs reference headings.

    The card: header (vessel, compass, place, date, latitude, variation, reference, conditions), coefficients
    and both tables at 15° (compass → magnetic; magnetic → compass, the course to steer) in E/W notation,
    residuals per heading, warnings, adjuster's signature line.
    """
    from calibration.deviation import card_text, card_warnings, ew, fit_deviation, plot_card
    from calibration.file import provenance, update_calibration
    from calibration.swing import heading_from_mag, roll_pitch_from_accel
    from calibration.wmm import parse_position, position_from_nmea, wmm_variation
    from formats.atomic import atomic_path
    from formats.frames import wrap_deg180

    for o in outputs:
        if not o.lower().endswith((".pdf", ".png", ".svg", ".toml", ".txt")):
            raise ImutoolError(f"output {o!r}: use .pdf/.png/.svg (card plot), .txt (text card) or .toml "
                               "(calibration file)")
    info = _card_info(card_info)
    steps = _steps(quiet)
    steps.stage("reading")
    rec = _load(input_path, io, with_files)  # mounting and a mag calibration are welcome here
    steps.stage("fitting")
    # compass heading
    if heading_column or "heading" in rec.channels:
        col = heading_column or "heading"
        require_channels(rec, [col], input_path)
        compass = np.asarray(rec[col], dtype=float) % 360.0
        src = f"column {col}"
    else:
        require_channels(rec, ["mag"], input_path)
        m = rec.get("mag", "uT")
        if "accel" in rec.channels:
            r, p = roll_pitch_from_accel(rec.get("accel", "m/s^2"))
            compass = heading_from_mag(m, r, p)
            src = "mag, tilt-compensated with accel"
        else:
            compass = heading_from_mag(m)
            src = "mag (assumed level)"
    # reference
    if reference:
        ref_rec = formats.read(reference)
        rsrc = reference
    else:
        ref_rec, rsrc = rec, input_path
    if reference_column:
        names = [reference_column] if reference_column in ref_rec.channels else []
    else:
        own = heading_column or "heading"  # the compass column itself is no reference
        names = [n for n in _REF_NAMES if n in ref_rec.channels and (reference or n != own)]
    if not names:
        raise ImutoolError(f"no reference heading column (looked for {reference_column or ', '.join(_REF_NAMES)}; "
                           f"has {', '.join(ref_rec.channels)})", path=rsrc)
    rname = names[0]
    rvals = np.asarray(ref_rec[rname], dtype=float)
    rt = ref_rec.time + time_offset
    if "sog" in ref_rec.channels and rname in ("cog", "course"):
        rvals = np.where(np.asarray(ref_rec["sog"]) >= min_speed, rvals, np.nan)
    kind = reference_kind if reference_kind != "auto" else ("magnetic" if rname in _MAG_REFS else "true")
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
        if cand and not cand.lower().endswith((".csv", ".parquet", ".bag", ".db3", ".mcap", ".toml")):
            plat, plon, log_day = position_from_nmea(cand)
            if lat is None and plat is not None:
                lat, lon, pos_src = plat, plon, f"first fix in {os.path.basename(cand)}"
            break
    when = _swing_date(date_opt or info.get("date"), rec, ref_rec if reference else None) or log_day
    var_src = "given with --variation" if variation is not None else None
    notes: list[str] = []
    if kind == "true" and variation is None:
        if lat is None or when is None:
            miss = " and ".join(x for x, v in (("a position (--position LAT,LON or RMC/GGA in the reference "
                                                "log)", lat), ("a date (--date)", when)) if v is None)
            raise ImutoolError(f"the reference {os.path.basename(rsrc)}:{rname} is TRUE heading: give --variation "
                               f"(deg, E +), or {miss} for the World Magnetic Model — without it the card would "
                               "carry the variation as deviation")
        v = wmm_variation(lat, lon, when)
        variation = v.deg
        var_src = v.source()
        if v.warning:
            notes.append(v.warning)
    if kind == "true":
        comp_ref = "true − variation"
    else:
        comp_ref = "magnetic"
    if ref_rec is rec:
        ref_at = rvals
        comp_at = compass
    elif np.count_nonzero(np.isfinite(rvals)) < len(rec) // 2:
        comp_at = _angle_interp(rt, rec.time, compass)  # sparse bearings: compass at the reference times
        ref_at = rvals
    else:
        comp_at = compass
        ref_at = _angle_interp(rec.time, rt, rvals)
    if kind == "true":
        ref_at = ref_at - variation
    card = fit_deviation(comp_at, ref_at, min_span_deg=min_span, limit_deg=max_deviation)
    card.warnings = notes + card_warnings(card, max_deviation)
    header = {**info, "vessel": vessel or info.get("vessel"), "compass": compass_name or info.get("compass"),
              "place": place or info.get("place"), "conditions": conditions or info.get("conditions"),
              "adjuster": adjuster or info.get("adjuster"),
              "date": (when.isoformat()[:10] if hasattr(when, "isoformat") else None),
              "latitude": lat, "longitude": lon, "position_source": pos_src,
              "variation": variation, "variation_source": var_src,
              "reference": f"{os.path.basename(rsrc)}:{rname} ({kind}; magnetic = {comp_ref}); compass from {src}"}
    card.header = {k: v for k, v in header.items() if v not in (None, "")}
    summary: dict[str, Any] = {"compass_heading": src, "reference": f"{rsrc}:{rname} ({kind})",
                               "variation_deg": variation, "variation_source": var_src,
                               "coefficients_deg": {n: round(float(getattr(card, n)), 4) for n in "ABCDE"},
                               "std_deg": {k: round(v, 4) for k, v in card.std.items()},
                               "residual_rms_deg": round(card.quality["residual_rms_deg"], 4),
                               "max_abs_deviation_deg": round(card.max_abs_deg(), 3),
                               "samples": card.quality["n"], "outputs": list(outputs), "header": card.header,
                               "warnings": card.warnings,
                               "card_15deg": [[p, round(d, 2)] for p, d, _ in card.table(15.0)]}
    if card.invertible():
        summary["magnetic_to_compass_15deg"] = [[m, round(p, 2)] for m, _, p in card.table_magnetic(15.0)]
    for o in outputs:
        if o.lower().endswith(".toml"):
            section = card.to_section()
            section["provenance"] = provenance(input_path, "deviation least squares", sensor or
                                               str(rec.meta.get("sensor", "")), card.quality,
                                               reference=f"{rsrc}:{rname} ({kind})", variation_deg=variation,
                                               variation_source=var_src, compass_heading=src)
            update_calibration(o, "deviation", section, append)
        elif o.lower().endswith(".txt"):
            with atomic_path(o) as tmp:
                tmp.write_text(card_text(card), encoding="utf-8")
        else:
            ok = np.isfinite(comp_at) & np.isfinite(ref_at)
            plot_card(card, o, comp_at[ok], wrap_deg180(ref_at[ok] - comp_at[ok]),
                      title=f"Deviation card — {card.header.get('vessel') or os.path.basename(input_path)}")
    lines = [f"deviation card ({card.quality['n']} samples; compass from {src}; reference {rsrc}:{rname}, {kind})",
             "  δ(ψ) = A + B sinψ + C cosψ + D sin2ψ + E cos2ψ   (magnetic = compass + δ; E add, W subtract)",
             "  " + "  ".join(f"{n} = {ew(getattr(card, n), 2)} ± {card.std.get(n, float('nan')):.2f}°"
                              for n in "ABCDE")]
    if kind == "true":
        lines.append(f"  variation {ew(variation, 2)} ({var_src})")
    lines += [f"  residual {card.quality['residual_rms_deg']:.3f}° RMS, max {card.quality['residual_max_deg']:.2f}°; "
              f"largest deviation {card.max_abs_deg():.1f}°", "  compass → deviation:"]
    tab = card.table(15.0)
    for i in range(0, len(tab), 6):
        lines.append("   " + "  ".join(f"{p:03.0f}° {ew(d):>7s}" for p, d, _ in tab[i:i + 6]))
    if card.invertible():
        lines.append("  magnetic → compass (course to steer):")
        tm = card.table_magnetic(15.0)
        for i in range(0, len(tm), 6):
            lines.append("   " + "  ".join(f"{m:03.0f}°→{p:05.1f}°" for m, _, p in tm[i:i + 6]))
    lines.append(f"  written: {', '.join(outputs)}")
    for w in card.warnings:
        click.echo(f"warning: {w}", err=True)
    steps.close()
    emit_summary(summary, as_json, quiet, lines)


def _steps(quiet: bool):
    """Progress on stderr (interactive only): reading, fitting (+ writing)."""
    from imutool.progress import stages

    return stages("calibrate", ["reading", "fitting"], quiet)


# -- gyro ------------------------------------------------------------------------------------------------------
def _rest_options(f):
    opts = [
        click.option("--window", "window_s", type=float, default=1.0, show_default=True,
                     help="Rest detection: moving-std window (s)."),
        click.option("--gyro-std", "gyro_std_deg", type=float, default=0.5, show_default=True,
                     help="Rest detection: gyro moving std below this (deg/s)."),
        click.option("--accel-std", type=float, default=0.1, show_default=True,
                     help="Rest detection: accel moving std below this (m/s²)."),
        click.option("--min-rest", "min_rest_s", type=float, default=2.0, show_default=True,
                     help="Rest detection: shortest rest interval kept (s)."),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def _rest_kw(window_s: float, gyro_std_deg: float, accel_std: float, min_rest_s: float) -> dict[str, float]:
    return {"window_s": window_s, "gyro_std": float(np.radians(gyro_std_deg)), "accel_std": accel_std,
            "min_rest_s": min_rest_s}


@calibrate_group.command("gyro", epilog="Example: imutool calibrate gyro static.csv -o cal.toml --append")
@click.argument("input_path", metavar="INPUT")
@click.option("-o", "--output", required=True, help="Calibration file (.toml).")
@click.option("--turns-deg", type=float, default=None,
              help="Each motion between rests is a turn of this many degrees about one axis: fit scale and "
                   "misalignment (needs turns about all three axes).")
@click.option("--min-temp-range", type=float, default=1.0, show_default=True,
              help="Fit a temperature slope only if the rest samples span this many °C.")
@_rest_options
@click.option("--append", is_flag=True, help="Merge into an existing calibration file (else a new file).")
@click.option("--sensor", default=None, help="Sensor id for the provenance.")
@_with_option
@input_options
@output_options
@safe_outputs("output", append="append")
def gyro_cmd(input_path: str, output: str, turns_deg: float | None, min_temp_range: float, window_s: float,
             gyro_std_deg: float, accel_std: float, min_rest_s: float, append: bool, sensor: str | None,
             with_files: tuple[str, ...], as_json: bool, quiet: bool, **io: Any) -> None:
    """Gyro bias over automatically detected rest intervals (+ temperature slope, + scale from known turns)."""
    from calibration.file import provenance, update_calibration
    from calibration.inertial import calibrate_gyro

    _check_toml_out(output, append)
    steps = _steps(quiet)
    steps.stage("reading")
    rec = _load(input_path, io, with_files, fitting="gyro")
    steps.stage("fitting")
    require_channels(rec, ["gyro"], input_path)
    acc = rec.get("accel", "m/s^2") if "accel" in rec.channels else None
    temp = rec["temp"] if "temp" in rec.channels else None
    cal = calibrate_gyro(rec.time, rec.get("gyro", "rad/s"), acc, temp, min_temp_range=min_temp_range,
                         turns_deg=turns_deg, **_rest_kw(window_s, gyro_std_deg, accel_std, min_rest_s))
    section = cal.to_section()
    section["provenance"] = provenance(input_path, "gyro static bias over rest intervals"
                                       + (" + temperature slope" if cal.temp_slope is not None else "")
                                       + (" + scale from turns" if cal.scale is not None else ""),
                                       sensor or str(rec.meta.get("sensor", "")), cal.quality)
    update_calibration(output, "gyro", section, append)
    summary = {"output": output, "bias_rad_s": cal.bias.tolist(), "bias_deg_s": np.degrees(cal.bias).tolist(),
               "temp_slope_deg_s_per_degC": None if cal.temp_slope is None else np.degrees(cal.temp_slope).tolist(),
               "scale": None if cal.scale is None else cal.scale.tolist(), **cal.quality}
    lines = [f"gyro calibration → {output}",
             f"  rest: {cal.n_rest} intervals, {cal.rest_s:.1f} s",
             f"  bias (deg/s) = {np.array2string(np.degrees(cal.bias), precision=4)}"]
    if cal.temp_slope is not None:
        lines.append(f"  temperature slope (deg/s/°C) = {np.array2string(np.degrees(cal.temp_slope), precision=5)}"
                     f" about {cal.temp_ref:.2f} °C")
    elif "temp_note" in cal.quality:
        lines.append(f"  {cal.quality['temp_note']}")
    if cal.scale is not None:
        lines.append("  S = " + np.array2string(cal.scale, precision=5).replace("\n", "\n      "))
    steps.close()
    emit_summary(summary, as_json, quiet, lines)


# -- accel -----------------------------------------------------------------------------------------------------
@calibrate_group.command("accel", epilog="Example: imutool calibrate accel sixpos.csv -o cal.toml --append "
                                         "--latitude 59.4")
@click.argument("input_path", metavar="INPUT")
@click.option("-o", "--output", required=True, help="Calibration file (.toml).")
@click.option("--kind", type=click.Choice(["auto", "offset", "diag", "full"]), default="auto", show_default=True,
              help="offset: bias; diag: + scale; full: + misalignment (≥ 9 poses); auto by pose count.")
@click.option("--gravity", type=float, default=None, help="Local gravity (m/s²); default from --latitude.")
@click.option("--latitude", type=float, default=None,
              help="Latitude (deg) for WGS-84 normal gravity; default: standard gravity 9.80665.")
@click.option("--height", type=float, default=0.0, show_default=True, help="Height (m) for the gravity formula.")
@click.option("--min-poses", type=int, default=6, show_default=True, help="Fewest distinct static poses accepted.")
@_rest_options
@click.option("--append", is_flag=True, help="Merge into an existing calibration file (else a new file).")
@click.option("--sensor", default=None, help="Sensor id for the provenance.")
@_with_option
@input_options
@output_options
@safe_outputs("output", append="append")
def accel_cmd(input_path: str, output: str, kind: str, gravity: float | None, latitude: float | None, height: float,
              min_poses: int, window_s: float, gyro_std_deg: float, accel_std: float, min_rest_s: float,
              append: bool, sensor: str | None, with_files: tuple[str, ...], as_json: bool, quiet: bool,
              **io: Any) -> None:
    """Accelerometer bias, scale and misalignment from six or more static poses (detected automatically)."""
    from calibration.file import provenance, update_calibration
    from calibration.inertial import calibrate_accel, normal_gravity

    _check_toml_out(output, append)
    steps = _steps(quiet)
    steps.stage("reading")
    rec = _load(input_path, io, with_files, fitting="accel")
    steps.stage("fitting")
    require_channels(rec, ["accel"], input_path)
    if gravity is None:
        gravity = normal_gravity(latitude, height) if latitude is not None else 9.80665
    gyro = rec.get("gyro", "rad/s") if "gyro" in rec.channels else None
    cal = calibrate_accel(rec.time, rec.get("accel", "m/s^2"), gyro, gravity=gravity, kind=kind,
                          min_poses=min_poses, **_rest_kw(window_s, gyro_std_deg, accel_std, min_rest_s))
    section = cal.to_section()
    section["provenance"] = provenance(input_path, f"accel many-position |g| fit ({cal.kind})",
                                       sensor or str(rec.meta.get("sensor", "")), cal.quality,
                                       latitude_deg=latitude)
    update_calibration(output, "accel", section, append)
    summary = {"output": output, "kind": cal.kind, "gravity_m_s2": gravity, "bias_m_s2": cal.bias.tolist(),
               "bias_std_m_s2": cal.bias_std.tolist(), "T": cal.T.tolist(), **cal.quality}
    lines = [f"accel calibration ({cal.kind}, {cal.quality['poses']} poses, g = {gravity:.5f} m/s²) → {output}",
             "  model f = T (f_meas − b)",
             f"  b (m/s²) = {np.array2string(cal.bias, precision=4)} ± {np.array2string(cal.bias_std, precision=4)}",
             "  T = " + np.array2string(cal.T, precision=5).replace("\n", "\n      "),
             f"  residual {cal.residual_rms:.4g} m/s² RMS over the poses"]
    if "note" in cal.quality:
        lines.append(f"  note: {cal.quality['note']}")
    steps.close()
    emit_summary(summary, as_json, quiet, lines)


# -- show ------------------------------------------------------------------------------------------------------
@calibrate_group.command("show", epilog="Example: imutool calibrate show cal.toml --as c > cal.h")
@click.argument("path", metavar="CAL.toml", type=click.Path(exists=True, dir_okay=False))
@click.option("--as", "form", type=click.Choice(["text", "c", "fusion", "matlab", "python", "json", "magneto"]),
              default="text", show_default=True,
              help="text: the file and the deviation card; c (= fusion): x-io Fusion C; matlab: magcal A, b, "
                   "expmfs; python: numpy; json: every section; magneto: Magneto's printout. Code forms paste and "
                   "compile/run as printed.")
def show_cmd(path: str, form: str) -> None:
    """Print a calibration file, or paste-ready code: C (x-io Fusion), MATLAB, Python/numpy, JSON, Magneto."""
    from calibration.crosswalk import render
    from calibration.deviation import card_text
    from calibration.file import load_calibration

    cal = load_calibration(path)
    if form == "magneto":
        from calibration.magnetometer import crosswalk

        mg = cal.mag()
        if mg is None:
            raise ImutoolError("no [mag] section to convert", path=path)
        click.echo(crosswalk(mg[0], mg[1], form), nl=False)
        return
    if form != "text":
        click.echo(render(cal, form), nl=False)
        return
    click.echo(f"calibration file {path}: sections {', '.join(cal.sections)}")
    for name, sec in cal.sections.items():
        prov = sec.get("provenance", {})
        click.echo(f"[{name}] {sec.get('model', '')}")
        for k, v in sec.items():
            if k in ("provenance", "model", "card_15deg", "magnetic_to_compass_15deg", "header", "warnings"):
                continue
            click.echo(f"  {k} = {v}")
        if prov:
            click.echo(f"  provenance: {prov.get('method', '')}; {prov.get('input', '')} "
                       f"sha256 {str(prov.get('input_sha256', ''))[:12]}…; {prov.get('date_utc', '')}; "
                       f"sensor {prov.get('sensor', '') or '?'}")
    dev = cal.deviation
    if dev is not None:
        click.echo("")
        click.echo(card_text(dev))
