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
from formats.recording import (
    SENSOR_CHANNELS,
    all_nan_sensors,
    missing_sensor_warnings,
    refuse_without_sensor_data,
    require_samples,
)


def load_recording(
    path: str | os.PathLike,
    *,
    columns: str | None = None,
    profile: str | None = None,
    topic: str | None = None,
    stamp: str = "header",
    duplicates: str = "drop",
    backwards: str = "error",
    mounting: str | None = None,
    calibration_file: str | None = None,
    validate: bool = True,
    strict: bool = False,
) -> tuple[Recording, dict[str, Any]]:
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
        checks.warnings += warns + missing_sensor_warnings(all_nan_sensors(rec))
        rec, checks = plausibility.bridge_absurd(rec, rep=checks)
    else:  # what the reader itself could not read is reported all the same
        t = rec.time[np.isfinite(rec.time)]
        distinct = 0 if not len(t) else (1 if np.ptp(t) == 0 else 2)  # rows at different times, up to two
        require_samples(len(rec), distinct, path, len(t) - distinct if distinct == 1 else 0)
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
            rec.meta["validation"] = {k: v for k, v in report.items() if k not in ("plausibility_figures", "warnings")}
        else:
            report["validated"] = False
        if checks.warnings:
            rec.meta["warnings"] = merged_warnings(rec.meta, checks.warnings)
        if strict and checks.warnings:
            raise ImutoolError(strict_message(checks.warnings), path=path)
    return rec, report


def merged_warnings(meta: dict[str, Any], *more: list[str]) -> list[str]:
    """The ``warnings`` of ``meta`` (a list, or one string from another writer), then those of ``more`` that are
    not already there: what an output built from that input says."""
    prev = meta.get("warnings")
    out = list(prev) if isinstance(prev, (list, tuple)) else [str(prev)] if prev else []
    for ws in more:
        out += [w for w in ws if w not in out]
    return out


def strict_message(warnings: list[str]) -> str:
    """The one-line error the input warnings become under ``strict``."""
    return "; ".join(warnings) + " (an error because of --strict)"


def require_channels(rec: Recording, names: list[str] | tuple[str, ...], path: str) -> None:
    """Refuse (ImutoolError naming ``path``) a recording that lacks any of the channels ``names``."""
    missing = [n for n in names if n not in rec.channels]
    if missing:
        raise ImutoolError(f"needs channel(s) {', '.join(missing)}; has {', '.join(rec.channels) or 'none'}", path=path)


class ChunkChecks:
    """What :func:`load_recording` does to a whole file, done to a file read chunk by chunk (the streamed
    ``filter`` and ``convert``), so a large file is checked as a small one is.

    :meth:`prepare` bridges each chunk's absurd samples (counted over the run; more than 1 % of the rows seen so
    far is a unit error; a run of them at a chunk's edge has no neighbour there and is set to NaN instead of
    interpolated), applies the calibration and the mounting, and runs the plausibility checks (units, axes,
    gravity direction) on the first chunk only — the start of the file, where an in-memory load samples six
    stretches of the whole. :meth:`finish` accounts for every row the run dropped with the same > 1 % warning and
    returns the warnings, for stderr and the summary; :meth:`meta_warnings` adds the input's own for the
    output's metadata. ``strict``: a warning raises an ImutoolError (inside a streamed writer: no output).
    """

    def __init__(
        self, path: str, *, mounting: str | None = None, calibration_file: str | None = None, strict: bool = False
    ):
        from formats import plausibility

        self.path = path
        self.mounting = mounting
        self.strict = strict
        self.cal = None
        if calibration_file:
            from calibration import load_calibration

            self.cal = load_calibration(calibration_file)
        self.mount = formats.parse_mounting(mounting) if mounting else None
        self.warnings: list[str] = []  # the first chunk's plausibility warnings
        self.earlier: list[str] = []  # warnings the input file itself carries (an estimate's, ...)
        self._absurd = plausibility.PlausibilityReport()
        self._checked = False
        self._rows = 0
        self._sensors: dict[str, bool] = {}  # sensor channel → some value seen (not NaN)

    def prepare(self, chunk: Recording) -> Recording:
        """The chunk to use: absurd samples bridged, calibrated, mounted (its times must already increase)."""
        from formats import plausibility

        self._rows += len(chunk)
        for k in SENSOR_CHANNELS:
            if k in chunk.channels and not self._sensors.get(k):
                self._sensors[k] = k not in all_nan_sensors(chunk)
        chunk, _ = plausibility.bridge_absurd(chunk, rep=self._absurd, out_of=self._rows)
        if self.cal is not None:
            chunk = self.cal.apply(chunk)
        if self.mount is not None:
            chunk = chunk.mounted(*self.mount)
        if not self._checked and len(chunk):
            self._checked = True
            self.earlier = merged_warnings(chunk.meta)
            found = plausibility.check_recording(chunk, self.mounting)
            self.warnings += found.warnings
            self._refuse(found.warnings)
        return chunk

    def finish(
        self,
        rows_read: int,
        rows_kept: int,
        *,
        duplicates: int = 0,
        skipped: int = 0,
        reader_meta: dict[str, Any] | None = None,
    ) -> tuple[dict[str, Any], list[str]]:
        """(validation report, every warning of the run). rows_read: rows the reader returned; rows_kept: rows
        used; duplicates: of the rows dropped, those whose time repeated the row before; skipped: malformed
        rows the reader skipped (or ``reader_meta``: the reader's metadata, e.g. a bag's, which hold them)."""
        from formats import plausibility

        require_samples(rows_read, rows_kept, self.path, duplicates)
        empty = [k for k, seen in self._sensors.items() if not seen]
        refuse_without_sensor_data(empty, list(self._sensors), self.path)
        missing = missing_sensor_warnings(empty)
        report, dropped = plausibility.dropped_rows(
            rows_read,
            rows_kept,
            {"duplicate_timestamps": duplicates},
            reader_meta if reader_meta is not None else {"skipped_rows": skipped},
        )
        for counts in self._absurd.absurd.values():
            counts[1] = rows_read  # the share of a unit error is over the whole run
        absurd = self._absurd.absurd_warnings()
        report.update({k: v for k, v in self._absurd.as_dict().items() if k.startswith("absurd_")})
        self._refuse(missing + absurd + dropped)
        return report, self.warnings + missing + absurd + dropped

    def meta_warnings(self, *more: list[str]) -> list[str]:
        """The output's ``warnings``: the input's own, then these (each once)."""
        return merged_warnings({"warnings": self.earlier}, *more)

    def _refuse(self, warnings: list[str]) -> None:
        if self.strict and warnings:
            raise ImutoolError(strict_message(warnings), path=self.path)


INPUT_NOTES = ("warnings", "validation")


def input_notes(meta: dict[str, Any]) -> dict[str, Any]:
    """What loading found about an input (``warnings`` and ``validation`` in its metadata, from
    :func:`load_recording`), for the metadata of an output built from it: an estimate says what was wrong with
    the data it came from."""
    return {k: meta[k] for k in INPUT_NOTES if meta.get(k)}
