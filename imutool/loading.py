"""Loading a recording the way every imutool command does: read, validate, bridge absurd samples, calibrate,
mount, check plausibility.

:func:`load_recording` is the library route behind every command's input (the CLI's ``load_input`` adds only
printing the warnings and keeping the report for the command's summary). Nothing is printed here: what validation
did and every plausibility warning come back in the report (and in ``rec.meta``).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.errors import ImutoolError


def load_recording(path: str | os.PathLike, *, columns: str | None = None, profile: str | None = None,
                   topic: str | None = None, stamp: str = "header", duplicates: str = "drop",
                   backwards: str = "error", mounting: str | None = None, calibration_file: str | None = None,
                   validate: bool = True, strict: bool = False) -> tuple[Recording, dict[str, Any]]:
    """Read ``path`` (any format imutool reads) → (recording, validation report dict).

    columns/profile: foreign CSV column mapping; topic/stamp: bag topic and time source; duplicates/backwards:
    validation policies (:meth:`formats.Recording.validated`); mounting: sensor→body ``'x,-y,-z[;r,p,y]'`` (deg);
    calibration_file: calibration TOML applied before mounting. The report holds rows read/kept/dropped and why,
    samples bridged, ``warnings`` (implausible units or axes, rows dropped...) and ``plausibility_figures``; what
    validation did and the warnings also go into ``rec.meta``. ``strict``: warnings raise an ImutoolError.
    """
    from formats import plausibility

    path = os.fspath(path)
    kind = formats.kind_of(path)
    opts: dict[str, Any] = {}
    if kind == "csv":
        opts = {"columns": columns, "profile": profile}
    elif kind in ("ros1", "ros2"):
        opts = {"topic": topic, "stamp": stamp}
    rec = formats.read(path, **opts)
    report: dict[str, Any] = {}
    checks = plausibility.PlausibilityReport()
    if validate:
        n_in = len(rec)
        rec, rep = rec.validated(duplicates=duplicates, backwards=backwards, source=path)
        report = rep.as_dict()
        drops, warns = plausibility.dropped_rows(n_in, len(rec), report, rec.meta, duplicates)
        report.update(drops)
        checks.warnings += warns
        rec, checks = plausibility.bridge_absurd(rec, rep=checks)
    else:  # what the reader itself could not read is reported all the same
        report, warns = plausibility.dropped_rows(len(rec), len(rec), {}, rec.meta)
        checks.warnings += warns
    if calibration_file:
        from calibration import load_calibration

        rec = load_calibration(calibration_file).apply(rec)
    if mounting:
        remap, mis = formats.parse_mounting(mounting)
        rec = rec.mounted(remap, mis)
    if len(rec):  # also for commands that read without validating (info, plot): they show the warnings
        ok = np.all(np.diff(rec.time) > 0) if len(rec) > 1 else True
        found = plausibility.check_recording(rec if ok else rec.select(np.argsort(rec.time, kind="stable")), mounting)
        checks.warnings += found.warnings
        checks.figures.update(found.figures)
        report.update({k: v for k, v in checks.as_dict().items() if k != "figures"})
        report["plausibility_figures"] = checks.figures
        if validate:
            rec.meta["validation"] = {k: v for k, v in report.items()
                                      if k not in ("plausibility_figures", "warnings")}
        else:
            report["validated"] = False
        if checks.warnings:
            prev = rec.meta.get("warnings")
            prev = list(prev) if isinstance(prev, (list, tuple)) else [str(prev)] if prev else []
            rec.meta["warnings"] = prev + [w for w in checks.warnings if w not in prev]
        if strict and checks.warnings:
            raise ImutoolError(strict_message(checks.warnings), path=path)
    return rec, report


def strict_message(warnings: list[str]) -> str:
    """The one-line error the input warnings become under ``strict``."""
    return "; ".join(warnings) + " (an error because of --strict)"


def require_channels(rec: Recording, names: list[str] | tuple[str, ...], path: str) -> None:
    """Refuse (ImutoolError naming ``path``) a recording that lacks any of the channels ``names``."""
    missing = [n for n in names if n not in rec.channels]
    if missing:
        raise ImutoolError(f"needs channel(s) {', '.join(missing)}; has {', '.join(rec.channels) or 'none'}",
                           path=path)
