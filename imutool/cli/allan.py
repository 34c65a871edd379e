"""``imutool allan``: overlapping Allan deviation → ARW/VRW, bias instability, RRW; noise.yaml and kalibr imu.yaml."""

from __future__ import annotations

import os
from typing import Any

import click
import numpy as np

from formats.errors import ImutoolError
from imutool.cli.common import emit_summary, input_options, load_input, output_options, safe_outputs

_IN_KEYS = ("columns", "profile", "topic", "stamp", "duplicates", "backwards", "mounting", "calibration_file")
_SI = {"gyro": "rad/s", "accel": "m/s^2", "mag": "uT"}
_LABEL = {"gyro": ("ARW", "rad/s/√Hz"), "accel": ("VRW", "m/s²/√Hz"), "mag": ("white", "µT/√Hz")}


def _rate(t: np.ndarray) -> tuple[float, str]:
    """Sample rate for the Allan analysis: samples / span. Host timestamps of a buffered sensor often come in
    bursts (median step ≪ mean step); the sensor itself samples uniformly at the mean rate."""
    if len(t) < 2 or not float(t[-1] - t[0]) > 0:
        raise ImutoolError(f"Allan deviation needs a time series: {len(t)} row(s) spanning no time")
    mean_rate = (len(t) - 1) / float(t[-1] - t[0])
    med = float(np.median(np.diff(t)))
    if abs(med * mean_rate - 1.0) > 0.05:
        return mean_rate, (f"irregular timestamps (median step {1e3 * med:.2f} ms vs mean {1e3 / mean_rate:.2f} ms): "
                           f"samples taken as uniform at the mean rate {mean_rate:.3f} Hz")
    return mean_rate, "regular"


@click.command("allan", epilog="Example: imutool allan static.csv -o noise.yaml --plot allan.png --kalibr imu.yaml")
@click.argument("inputs", nargs=-1, required=True, metavar="INPUT...")
@click.option("-o", "--output", required=True,
              help="Noise file (.yaml, SI: rad/s/√Hz, m/s²/√Hz, µT/√Hz): white noise, bias instability and random "
                   "walk per sensor, to fill in the noise options of filter/ins or a kalibr config.")
@click.option("--plot", default=None, help="Log-log Allan deviation plot with the fitted lines (.png/.pdf).")
@click.option("--kalibr", default=None, help="Also write a kalibr-style imu.yaml here.")
@click.option("--topic-name", default="/imu0", show_default=True, help="rostopic written into the kalibr file.")
@click.option("--kalibr-fallback", type=click.Choice(["refuse", "upper-bound"]), default="refuse", show_default=True,
              help="A random walk the recording does not resolve: refuse the kalibr file, or write its upper bound "
                   "(labelled in the file, with a warning). Never a silent 0.")
@click.option("--channels", default="gyro,accel,mag", show_default=True,
              help="Channels to analyse (those present in the inputs).")
