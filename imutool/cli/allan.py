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
@click.option("--channels", default="gyro,accel,mag", show_default=True,
              help="Channels to analyse (those present in the inputs).")
@click.option("--per-decade", type=int, default=10, show_default=True, help="Cluster times per decade of τ.")
@click.option("--start", type=float, default=None, help="Use data from this time (s) on.")
@click.option("--end", type=float, default=None, help="Use data before this time (s).")
@input_options
@output_options
@safe_outputs("output", "plot", "kalibr")
def allan_cmd(inputs: tuple[str, ...], output: str, plot: str | None, kalibr: str | None, topic_name: str,
              channels: str, per_decade: int, start: float | None, end: float | None, as_json: bool, quiet: bool,
              **io: Any) -> None:
    """Allan deviation of a static recording (several INPUT files: one per sensor, each on its own clock).

    For each axis: N (ARW/VRW) read at τ = 1 s on the slope −½ line, bias instability B = min σ / 0.664,
    K (rate/acceleration random walk) read at τ = 3 s on the slope +½ line. The summary gives the gyro in
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
            n_, b_, k_ = (res.summary()[k] for k in ("N", "B", "K"))
            values[f"{name}_noise_density"] = float(np.mean(n_))
            values[f"{name}_bias_instability"] = float(np.mean(b_))
            values[f"{name}_random_walk"] = float(np.mean(k_))
            values[f"{name}_noise_density_xyz"] = [float(v) for v in n_]
            values[f"{name}_bias_instability_xyz"] = [float(v) for v in b_]
            values[f"{name}_random_walk_xyz"] = [float(v) for v in k_]
            info[name] = {"file": path, "rate_hz": round(fs, 3), "samples": int(len(y)),
                          "duration_s": round(float(len(y) / fs), 1), "dropped_nan_rows": int((~ok).sum()),
                          "timing": timing,
                          "gaps": len(rep.get("gaps", [])),
                          "N": n_, "B": b_, "K": k_, "tau_min_s": res.summary()["tau_min_s"],
                          "B_upper_bound": res.summary()["B_upper_bound"],
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
    if kalibr:
        write_kalibr(kalibr, values, topic_name)
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
        if r.name == "gyro":  # degrees at the user surface (the noise file stays SI)
            lines.append("    ARW N          (°/√h) = " + "  ".join(f"{np.degrees(v) * 60:.4g}" for v in s["N"]))
            lines.append("    bias inst. B    (°/h) = " + "  ".join(f"{np.degrees(v) * 3600:.4g}" for v in s["B"])
                         + taus)
            lines.append("    rate RW K    (°/h/√h) = "
                         + "  ".join(f"{np.degrees(v) * 216000:.4g}" for v in s["K"]))
        else:
            lines.append(f"    {lab} N  ({unit:>11s}) = " + "  ".join(f"{v:.4g}" for v in s["N"]))
            lines.append(f"    bias inst. B ({_SI[r.name]:>9s}) = " + "  ".join(f"{v:.4g}" for v in s["B"]) + taus)
            lines.append(f"    random walk K ({_SI[r.name]}/√s) = " + "  ".join(f"{v:.4g}" for v in s["K"]))
        if any(s["B_upper_bound"]):
            lines.append("    note: σ(τ) still falls at the longest τ on some axes: B there is an upper bound and K is "
                         "not resolved (record longer)")
    steps.close()
    emit_summary({"output": output, "kalibr": kalibr, "plot": plot, "channels": info}, as_json, quiet, lines)
