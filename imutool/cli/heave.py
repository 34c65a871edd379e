"""`imutool heave IN -o OUT`: real-time and delayed heave (m, positive up) from acceleration."""

from __future__ import annotations

import click

import formats
from formats.errors import ImutoolError
from imutool.cli.common import emit_summary, input_options, load_input, output_options, parse_vector, safe_outputs


@click.command("heave", epilog="Example: imutool simulate sea-state -o sea.csv && imutool heave sea.csv -o heave.csv")
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True))
@click.option("-o", "--output", required=True, type=click.Path(), help="Output (.csv, ...): heave m positive UP.")
@click.option(
    "--method",
    type=click.Choice(["realtime", "harmonic", "paper", "bandpass", "envelope"]),
    default="realtime",
    show_default=True,
    help="realtime: phase-corrected double-integrator bank (harmonic KF on line spectra); harmonic: KF "
    "observer with per-harmonic phase cancellation; paper: the heave paper's KF multi-step observer; "
    "bandpass: causal HPₙ/s² baseline; envelope: the 'traditional' envelope detrend (offline).",
)
@click.option("--harmonics", type=int, default=None, help="Oscillators in the KF model [default 3 paper, 5 realtime].")
@click.option(
    "--vertical",
    default=None,
    metavar="COL[,COL]",
    help="Single vertical accelerometer column(s), averaged (e.g. ACC_Heave_SB,ACC_HEAVE_PS). "
    "Default: 3-axis accel rotated to NED with the attitude.",
)
@click.option(
    "--vertical-sign",
    type=click.Choice(["up", "down"]),
    default="up",
    show_default=True,
    help="Where the --vertical accelerometers' positive axis points.",
)
@click.option(
    "--attitude",
    type=click.Choice(["auto", "q", "ekf", "tilt", "ref"]),
    default="auto",
    show_default=True,
    help="Vertical from: q columns (auto if present), the attitude EKF, a "
    "complementary tilt filter, or ref_q truth (testing only).",
)
@click.option(
    "--tilt-gain",
    type=float,
    default=0.07,
    show_default=True,
    help="Tilt filter gain (1/s); its gyro-bias integral gain is gain²/4 (critically damped).",
)
@click.option(
    "--lever-arm",
    default=None,
    metavar="X,Y,Z",
    help="Monitoring point relative to the IMU, m body FRD (x bow, y starboard, z down).",
)
@click.option("--cutoff", type=float, default=None, help="Causal band-pass cut-off Hz [default 0.2 × dominant].")
@click.option(
    "--cutoff-ratio",
    type=float,
    default=None,
    help="Corner as a fraction of the tracked heave frequency [default 0.2; realtime: its tuned value].",
)
@click.option(
    "--order",
    type=int,
    default=None,
    help="High-pass order (≥ 3) [default 3; realtime: the corrected integrator's tuned order ≥ 4].",
)
@click.option(
    "--delayed-cutoff",
    type=float,
    default=None,
    help="Zero-phase delayed heave cut-off Hz [default 0.35 × record dominant frequency].",
)
@click.option(
    "--window",
    "window_s",
    type=float,
    default=None,
    help="Frequency-tracking window (s) [default 240 realtime, 120 the KF methods].",
)
@click.option("--hop", "hop_s", type=float, default=10.0, show_default=True, help="Tracking update interval (s).")
@click.option(
    "--min-window",
    "min_window_s",
    type=float,
    default=10.0,
    show_default=True,
    help="Data (s) before the first frequency estimate.",
)
@click.option("--fmin", type=float, default=0.03, show_default=True, help="Lowest heave frequency considered (Hz).")
@click.option("--fmax", type=float, default=2.0, show_default=True, help="Highest heave frequency considered (Hz).")
@click.option(
    "--bandwidth",
    type=float,
    default=0.03,
    show_default=True,
    help="KF process noise as the oscillators' relative bandwidth.",
)
@click.option(
    "--meas-noise",
    type=float,
    default=0.002,
    show_default=True,
    help="KF measurement noise as a fraction of the displacement std.",
)
@click.option(
    "--residual-noise",
    type=float,
    default=0.02,
    show_default=True,
    help="Residual Δh random walk (fraction of std per √s).",
)
@click.option(
    "--nmea",
    "nmea_path",
    default=None,
    type=click.Path(),
    help="Also write heave sentences here ($PASHR and/or TSS1, see --nmea-sentences); settling rows are "
    "flagged (PASHR IMU status 0, empty heave; TSS1 lower-case status).",
)
@click.option(
    "--nmea-sentences",
    default="PASHR",
    show_default=True,
    help="PASHR and/or TSS1 (TSS1 needs roll/pitch columns in INPUT, e.g. an imutool filter output).",
)
@click.option(
    "--nmea-rate",
    type=float,
    default=None,
    help="NMEA output rate (Hz); default: the highest standard rate that fits --nmea-baud.",
)
@click.option(
    "--nmea-baud", type=int, default=4800, show_default=True, help="Line speed the NMEA output must fit (8N1)."
)
@click.option(
    "--heave-positive",
    type=click.Choice(["up", "down"]),
    default="up",
    show_default=True,
    help="Sign of heave in every output (CSV columns and NMEA): up (imutool, TSS1, Applanix) or down "
    "(SBG, Kongsberg native). Written into each output's header.",
)
@input_options
@output_options
@safe_outputs("output", "nmea_path")
def heave_cmd(
    input_path: str,
    output: str,
    method: str,
    harmonics: int | None,
    vertical: str | None,
    vertical_sign: str,
    attitude: str,
    tilt_gain: float,
    lever_arm: str | None,
    cutoff: float | None,
    cutoff_ratio: float | None,
    order: int | None,
    delayed_cutoff: float | None,
    window_s: float | None,
    hop_s: float,
    min_window_s: float,
    fmin: float,
    fmax: float,
    bandwidth: float,
    meas_noise: float,
    residual_noise: float,
    nmea_path: str | None,
    nmea_sentences: str,
    nmea_rate: float | None,
    nmea_baud: int,
    heave_positive: str,
    as_json: bool,
    quiet: bool,
    **inopts,
) -> None:
    """Heave (m, positive UP), heave rate, dominant period, settled flag and a delayed zero-phase heave."""
    from imutool.heave import heave_recording
    from imutool.progress import stages

    steps = stages("heave", ["reading", "heave", "writing"], quiet)
    steps.stage("reading")
    rec, _ = load_input(input_path, **inopts)
    cols = None
    if vertical:
        cols = []
        for c in vertical.split(","):
            c = c.strip()
            name = c if c in rec.channels else c.lower() if c.lower() in rec.channels else c
            cols.append(name)
    arm = parse_vector(lever_arm, 3, "--lever-arm") if lever_arm else None
    att = "auto" if attitude == "auto" else attitude
    if att == "tilt":
        att = "tiltonly"
    steps.stage(f"heave ({method})")
    out, summary = heave_recording(
        rec,
        method=method,
        vertical=cols,
        vertical_sign=vertical_sign,
        attitude=att,
        lever_arm=arm,
        tilt_gain=tilt_gain,
        harmonics=harmonics,
        cutoff=cutoff,
        cutoff_ratio=cutoff_ratio,
        order=order,
        delayed_cutoff=delayed_cutoff,
        window_s=window_s,
        hop_s=hop_s,
        min_window_s=min_window_s,
        fmin=fmin,
        fmax=fmax,
        bandwidth=bandwidth,
        meas_noise=meas_noise,
        residual_noise=residual_noise,
    )
    nmea_info = None
    if nmea_path:
        from imutool.nmea_out import write_log

        sents = [x.strip().upper() for x in nmea_sentences.split(",") if x.strip()]
        bad = [x for x in sents if x not in ("PASHR", "TSS1")]
        if bad:
            raise ImutoolError(f"--nmea-sentences: {', '.join(bad)} not heave sentences (PASHR, TSS1)")
        nrec = out.copy()
        for name in ("roll", "pitch", "heading", "heading_true", "sog", "cog", "lat", "lon"):
            if name in rec.channels and name not in nrec.channels:
                nrec.add(name, rec[name], rec.units.get(name))
        for key in ("start_utc", "utc_start", "start_time_utc", "scenario", "sensor"):
            if rec.meta.get(key) and key not in nrec.meta:
                nrec.meta[key] = rec.meta[key]
        nmea_info = write_log(
            nrec,
            nmea_path,
            sents,
            rate_hz=nmea_rate,
            baud=nmea_baud,
            source=input_path,
            heave_positive=heave_positive,
            heading_ref="true",
        )
    if heave_positive == "down":  # every heave column flips; the header says so
        for name in ("heave", "heave_delayed", "heave_rate", "heave_rate_delayed", "ref_heave", "ref_heave_rate"):
            if name in out.channels:
                out.add(name, -out[name], out.units.get(name))
        out.meta["heave_positive"] = "down"
        out.meta["heave"] = str(out.meta.get("heave", "m")).replace("positive UP", "positive DOWN")
    else:
        out.meta["heave_positive"] = "up"
    steps.stage("writing")
    formats.write(out, output)
    steps.close()
    summary = {"input": input_path, "output": output, "rows": len(out), "heave_positive": heave_positive, **summary}
    if nmea_info is not None:
        summary["nmea"] = nmea_info
    emit_summary(summary, as_json, quiet)
