"""The route behind ``imutool gyrofree`` and ``imutool batch gyrofree``: read the input, compute the angular
rate from the accelerometer array with :mod:`imutool.gyrofree` (arrays in, arrays out), write the result; and the
layout check of ``--check-layout`` against an input file.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.errors import ImutoolError
from imutool.gyrofree import (
    RATE_RW,
    TILT_GAIN,
    Layout,
    check_columns,
    check_layout,
    gyrofree_recording,
    load_layout,
    measurements,
    planar_roll,
)
from imutool.loading import input_notes, one_clock
from imutool.routes import OnInput, RouteResult, load_input, read_source


def layout_report(layout_path: str, input_path: str | os.PathLike | None = None, **load_options: Any) -> dict[str, Any]:
    """``gyrofree --check-layout``: the layout's observability (:func:`check_layout`); with ``input_path``, its
    columns and units checked against that recording too. A degenerate layout, or a column the recording
    lacks, is an ImutoolError."""
    layout = load_layout(layout_path)
    info = check_layout(layout, refuse=False)
    if not info["observable"]:
        raise ImutoolError(f"layout {layout.name} is degenerate: {'; '.join(info['reasons'])}")
    if input_path is not None:
        rec, _ = load_input(os.fspath(input_path), [], **load_options)
        check_columns(layout, rec)
        info["input"] = os.fspath(input_path)
    return info


def run_gyrofree(
    source: str | os.PathLike | Recording,
    output: str | os.PathLike | None = None,
    *,
    layout: str | Layout = "paper",
    noise: float | None = None,
    initial_rate_deg_s: Any = None,
    initial_sign: str = "+",
    tilt_gain: float = TILT_GAIN,
    rate_rw_deg_s: float | None = None,
    planar: list[str] | tuple[str, ...] | None = None,
    causal: bool = False,
    cutoff: float | None = None,
    strict: bool = False,
    on_input: OnInput | None = None,
    **load_options: Any,
) -> RouteResult:
    """Angular rate, angular acceleration and attitude of ``source`` (accelerometer array; a path or a
    Recording) from ``layout`` (a Layout, a layout TOML or 'paper'), written to ``output``: the route behind
    ``imutool gyrofree`` and ``imutool batch gyrofree``.

    Full solution (:func:`gyrofree_recording`): ``noise`` σ per sample (m/s², default the layout's density·√fs,
    else estimated), ``initial_rate_deg_s`` (3 values, deg/s; default from the data, the largest component of
    sign ``initial_sign`` '+' or '-'), ``tilt_gain`` 1/s, ``rate_rw_deg_s`` (deg/s/√s; default :data:`RATE_RW`).
    ``planar``: two single-axis sensors' columns → dynamic roll (:func:`planar_roll`, zero-phase unless
    ``causal``, band-pass ``cutoff`` Hz). A path is loaded with ``load_options`` (columns, ... calibration_file).
    """
    if not planar:
        unused = [flag for flag, given in (("--cutoff", cutoff is not None), ("--causal", causal)) if given]
        if unused:
            verb = "apply" if len(unused) > 1 else "applies"
            raise ImutoolError(
                f"{' and '.join(unused)} {verb} only with --planar COL1,COL2 (the two-accelerometer roll's "
                "band-pass); the full solution has no band-pass"
            )
    if not isinstance(layout, Layout):
        layout = load_layout(os.fspath(layout))
    inputs: list[dict[str, Any]] = []
    rec, name, _ = read_source(source, inputs, strict=strict, on_input=on_input, **load_options)
    rec = one_clock(rec, [c for s in layout.sensors for c in s.columns], inputs)  # many clocks: the array's
    if planar:
        names = list(planar)
        if len(names) != 2:
            raise ImutoolError("--planar needs two column names: COL1,COL2")
        sens = {s.columns[0]: s for s in layout.sensors if len(s.columns) == 1}
        for c in names:
            if c not in sens:
                raise ImutoolError(f"--planar column {c!r} is not a single-axis sensor of layout {layout.name}")
        s1, s2 = sens[names[0]], sens[names[1]]
        if not np.allclose(s1.axes[0], s2.axes[0]):
            raise ImutoolError("--planar: the two accelerometers must have the same sensitive axis")
        y = measurements(rec, layout)
        _, _, cols, _ = layout.rows()
        a1, a2 = y[:, cols.index(names[0])], y[:, cols.index(names[1])]
        res = planar_roll(rec.time, a1, a2, s1.position, s2.position, s1.axes[0], cutoff, causal)
        out = Recording(rec.time.copy(), meta=input_notes(rec.meta))
        out.add("roll_accel", res["roll_accel"], "rad/s^2")
        out.add("roll_rate", res["roll_rate"], "rad/s")
        out.add("roll", np.degrees(res["roll"]), "deg")
        out.meta["roll"] = "deg, positive starboard down (FRD), dynamic part only (static heel not observable)"
        summary: dict[str, Any] = {
            "mode": "planar roll",
            "columns": names,
            "cutoff_hz": round(res["cutoff_hz"], 4),
            "integration": "causal" if causal else "zero-phase",
        }
    else:
        w0 = None if initial_rate_deg_s is None else np.radians(np.asarray(initial_rate_deg_s, dtype=float))
        rate_rw = RATE_RW if rate_rw_deg_s is None else float(np.radians(rate_rw_deg_s))  # degrees out, SI inside
        out, summary = gyrofree_recording(
            rec, layout, noise, 1.0 if initial_sign == "+" else -1.0, w0, tilt_gain, rate_rw
        )
    if output is not None:
        formats.write(out, output)
    summary = {"input": name, "output": None if output is None else os.fspath(output), "rows": len(out), **summary}
    return RouteResult(summary, inputs, out)
