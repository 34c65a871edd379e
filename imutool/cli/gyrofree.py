"""`imutool gyrofree IN --layout L -o OUT`: angular rate, angular acceleration and attitude from accelerometers."""

from __future__ import annotations

import click
import numpy as np

import formats
from formats import Recording
from formats.errors import ImutoolError
from imutool.cli.common import emit_summary, input_options, load_input, output_options, parse_vector, safe_outputs
from imutool.loading import input_notes


@click.command(
    "gyrofree",
    epilog="Example: imutool simulate accel-array -o array.csv && "
    "imutool gyrofree array.csv --layout paper -o rates.csv",
)
@click.argument("input_path", metavar="INPUT", type=click.Path(exists=True), required=False)
@click.option("-o", "--output", default=None, type=click.Path(), help="Output file (.csv, ...).")
@click.option(
    "--layout",
    "layout_path",
    required=True,
    help="Layout TOML (positions m body FRD, axes, columns, units) or 'paper' (r = 0.1 m).",
)
@click.option("--check-layout", is_flag=True, help="Only check observability/conditioning of the layout.")
@click.option(
    "--noise",
    type=float,
    default=None,
    help="Accelerometer noise σ per sample (m/s²) [default: layout noise_density·√fs, else estimated].",
)
@click.option("--initial-rate", default=None, metavar="WX,WY,WZ", help="Initial ω (deg/s) [default from data].")
@click.option(
    "--initial-sign",
    type=click.Choice(["+", "-"]),
    default="+",
    show_default=True,
    help="Sign of the largest initial ω component (h(ω) = h(−ω)).",
)
@click.option(
    "--tilt-gain",
    type=float,
    default=0.0,
    show_default=True,
    help="Gravity tilt correction gain (1/s) from the centre specific force (0 = pure integration).",
)
@click.option(
    "--rate-rw", type=float, default=None, help="ω random walk in Q, deg/s/√s [default 0.00573 = 1e-4 rad/s/√s]."
)
@click.option(
    "--planar",
    default=None,
    metavar="COL1,COL2",
    help="Reduced mode: two parallel single-axis accelerometers (layout sensors' columns) → roll.",
)
@click.option("--causal", is_flag=True, help="Planar mode: causal band-pass integration (default zero-phase).")
@click.option("--cutoff", type=float, default=None, help="Planar mode band-pass cut-off Hz [0.3 × dominant].")
@input_options
@output_options
@safe_outputs("output")
def gyrofree_cmd(
    input_path: str | None,
    output: str | None,
    layout_path: str,
    check_layout: bool,
    noise: float | None,
    initial_rate: str | None,
    initial_sign: str,
    tilt_gain: float,
    rate_rw: float,
    planar: str | None,
    causal: bool,
    cutoff: float | None,
    as_json: bool,
    quiet: bool,
    **inopts,
) -> None:
    """ω (rad/s), ω̇ (rad/s²), f_O and attitude from N accelerometers (no gyro); --check-layout for geometry."""
    from imutool import gyrofree as gf

    layout = gf.load_layout(layout_path)
    if check_layout:
        info = gf.check_layout(layout, refuse=False)
        emit_summary(info, as_json, quiet)
        if not info["observable"]:
            raise ImutoolError(f"layout {layout.name} is degenerate: {'; '.join(info['reasons'])}")
        return
    if not input_path or not output:
        raise ImutoolError("give INPUT and -o OUTPUT (or --check-layout)")
    rec, _ = load_input(input_path, **inopts)
    if planar:
        names = [c.strip() for c in planar.split(",")]
        if len(names) != 2:
            raise ImutoolError("--planar needs two column names: COL1,COL2")
        sens = {s.columns[0]: s for s in layout.sensors if len(s.columns) == 1}
        for c in names:
            if c not in sens:
                raise ImutoolError(f"--planar column {c!r} is not a single-axis sensor of layout {layout.name}")
        s1, s2 = sens[names[0]], sens[names[1]]
        if not np.allclose(s1.axes[0], s2.axes[0]):
            raise ImutoolError("--planar: the two accelerometers must have the same sensitive axis")
        y = gf.measurements(rec, layout)
        _, _, cols, _ = layout.rows()
        a1, a2 = y[:, cols.index(names[0])], y[:, cols.index(names[1])]
        res = gf.planar_roll(rec.time, a1, a2, s1.position, s2.position, s1.axes[0], cutoff, causal)
        out = Recording(rec.time.copy(), meta=input_notes(rec.meta))
        out.add("roll_accel", res["roll_accel"], "rad/s^2")
        out.add("roll_rate", res["roll_rate"], "rad/s")
        out.add("roll", np.degrees(res["roll"]), "deg")
        out.meta["roll"] = "deg, positive starboard down (FRD), dynamic part only (static heel not observable)"
        summary = {
            "mode": "planar roll",
            "columns": names,
            "cutoff_hz": round(res["cutoff_hz"], 4),
            "integration": "causal" if causal else "zero-phase",
        }
    else:
        w0 = np.radians(parse_vector(initial_rate, 3, "--initial-rate")) if initial_rate else None
        rate_rw = 1e-4 if rate_rw is None else float(np.radians(rate_rw))  # options in degrees, SI inside
        out, summary = gf.gyrofree_recording(
            rec, layout, noise, 1.0 if initial_sign == "+" else -1.0, w0, tilt_gain, rate_rw
        )
    formats.write(out, output)
    emit_summary({"input": input_path, "output": output, "rows": len(out), **summary}, as_json, quiet)
