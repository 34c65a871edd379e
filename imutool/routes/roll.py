"""The route behind ``imutool roll`` and ``imutool batch roll``: read the input, take the heel on its own samples,
compute the roll statistics with :mod:`imutool.roll` (arrays in, arrays out) and write them.
"""

from __future__ import annotations

import os
from datetime import datetime
from typing import Any

import formats
from imutool.loading import input_notes, one_clock
from imutool.roll import ROLL_DEFAULTS as D
from imutool.roll import heel_of, roll_stats
from imutool.routes import OnInput, RouteResult, load_input


def run_roll(
    source: str | os.PathLike,
    output: str | os.PathLike | None = None,
    *,
    cycles_path: str | os.PathLike | None = None,
    hysteresis_deg: float | None = D["hysteresis_deg"],
    centre: str = D["centre"],
    centre_window_s: float = D["centre_window_s"],
    refine_frac: float = D["refine_frac"],
    max_period_s: float = D["max_period_s"],
    hysteresis_frac: float = D["hysteresis_frac"],
    hysteresis_min_deg: float = D["hysteresis_min_deg"],
    smooth_frac: float = D["smooth_frac"],
    disagree_frac: float = D["disagree_frac"],
    resets_s: list[float] | tuple[float, ...] = (),
    utc_start: datetime | None = None,
    strict: bool = False,
    on_input: OnInput | None = None,
    **load_options: Any,
) -> RouteResult:
    """Roll statistics of the heel (``heel`` or ``roll`` channel, deg, + starboard down) of ``source``: the route
    behind ``imutool roll`` and ``imutool batch roll``. Writes the per-sample statistics to ``output`` and the
    per-cycle table to ``cycles_path`` (when given); settings as :func:`roll_stats`. A path is loaded with
    ``load_options`` (columns, profile, ... calibration_file; ``strict``: its warnings are an error). The
    result's ``data["stats"]`` is the :class:`RollStats`, ``recording`` the per-sample statistics; the summary's
    ``period_estimates`` the three periods side by side, ``warnings`` their disagreement."""
    name = os.fspath(source)
    inputs: list[dict[str, Any]] = []
    rec, _ = load_input(name, inputs, strict=strict, on_input=on_input, **load_options)
    rec = one_clock(rec, ("heel", "roll"), inputs)  # many clocks: the heel's own samples
    heel = heel_of(rec, name)
    rs = roll_stats(
        rec.time,
        heel,
        hysteresis_deg=hysteresis_deg,
        centre=centre,
        centre_window_s=centre_window_s,
        refine_frac=refine_frac,
        max_period_s=max_period_s,
        resets_s=list(resets_s),
        utc_start=utc_start,
        hysteresis_frac=hysteresis_frac,
        hysteresis_min_deg=hysteresis_min_deg,
        smooth_frac=smooth_frac,
        disagree_frac=disagree_frac,
    )
    meta = {k: v for k, v in rec.meta.items() if k in ("sensor", "device", "frame", "mounting", "calibration")}
    meta["source"] = name
    meta.update(input_notes(rec.meta))
    out = rs.as_recording(meta)
    if output is not None:
        formats.write(out, output)
    if cycles_path:
        formats.write(rs.cycles.as_recording(), cycles_path)
    summary = {
        "input": name,
        "output": None if output is None else os.fspath(output),
        "cycles_output": None if cycles_path is None else os.fspath(cycles_path),
        **rs.summary(),
        "settings": rs.settings,
    }
    return RouteResult(summary, inputs, out, {"stats": rs})
