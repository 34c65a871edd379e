"""Sensor noise from a static recording: the one route behind ``imutool allan``, ``imutool batch allan`` and a
Python user.

:func:`allan_noise` reads one or more files (one per sensor, each on its own clock), computes the overlapping
Allan deviation per channel (:mod:`calibration.allan`), reads white noise N, bias instability B and random walk
K off it, and writes the noise file (.yaml, SI: rad/s/√Hz, m/s²/√Hz, µT/√Hz), optionally a kalibr imu.yaml and a
plot. Nothing is printed; it returns a :class:`NoiseRun` (a :class:`imutool.routes.RouteResult`); the summary
carries the gyro terms in degrees too (ARW °/√h, B °/h, K °/h/√h).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from formats.errors import ImutoolError
from imutool.loading import load_recording
from imutool.routes import LOAD_OPTIONS, OnInput, RouteResult, Stage

SI = {"gyro": "rad/s", "accel": "m/s^2", "mag": "uT"}


@dataclass
class NoiseRun(RouteResult):
    """What :func:`allan_noise` produced: the :class:`imutool.routes.RouteResult` (``summary``: outputs,
    ``channels`` (= info) and ``warnings`` (kalibr fallbacks); ``inputs``: what loading each file did), and
    ``results``: the :mod:`calibration.allan` result per channel analysed; ``values``: what the noise file holds;
    ``info``: per channel the file, rate, samples, timing, N/B/K and their labels."""

    results: list[Any] = field(default_factory=list)
    values: dict[str, Any] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)


def sample_rate(t: np.ndarray) -> tuple[float, str]:
    """Sample rate for the Allan analysis: samples / span. Host timestamps of a buffered sensor often come in
    bursts (median step ≪ mean step); the sensor itself samples uniformly at the mean rate."""
    if len(t) < 2 or not float(t[-1] - t[0]) > 0:
        raise ImutoolError(f"Allan deviation needs a time series: {len(t)} row(s) spanning no time")
    mean_rate = (len(t) - 1) / float(t[-1] - t[0])
    med = float(np.median(np.diff(t)))
    if abs(med * mean_rate - 1.0) > 0.05:
        return mean_rate, (
            f"irregular timestamps (median step {1e3 * med:.2f} ms vs mean {1e3 / mean_rate:.2f} ms): "
            f"samples taken as uniform at the mean rate {mean_rate:.3f} Hz"
        )
    return mean_rate, "regular"


def allan_noise(
    inputs: str | os.PathLike | list[str] | tuple[str, ...],
    output: str | os.PathLike,
    *,
    plot: str | os.PathLike | None = None,
    kalibr: str | os.PathLike | None = None,
    topic_name: str = "/imu0",
    kalibr_fallback: str = "refuse",
    channels: str | tuple[str, ...] = "gyro,accel,mag",
    per_decade: int = 10,
    start: float | None = None,
    end: float | None = None,
    strict: bool = False,
    stage: Stage | None = None,
    on_input: OnInput | None = None,
    **load_options: Any,
) -> NoiseRun:
    """Allan deviation of the static recording(s) ``inputs`` → noise file ``output`` (.yaml).

        channels: which of gyro, accel, mag to analyse (the first input holding each is used); per_decade: cluster
        times per decade of τ; start/end: time window (s). kalibr: also a kalibr-style imu.yaml (``topic_name``); an
        unresolved random walk is refused there (``kalibr_fallback='refuse'``) or written as its labelled upper
        bound (``'upper-bound'``, with a warning). load_options as :func:`imutool.loading.load_recording` (``strict``:
    an input's warnings are an error);
        ``on_input(path, report)`` after each file is read, ``stage(name)`` as each step starts.
    """
    unknown = set(load_options) - set(LOAD_OPTIONS)
    if unknown:
        raise TypeError(f"allan_noise() got unexpected keyword argument(s) {', '.join(sorted(unknown))}")
    io = {k: v for k, v in load_options.items() if v is not None}
    inputs = [os.fspath(inputs)] if isinstance(inputs, (str, os.PathLike)) else [os.fspath(p) for p in inputs]
    output = os.fspath(output)
    plot = os.fspath(plot) if plot else None
    kalibr = os.fspath(kalibr) if kalibr else None

    from calibration.allan import analyse, plot_allan
    from calibration.noise_file import write_kalibr, write_noise

    def _stage(name: str) -> None:
        if stage is not None:
            stage(name)

    if not output.lower().endswith((".yaml", ".yml")):
        raise ImutoolError(f"the noise file must be .yaml: {output!r}")
    wanted = [c.strip() for c in (channels.split(",") if isinstance(channels, str) else channels) if c.strip()]
    for c in wanted:
        if c not in SI:
            raise ImutoolError(f"--channels: unknown channel {c!r} (gyro, accel, mag)")
    results = []
    loaded: list[dict[str, Any]] = []
    values: dict[str, Any] = {}
    info: dict[str, Any] = {}
    rates = []
    for path in inputs:
        _stage(f"reading {os.path.basename(path)}")
        rec, rep = load_recording(path, strict=strict, **io)
        if len(rec):
            loaded.append({"input": path, **rep})
            if on_input is not None:
                on_input(path, rep)
        if start is not None or end is not None:
            rec = rec.slice_time(start, end)
        for name in wanted:
            if name not in rec.channels or any(r.name == name for r in results):
                continue
            y = rec.get(name, SI[name])
            ok = np.all(np.isfinite(y), axis=1)
            if not ok.all():
                y = y[ok]
            fs, timing = sample_rate(rec.time)
            rates.append(fs)
            _stage(f"Allan deviation of {name}")
            res = analyse(y, fs, name, SI[name], per_decade)
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
            info[name] = {
                "file": path,
                "rate_hz": round(fs, 3),
                "samples": int(len(y)),
                "duration_s": round(float(len(y) / fs), 1),
                "dropped_nan_rows": int((~ok).sum()),
                "timing": timing,
                "gaps": len(rep.get("gaps", [])),
                "N": n_,
                "B": b_,
                "K": k_,
                "tau_min_s": res.summary()["tau_min_s"],
                "B_upper_bound": sm["B_upper_bound"],
                "allan_minimum": sm["B_kind"],
                "K_resolved": sm["K_resolved"],
                "K_upper_bound": sm["K_upper"],
                "units": {"N": f"{SI[name]}/√Hz", "B": SI[name], "K": f"{SI[name]}/√s"},
            }
            if name == "gyro":  # degrees at the user surface
                info[name]["deg"] = {
                    "ARW_deg_per_rt_h": [float(np.degrees(v) * 60) for v in n_],
                    "B_deg_per_h": [float(np.degrees(v) * 3600) for v in b_],
                    "K_deg_per_h_per_rt_h": [float(np.degrees(v) * 3600 * 60) for v in k_],
                }
    if not results:
        raise ImutoolError(f"none of the channels {', '.join(wanted)} found in {', '.join(inputs)}")
    values["rate_hz"] = float(max(rates))
    values["source"] = ", ".join(inputs)
    _stage("writing")
    write_noise(output, values)
    warnings: list[str] = []
    if kalibr:
        warnings = write_kalibr(kalibr, values, topic_name, fallback=kalibr_fallback)
    if plot:
        plot_allan(results, plot, title=f"Allan deviation — {', '.join(os.path.basename(p) for p in inputs)}")
    summary = {"output": output, "kalibr": kalibr, "plot": plot, "channels": info, "warnings": warnings}
    return NoiseRun(summary, loaded, results=results, values=values, info=info)