@click.option("--per-decade", type=int, default=10, show_default=True, help="Cluster times per decade of τ.")
@click.option("--start", type=float, default=None, help="Use data from this time (s) on.")
@click.option("--end", type=float, default=None, help="Use data before this time (s).")
@input_options
@output_options
@safe_outputs("output", "plot", "kalibr")
def allan_cmd(inputs: tuple[str, ...], output: str, plot: str | None, kalibr: str | None, topic_name: str,
              kalibr_fallback: str, channels: str, per_decade: int, start: float | None, end: float | None,
              as_json: bool, quiet: bool, **io: Any) -> None:
    """Allan deviation of a static recording (several INPUT files: one per sensor, each on its own clock).

    For each axis: N (ARW/VRW) read at τ = 1 s on the slope −½ line, bias instability B = min σ / 0.664 when a
    flicker floor is seen (else the minimum is labelled the white/random-walk crossover, an upper bound), K
    (rate/acceleration random walk) read at τ = 3 s on the slope +½ line (or "not resolved" with its bound).
    The summary gives the gyro in
    degrees (ARW °/√h, B °/h, K °/h/√h), accelerometer and magnetometer in SI; the noise file is SI throughout.
    """
    from calibration.allan import analyse, plot_allan
    from calibration.noise import write_kalibr, write_noise

    if not output.lower().endswith((".yaml", ".yml")):
        raise ImutoolError(f"the noise file must be .yaml: {output!r}")
    wanted = [c.strip() for c in channels.split(",") if c.strip()]
    for c in wanted:
        if c not in _SI:
            raise ImutoolError(f"--channels: unknown channel {c!r} (gyro, accel, mag)")
    results = []
    values: dict[str, Any] = {}
    info: dict[str, Any] = {}
    rates = []
    from imutool.progress import stages

    steps = stages("allan", [*inputs, *wanted, "writing"], quiet)
    for path in inputs:
        steps.stage(f"reading {os.path.basename(path)}")
        rec, rep = load_input(path, **{k: io.get(k) for k in _IN_KEYS if io.get(k) is not None})
        if start is not None or end is not None:
            rec = rec.slice_time(start, end)
        for name in wanted:
            if name not in rec.channels or any(r.name == name for r in results):
                continue
            y = rec.get(name, _SI[name])
            ok = np.all(np.isfinite(y), axis=1)
            if not ok.all():
                y = y[ok]
            fs, timing = _rate(rec.time)
            rates.append(fs)
            steps.stage(f"Allan deviation of {name}")
            res = analyse(y, fs, name, _SI[name], per_decade)
            results.append(res)
            sm = res.summary()
            n_, b_, k_ = (sm[k] for k in ("N", "B", "K"))
            values[f"{name}_noise_density"] = float(np.mean(n_))
            values[f"{name}_noise_density_xyz"] = [float(v) for v in n_]
            # a bias instability only where a flicker floor is seen; else the minimum's bound, labelled
            if all(k == "bias instability" for k in sm["B_kind"]):
                values[f"{name}_bias_instability"] = float(np.mean(b_))
                values[f"{name}_bias_instability_xyz"] = [float(v) for v in b_]
            else:
                values[f"{name}_bias_instability_upper_bound"] = float(np.max(b_))
            values[f"{name}_allan_minimum_xyz"] = list(sm["B_kind"])
            # a random walk only where the +1/2 slope is seen; else its upper bound, labelled (never a silent 0)
            if all(sm["K_resolved"]):
                values[f"{name}_random_walk"] = float(np.mean(k_))
                values[f"{name}_random_walk_xyz"] = [float(v) for v in k_]
            else:
                values[f"{name}_random_walk_upper_bound"] = float(np.max(sm["K_upper"]))
            info[name] = {"file": path, "rate_hz": round(fs, 3), "samples": int(len(y)),
                          "duration_s": round(float(len(y) / fs), 1), "dropped_nan_rows": int((~ok).sum()),
                          "timing": timing,
                          "gaps": len(rep.get("gaps", [])),
                          "N": n_, "B": b_, "K": k_, "tau_min_s": res.summary()["tau_min_s"],
                          "B_upper_bound": sm["B_upper_bound"], "allan_minimum": sm["B_kind"],
                          "K_resolved": sm["K_resolved"], "K_upper_bound": sm["K_upper"],
                          "units": {"N": f"{_SI[name]}/√Hz", "B": _SI[name], "K": f"{_SI[name]}/√s"}}
            if name == "gyro":  # degrees at the user surface
                info[name]["deg"] = {"ARW_deg_per_rt_h": [float(np.degrees(v) * 60) for v in n_],
                                     "B_deg_per_h": [float(np.degrees(v) * 3600) for v in b_],
                                     "K_deg_per_h_per_rt_h": [float(np.degrees(v) * 3600 * 60) for v in k_]}
    if not results:
        raise ImutoolError(f"none of the channels {', '.join(wanted)} found in {', '.join(inputs)}")
    values["rate_hz"] = float(max(rates))
    values["source"] = ", ".join(inputs)
    steps.stage("writing")
    write_noise(output, values)
    warnings: list[str] = []
    if kalibr:
        warnings = write_kalibr(kalibr, values, topic_name, fallback=kalibr_fallback)
    if plot:
        plot_allan(results, plot, title=f"Allan deviation — {', '.join(os.path.basename(p) for p in inputs)}")
    lines = [f"Allan deviation → {output}" + (f", {kalibr}" if kalibr else "") + (f", {plot}" if plot else "")]
    for r in results:
        lab, unit = _LABEL[r.name]
        s = r.summary()
        lines.append(f"  {r.name} ({info[r.name]['rate_hz']} Hz, {info[r.name]['duration_s']} s):")
        if info[r.name]["timing"] != "regular":
            lines.append(f"    note: {info[r.name]['timing']}")
        taus = "   at τ = " + ", ".join(f"{v:.3g}" for v in s["tau_min_s"]) + " s"
        lab_b = {"bias instability": "flicker floor", "crossover": "white/random-walk crossover, NOT a bias "
                 "instability", "upper bound": "σ still falling: upper bound"}
        taus += " (" + "; ".join(lab_b[k] for k in s["B_kind"]) + ")"
        is_b = all(k == "bias instability" for k in s["B_kind"])
        blab = "bias inst. B" if is_b else "Allan min/0.664"

        def kfmt(scale: float, s=s) -> str:
            return "  ".join(f"{v * scale:.4g}" if ok else f"not resolved (<= {ub * scale:.3g})"
                             for v, ok, ub in zip(s["K"], s["K_resolved"], s["K_upper"], strict=True))
        if r.name == "gyro":  # degrees at the user surface (the noise file stays SI)
            lines.append("    ARW N          (°/√h) = " + "  ".join(f"{np.degrees(v) * 60:.4g}" for v in s["N"]))
            lines.append(f"    {blab:15s} (°/h) = " + "  ".join(f"{np.degrees(v) * 3600:.4g}" for v in s["B"])
                         + taus)
            lines.append("    rate RW K    (°/h/√h) = " + kfmt(np.degrees(1.0) * 216000))
        else:
            lines.append(f"    {lab} N  ({unit:>11s}) = " + "  ".join(f"{v:.4g}" for v in s["N"]))
            lines.append(f"    {blab} ({_SI[r.name]:>9s}) = " + "  ".join(f"{v:.4g}" for v in s["B"]) + taus)
            lines.append(f"    random walk K ({_SI[r.name]}/√s) = " + kfmt(1.0))
        if any(k == "upper bound" for k in s["B_kind"]):
            lines.append("    note: σ(τ) still falls at the longest τ on some axes: B there is an upper bound and K is "
                         "not resolved (record longer)")
    steps.close()
    for w in warnings:
        click.echo(f"warning: {w}", err=True)
    emit_summary({"output": output, "kalibr": kalibr, "plot": plot, "channels": info, "warnings": warnings},
                 as_json, quiet, lines)
