"""The recording: one in-memory model for every reader, writer and algorithm (docs/architecture.md).

A :class:`Recording` is ``time`` (float64 s), named channels of shape (N,) or (N, k), per-channel units and
a metadata dict. Vector channels remember the CSV column names they came from (``gyro`` ← ``gyro_x,
gyro_y, gyro_z``; ``q`` ← ``qw,qx,qy,qz``) so writing back reproduces the columns exactly.
"""

from __future__ import annotations

import copy
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import units as _units
from .errors import ImutoolError
from .frames import matrix_to_quat, parse_axis_remap, quat_conjugate, quat_multiply, rotation_about_axes

# Canonical channels and the unit they carry in an imutool CSV (docs/formats.md).
CANONICAL_UNITS = {
    "gyro": "rad/s",
    "accel": "m/s^2",
    "mag": "uT",
    "temp": "degC",
    "roll": "deg",
    "pitch": "deg",
    "heading": "deg",
    "heave": "m",
    "heave_rate": "m/s",
    "pos": "m",
    "vel": "m/s",
    "gyro_bias": "rad/s",
    "q": "1",
    "zvi": "1",
}

_VECTOR_SUFFIXES = (("_x", "_y", "_z"), ("_n", "_e", "_d"))
_QUAT_SUFFIXES = ("w", "x", "y", "z")


def canonical_unit(name: str) -> str | None:
    """The unit a canonical channel name carries (``ref_`` prefix and ``_std`` suffix are transparent)."""
    base = name[4:] if name.startswith("ref_") else name
    if base.endswith("_std"):
        base = base[:-4]
    return CANONICAL_UNITS.get(base)


def group_columns(names: list[str]) -> list[tuple[str, list[str]]]:
    """Group CSV column names into channels: ``a_x,a_y,a_z`` → ``a``; ``qw..qz`` → ``q``; else scalars.

    Returns (channel name, [column names]) in column order of first appearance.
    """
    present = set(names)
    taken: set[str] = set()
    out: list[tuple[str, list[str]]] = []
    for n in names:
        if n in taken:
            continue
        group = None
        for sfx in _VECTOR_SUFFIXES:
            for s in sfx:
                if n.endswith(s) and len(n) > len(s):
                    base = n[: -len(s)]
                    cols = [base + t for t in sfx]
                    if all(c in present and c not in taken for c in cols):
                        group = (base, cols)
                    break
            if group:
                break
        if group is None and len(n) >= 2 and n[-1] in "wxyz" and n[:-1].endswith("q"):
            base = n[:-1]
            cols = [base + t for t in _QUAT_SUFFIXES]
            if all(c in present and c not in taken for c in cols):
                group = (base, cols)
        if group is None:
            group = (n, [n])
        taken.update(group[1])
        out.append(group)
    return out


def default_columns(name: str, width: int) -> list[str]:
    """Column names for a channel of the given width."""
    if width == 1:
        return [name]
    if width == 4 and (name == "q" or name.endswith("_q") or name.endswith("q")):
        return [name + s for s in _QUAT_SUFFIXES]
    if width == 3:
        if name in ("pos", "vel") or name.endswith(("_pos", "_vel")) or name.startswith(("pos_", "vel_")):
            return [name + s for s in _VECTOR_SUFFIXES[1]]
        return [name + s for s in _VECTOR_SUFFIXES[0]]
    return [f"{name}_{i}" for i in range(width)]


MAX_TIME_S = 1e11  # |time| beyond this (s) is refused by validation: a unit error, not a clock
SENSOR_CHANNELS = ("gyro", "accel", "mag")


def require_samples(rows_read: int, rows_kept: int, source: str, duplicates: int = 0) -> None:
    """A recording with fewer than two rows (two distinct times) has no duration and no rate: refused, one line
    saying how many rows were read and why they went. The one check behind validation (a whole file) and the
    streamed runs (chunk by chunk, at the end)."""
    if rows_kept >= 2:
        return
    if rows_read == 0:
        raise ImutoolError("no data rows", path=source)
    why = f"; {duplicates} dropped with a repeated time stamp" if duplicates else ""
    raise ImutoolError(
        f"{rows_kept} row(s) left of {rows_read} read{why}: a recording needs at least two rows at different "
        "times (it has no duration)",
        path=source,
    )


def all_nan_sensors(rec: Recording) -> list[str]:
    """The sensor channels (gyro, accel, mag) of ``rec`` whose every value is missing (NaN)."""
    return [k for k in SENSOR_CHANNELS if k in rec.channels and len(rec) and bool(np.all(np.isnan(rec[k])))]


def missing_sensor_warnings(names: list[str]) -> list[str]:
    """One warning per sensor channel that is NaN in every row (the others carry the recording)."""
    return [f"MISSING: every value of {k} is NaN or empty: the channel carries nothing" for k in names]


def refuse_without_sensor_data(names: list[str], present: list[str], source: str) -> None:
    """Refuse a recording whose every sensor channel (``present``) is missing in every row (``names``)."""
    if names and set(names) >= set(present):
        raise ImutoolError(
            f"every value of {', '.join(names)} is missing (NaN or empty): no sensor data to use", path=source
        )


@dataclass
class TimeReport:
    """What :meth:`Recording.validated` found and did (counts are of input rows)."""

    n_rows: int = 0
    duplicates: int = 0
    duplicates_conflicting: int = 0
    backwards: int = 0
    nan_rows: int = 0
    nan_by_channel: dict[str, int] = field(default_factory=dict)
    gaps: list[tuple[float, float]] = field(default_factory=list)  # (start time, length s)
    median_dt: float = float("nan")
    actions: list[str] = field(default_factory=list)
    # many clocks: per stream, its median step (s) and gaps on its own samples; then ``median_dt``/``gaps`` are
    # those of the stream with the most samples
    stream_median_dt: dict[str, float] = field(default_factory=dict)
    stream_gaps: dict[str, list[tuple[float, float]]] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return {
            "rows": self.n_rows,
            "duplicate_timestamps": self.duplicates,
            "duplicate_timestamps_with_different_data": self.duplicates_conflicting,
            "backwards_steps": self.backwards,
            "rows_with_nan": self.nan_rows,
            "nan_by_channel": dict(self.nan_by_channel),
            "gaps": [{"start_s": float(a), "length_s": float(b)} for a, b in self.gaps],
            "median_dt_s": float(self.median_dt),
            "actions": list(self.actions),
            **(
                {
                    "streams": {
                        k: {
                            "median_dt_s": float(v),
                            "gaps": [{"start_s": float(a), "length_s": float(b)} for a, b in self.stream_gaps[k]],
                        }
                        for k, v in self.stream_median_dt.items()
                    }
                }
                if self.stream_median_dt
                else {}
            ),
        }


@dataclass
class Recording:
    """Time series of sensor channels with units and metadata.

    ``time`` is float64 seconds (strictly increasing after :meth:`validated`). ``channels`` maps a name to an
    array of shape (N,) or (N, k). ``units`` maps a channel name to its unit (see :mod:`formats.units`).
    ``meta`` holds sensor, frame, source file, rate, mounting, calibration applied, ...
    ``columns`` maps a channel to its CSV column names (filled in automatically).

    **Many clocks.** A log of several streams (NMEA sentence types, bag topics, a ``--with`` file) is one table
    whose rows are the union of every stream's sample times. ``meta['streams']`` maps a stream name to its
    channels, and ``stream_rows`` a stream name to the boolean mask of the rows where that stream has a sample of
    its own. A row of one stream is never a missing sample of another: take a channel on its own rows with
    :meth:`series` or :meth:`stream`. A channel in no stream is sampled on every row (a single-clock recording has
    no streams at all, and every method below then behaves as it always did).
    """

    time: np.ndarray
    channels: dict[str, np.ndarray] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    columns: dict[str, list[str]] = field(default_factory=dict)
    stream_rows: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.time = np.ascontiguousarray(self.time, dtype=np.float64)
        if self.time.ndim != 1:
            raise ImutoolError("time must be one-dimensional")
        for k in list(self.stream_rows):
            m = np.asarray(self.stream_rows[k], dtype=bool)
            if m.shape != self.time.shape:
                raise ImutoolError(f"stream {k!r} has {m.shape[0]} row flags for {self.time.shape[0]} rows")
            self.stream_rows[k] = m
        for name in list(self.channels):
            self.channels[name] = self._check(name, self.channels[name])
            self.columns.setdefault(name, default_columns(name, self._width(self.channels[name])))
            if name not in self.units:
                cu = canonical_unit(name)
                if cu is not None:
                    self.units[name] = cu

    # -- basic access -------------------------------------------------------------------------------------
    @staticmethod
    def _width(a: np.ndarray) -> int:
        return 1 if a.ndim == 1 else a.shape[1]

    def _check(self, name: str, data: Any) -> np.ndarray:
        a = np.asarray(data)
        if a.dtype.kind not in "fiub":
            raise ImutoolError(f"channel {name!r} is not numeric")
        a = np.ascontiguousarray(a, dtype=np.float64) if a.dtype.kind == "f" or a.dtype.kind in "iub" else a
        if a.ndim not in (1, 2) or a.shape[0] != self.time.shape[0]:
            raise ImutoolError(
                f"channel {name!r} has shape {a.shape}; expected ({self.time.shape[0]},) or ({self.time.shape[0]}, k)"
            )
        return a

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def __contains__(self, name: str) -> bool:
        return name in self.channels

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.channels[name]
        except KeyError:
            raise ImutoolError(
                f"channel {name!r} not in recording (has: {', '.join(self.channels) or 'none'})"
            ) from None

    def get(self, name: str, unit: str | None = None) -> np.ndarray:
        """Channel values, converted to ``unit`` if given (e.g. ``rec.get('roll', 'rad')``)."""
        a = self[name]
        if unit is None:
            return a
        have = self.units.get(name)
        if have is None:
            raise ImutoolError(f"channel {name!r} has no unit; cannot convert to {unit!r}")
        return _units.convert(a, have, unit)

    def in_unit(self, name: str, unit: str) -> np.ndarray:
        """Channel values in ``unit``: converted when the channel states a unit, as stored when it states none
        (the caller's unit is then taken as the channel's, as for a CSV column read without one)."""
        return self.get(name, unit) if self.units.get(name) else self[name]

    def add(self, name: str, data: Any, unit: str | None = None, columns: list[str] | None = None) -> None:
        """Add or replace a channel (unit defaults to the canonical unit of the name)."""
        a = self._check(name, data)
        self.channels[name] = a
        self.columns[name] = list(columns) if columns else default_columns(name, self._width(a))
        if unit is None:
            unit = canonical_unit(name)
        if unit is not None:
            self.units[name] = unit
        elif name in self.units:
            del self.units[name]

    def remove(self, name: str) -> None:
        self.channels.pop(name, None)
        self.units.pop(name, None)
        self.columns.pop(name, None)

    def copy(self) -> Recording:
        return Recording(
            self.time.copy(),
            {k: v.copy() for k, v in self.channels.items()},
            dict(self.units),
            copy.deepcopy(self.meta),
            {k: list(v) for k, v in self.columns.items()},
            {k: v.copy() for k, v in self.stream_rows.items()},
        )

    # -- many clocks (class docstring) ----------------------------------------------------------------------
    @property
    def streams(self) -> dict[str, list[str]]:
        """Stream name → its channels (empty for a single-clock recording)."""
        return {k: list(v) for k, v in (self.meta.get("streams") or {}).items()}

    @property
    def multi_clock(self) -> bool:
        """True when some channel is sampled on only part of the rows (its own stream's)."""
        return any(not bool(m.all()) for m in self.stream_rows.values())

    def stream_of(self, name: str) -> str | None:
        """The stream a channel belongs to (None: sampled on every row)."""
        for k, chans in (self.meta.get("streams") or {}).items():
            if name in chans:
                return k
        return None

    def own_rows(self, name: str) -> np.ndarray:
        """Boolean mask of the rows that are samples of channel ``name`` (or of stream ``name``)."""
        if name in self.stream_rows:
            return self.stream_rows[name]
        k = self.stream_of(name)
        if k is not None and k in self.stream_rows:
            return self.stream_rows[k]
        return np.ones(len(self), dtype=bool)

    def series(self, name: str, unit: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(time s, values) of a channel on its own samples only, values converted to ``unit`` if given."""
        m = self.own_rows(name)
        a = self.get(name, unit) if unit is not None else self[name]
        if bool(m.all()):
            return self.time, a
        return self.time[m], a[m]

    def stream(self, name: str) -> Recording:
        """The recording of one stream on its own rows: ``name`` is a stream or one of its channels; the stream's
        channels (or, for a channel in no stream, the channels in no stream) on their samples, the metadata kept
        and ``meta['stream']`` naming it. A single-clock recording returns itself."""
        if not self.stream_rows:
            return self
        key = name if name in self.stream_rows else self.stream_of(name)
        if key is None:
            inside = {c for chans in self.streams.values() for c in chans}
            keep = [c for c in self.channels if c not in inside]
            mask = np.ones(len(self), dtype=bool)
        else:
            keep = [c for c in self.streams.get(key, []) if c in self.channels]
            mask = self.stream_rows[key]
        out = Recording(
            self.time[mask],
            {c: self.channels[c][mask] for c in keep},
            {c: self.units[c] for c in keep if c in self.units},
            copy.deepcopy(self.meta),
            {c: list(self.columns[c]) for c in keep},
        )
        out.meta.pop("streams", None)
        if key is not None:
            out.meta["stream"] = key
        return out

    def set_stream(self, name: str, channels: list[str], rows: np.ndarray) -> None:
        """Declare stream ``name``: its channels and the boolean mask of the rows that are its samples."""
        m = np.asarray(rows, dtype=bool)
        if m.shape != self.time.shape:
            raise ImutoolError(f"stream {name!r} has {m.shape[0]} row flags for {len(self)} rows")
        streams = dict(self.meta.get("streams") or {})
        for k in list(streams):
            streams[k] = [c for c in streams[k] if c not in channels]
            if not streams[k]:
                del streams[k]
                self.stream_rows.pop(k, None)
        streams[name] = list(channels)
        self.meta["streams"] = streams
        self.stream_rows[name] = m

    def restore_streams(self) -> None:
        """Rebuild ``stream_rows`` from ``meta['streams']`` after a file round trip: a row is a sample of a stream
        where any of its channels has a value (a sample whose every field was empty is not told apart from no
        sample in a CSV, so it is not one here)."""
        for k, chans in (self.meta.get("streams") or {}).items():
            if k in self.stream_rows:
                continue
            m = np.zeros(len(self), dtype=bool)
            for c in chans:
                if c in self.channels:
                    a = self.channels[c]
                    f = np.isfinite(a) if a.dtype.kind == "f" else np.ones(a.shape, dtype=bool)
                    m |= f.any(axis=1) if f.ndim > 1 else f
            self.stream_rows[k] = m

    def held(self, name: str, t: np.ndarray, max_age_steps: float = 3.0) -> np.ndarray:
        """Channel ``name`` at times ``t`` (s): its latest own sample at or before each time (sample and hold, never
        another stream's row); NaN before its first sample and where that sample is older than ``max_age_steps``
        × the channel's median step (a gap is not bridged)."""
        ts, a = self.series(name)
        a = np.asarray(a, dtype=float)
        t = np.asarray(t, dtype=float)
        out = np.full((len(t),) + a.shape[1:], np.nan)
        if ts.size == 0:
            return out
        idx = np.searchsorted(ts, t, side="right") - 1
        ok = idx >= 0
        if ts.size > 1:
            d = np.diff(ts)
            d = d[d > 0]
            if d.size:
                ok &= (t - ts[np.maximum(idx, 0)]) <= max_age_steps * float(np.median(d))
        out[ok] = a[idx[ok]]
        return out

    def on_clock(self, name: str, max_age_steps: float = 3.0) -> Recording:
        """The recording on the clock of one stream (``name``: a stream or one of its channels): that stream's
        channels on their own samples, every other channel held at its latest own sample at or before each time
        (:meth:`held`), and ``meta['resampled']`` saying which channels were held onto which clock. A
        single-clock recording returns itself. The one way a command puts channels of several clocks on a
        common grid."""
        if not self.multi_clock:
            return self
        base = self.stream(name)
        key = base.meta.get("stream", "rows in no stream")
        moved = [c for c in self.channels if c not in base.channels]
        for c in moved:
            base.add(c, self.held(c, base.time, max_age_steps), self.units.get(c), columns=self.columns.get(c))
        if moved:
            base.meta["resampled"] = (
                f"{', '.join(moved)} held at their latest own sample at or before each {key} time "
                f"(none older than {max_age_steps:g} of their own steps)"
            )
        return base

    def stream_summary(self) -> dict[str, dict[str, Any]]:
        """Per stream: its channels, samples, first and last time (s), duration (s) and median rate (Hz)."""
        out: dict[str, dict[str, Any]] = {}
        for k, chans in self.streams.items():
            t = self.time[self.own_rows(k)]
            tm = self.stream_timing(k)
            out[k] = {
                "channels": list(chans),
                "samples": int(t.size),
                "start_s": float(t[0]) if t.size else float("nan"),
                "end_s": float(t[-1]) if t.size else float("nan"),
                "duration_s": float(t[-1] - t[0]) if t.size > 1 else 0.0,
                "rate_hz": float(tm["rate_hz"]) if tm.get("rate_hz") else float("nan"),
                "step_s": tm.get("step_s"),
                "bursty": bool(tm.get("bursty")),
                "gaps": int(tm.get("gaps", 0)),
                "missing_s": float(tm.get("missing_s", 0.0)),
            }
        return out

    def stream_timing(self, name: str, gap_factor: float = 3.0, max_gaps: int = 5) -> dict[str, Any]:
        """Rate, bursts and gaps of a stream (or a channel's stream) on its own times
        (:func:`formats.timing.stream_timing`; no gap shorter than the resolution its reader states in
        ``meta['stream_time_resolution_s']``, e.g. NMEA sentences placed by their position between fixes)."""
        from .timing import stream_timing

        key = name if name in self.stream_rows else (self.stream_of(name) or name)
        res = float((self.meta.get("stream_time_resolution_s") or {}).get(key, 0.0) or 0.0)
        return stream_timing(self.time[self.own_rows(name)], gap_factor, max_gaps, min_gap_s=res)

    @property
    def duration(self) -> float:
        return float(self.time[-1] - self.time[0]) if len(self) > 1 else 0.0

    @property
    def rate_hz(self) -> float:
        """Nominal sample rate: 1 / median time step (NaN for fewer than two samples)."""
        if len(self) < 2:
            return float("nan")
        d = np.diff(self.time)
        d = d[d > 0]
        return float(1.0 / np.median(d)) if d.size else float("nan")

    def column_names(self) -> list[str]:
        out = ["time"]
        for name in self.channels:
            out.extend(self.columns[name])
        return out

    def select(self, rows: np.ndarray | slice) -> Recording:
        """A new recording with the given rows (boolean mask, index array or slice); arrays are copies."""
        take = (lambda a: a[rows].copy()) if isinstance(rows, slice) else (lambda a: a[rows])
        return Recording(
            take(self.time),
            {k: take(v) for k, v in self.channels.items()},
            dict(self.units),
            copy.deepcopy(self.meta),
            {k: list(v) for k, v in self.columns.items()},
            {k: take(v) for k, v in self.stream_rows.items()},
        )

    def slice_time(self, start: float | None = None, end: float | None = None) -> Recording:
        """Rows with start ≤ time < end (seconds, same time base as ``time``)."""
        lo = 0 if start is None else int(np.searchsorted(self.time, start, side="left"))
        hi = len(self) if end is None else int(np.searchsorted(self.time, end, side="left"))
        return self.select(slice(lo, hi))

    # -- validation ---------------------------------------------------------------------------------------
    def validated(
        self,
        duplicates: str = "drop",
        backwards: str = "error",
        gap_factor: float = 3.0,
        source: str | None = None,
        min_rows: int = 2,
    ) -> tuple[Recording, TimeReport]:
        """Check the time base and return (clean recording, report).

        duplicates: ``drop`` keeps the first of rows sharing a timestamp (identical or not; conflicting ones
        are counted separately), ``mean`` averages them, ``error`` refuses.
        backwards: ``error`` refuses a time that goes backwards, ``sort`` sorts rows by time (stable),
        ``drop`` drops rows earlier than the latest time seen.
        gap_factor: a step longer than gap_factor × median step is reported as a gap (never filled here).
        NaN values are counted per channel and kept (estimators skip them sample by sample).
        min_rows: fewer rows left than this (2: a recording needs a duration; 0 for a chunk of a stream, checked
        as a whole at its end) is an ImutoolError (:func:`require_samples`); so is a recording whose every sensor
        channel (gyro, accel, mag) is NaN in every row.
        """
        src = source or self.meta.get("source", "recording")
        rep = TimeReport(n_rows=len(self))
        rec = self
        t = rec.time
        if not np.all(np.isfinite(t)):
            bad = int(np.flatnonzero(~np.isfinite(t))[0])
            raise ImutoolError(f"time is not finite at row {bad + 1}", path=src)
        if len(t) and float(np.max(np.abs(t))) > MAX_TIME_S:  # 1e300 would make every window loop endless
            bad = int(np.flatnonzero(np.abs(t) > MAX_TIME_S)[0])
            raise ImutoolError(
                f"time {t[bad]:.6g} s at row {bad + 1} is beyond ±{MAX_TIME_S:.0e} s (3 000 years): "
                "not seconds? give the time column's unit (--columns 'stamp=time:ms')",
                path=src,
            )
        if len(rec) >= 2:
            d = np.diff(t)
            nb = int(np.count_nonzero(d < 0))
            rep.backwards = nb
            if nb:
                if backwards == "error":
                    i = int(np.flatnonzero(d < 0)[0])
                    raise ImutoolError(
                        f"time goes backwards at row {i + 2} ({t[i]:.6f} s → {t[i + 1]:.6f} s); "
                        f"{nb} such steps (use --backwards sort|drop to accept)",
                        path=src,
                    )
                if backwards == "sort":
                    rec = rec.select(np.argsort(t, kind="stable"))
                    rep.actions.append(f"sorted {nb} out-of-order rows by time")
                elif backwards == "drop":
                    keep = t >= np.maximum.accumulate(t)
                    rec = rec.select(keep)
                    rep.actions.append(f"dropped {int((~keep).sum())} rows earlier than the time before them")
                else:
                    raise ImutoolError(f"unknown backwards policy {backwards!r} (error, sort, drop)")
            t = rec.time
            same = np.diff(t) == 0
            nd = int(np.count_nonzero(same))
            rep.duplicates = nd
            if nd and rec.multi_clock:  # rows of different streams at one time are not duplicates
                rec = _collapse_streams(rec, rep, duplicates, src)
            elif nd:
                idx = np.flatnonzero(same)
                conflicting = 0
                for a in rec.channels.values():
                    x, y = a[idx], a[idx + 1]
                    neq = ~((x == y) | (np.isnan(x) & np.isnan(y)))
                    if neq.ndim > 1:
                        neq = neq.any(axis=1)
                    conflicting = max(conflicting, int(np.count_nonzero(neq)))
                rep.duplicates_conflicting = conflicting
                if duplicates == "error":
                    raise ImutoolError(
                        f"{nd} duplicate timestamps (first at row {idx[0] + 2}, t = {t[idx[0]]:.6f} s); "
                        "use --duplicates drop|mean to accept",
                        path=src,
                    )
                first = np.concatenate([[True], ~same])
                if duplicates == "drop":
                    rec = rec.select(first)
                    rep.actions.append(
                        f"dropped {nd} rows with a repeated timestamp ({conflicting} of them with different "
                        "data; the first row of each timestamp kept)"
                    )
                elif duplicates == "mean":
                    group = np.cumsum(first) - 1
                    counts = np.bincount(group)
                    chans = {}
                    for k, a in rec.channels.items():
                        a2 = a.reshape(len(a), -1)
                        s = np.stack([np.bincount(group, a2[:, j]) for j in range(a2.shape[1])], axis=1)
                        s /= counts[:, None]
                        chans[k] = s.reshape((-1,) + a.shape[1:])
                    rec = Recording(
                        rec.time[first],
                        chans,
                        dict(rec.units),
                        copy.deepcopy(rec.meta),
                        {k: list(v) for k, v in rec.columns.items()},
                        {k: np.bincount(group, m.astype(float)) > 0 for k, m in rec.stream_rows.items()},
                    )
                    rep.actions.append(f"averaged {nd} rows sharing a timestamp with their first row")
                else:
                    raise ImutoolError(f"unknown duplicates policy {duplicates!r} (drop, mean, error)")
        if rec.multi_clock:  # each stream's step and gaps on its own samples; the table's steps mean nothing
            most = 0
            for k in rec.stream_rows:
                ts = rec.time[rec.stream_rows[k]]
                if ts.size < 2:
                    continue
                tm = rec.stream_timing(k, gap_factor, max_gaps=ts.size)
                med = float(tm.get("step_s") or np.median(np.diff(ts)))
                rep.stream_gaps[k] = [(float(a), float(b)) for a, b in tm.get("first_gaps", [])]
                rep.stream_median_dt[k] = med
                if ts.size > most:
                    most, rep.median_dt, rep.gaps = ts.size, med, rep.stream_gaps[k]
        elif len(rec) >= 2:
            t = rec.time
            d = np.diff(t)
            med = float(np.median(d))
            rep.median_dt = med
            gi = np.flatnonzero(d > gap_factor * med)
            rep.gaps = [(float(t[i]), float(d[i])) for i in gi]
        nan_any = np.zeros(len(rec), dtype=bool)
        for k, a in rec.channels.items():
            m = np.isnan(a) if a.dtype.kind == "f" else np.zeros(a.shape, dtype=bool)
            if m.ndim > 1:
                m = m.any(axis=1)
            m &= rec.own_rows(k)  # another stream's row is not a missing sample of this channel
            c = int(np.count_nonzero(m))
            if c:
                rep.nan_by_channel[k] = c
            nan_any |= m
        rep.nan_rows = int(np.count_nonzero(nan_any))
        if min_rows and len(rec) < min_rows:
            require_samples(len(self), len(rec), src, rep.duplicates)
        if min_rows:
            refuse_without_sensor_data(all_nan_sensors(rec), [k for k in SENSOR_CHANNELS if k in rec.channels], src)
        rec.meta["validation"] = rep.as_dict()
        return rec, rep

    # -- mounting -----------------------------------------------------------------------------------------
    def mounted(
        self,
        remap: str | np.ndarray = "x,y,z",
        misalignment_deg: tuple[float, float, float] = (0.0, 0.0, 0.0),
        vector_channels: tuple[str, ...] = ("gyro", "accel", "mag"),
    ) -> Recording:
        """Transform sensor-axis channels into the vessel body frame (FRD).

        body = R_mis · M · sensor, where M is the signed axis permutation (``"x,-y,-z"``) and R_mis the small
        misalignment rotation Rz(yaw)·Ry(pitch)·Rx(roll) (degrees, body axes). Vector channels listed are
        rotated; a quaternion ``q`` (a device's sensor→NED) becomes body→NED: q_b = q_s ⊗ q(C)ᵀ with C = R_mis·M.
        Truth passed through (``ref_*``) is in its own frame and is left as it is — unless the recording declares
        its ``ref_q`` sensor→NED (:func:`ref_is_sensor_frame`: ``meta['ref_frame'] = 'sensor'``, or a ``ref_q*``
        header saying ``sensor->NED``, as BROAD's files do): then it is turned into body→NED as ``q`` is. Either
        way ``meta['ref_frame']`` becomes ``'body'`` and ``meta['ref_mounting']`` says what was done. The mounting
        is recorded in ``meta['mounting']``.
        """
        m = parse_axis_remap(remap) if isinstance(remap, str) else np.asarray(remap, dtype=float)
        r = rotation_about_axes(*np.radians(misalignment_deg)) @ m
        out = self.copy()
        for name in vector_channels:
            if name in out.channels:
                out.channels[name] = out.channels[name] @ r.T
        qc = matrix_to_quat(r)  # rotates sensor vectors into body
        sensor_ref = ref_is_sensor_frame(self.meta)
        for name in ("q", "ref_q") if sensor_ref else ("q",):
            if name in out.channels and out.channels[name].shape[1:] == (4,):
                out.channels[name] = quat_multiply(out.channels[name], quat_conjugate(qc))
        if any(n.startswith("ref_") for n in out.channels) or sensor_ref:
            out.meta["ref_frame"] = REF_BODY
            out.meta["ref_mounting"] = (
                "ref_q declared sensor→NED: turned into body→NED by the mounting"
                if sensor_ref and "ref_q" in out.channels
                else "ref_* truth in its own (body) frame: not rotated by the mounting"
            )
        spec = remap if isinstance(remap, str) else None
        out.meta["mounting"] = {
            "remap": spec if spec is not None else np.asarray(m).tolist(),
            "misalignment_deg": [float(v) for v in misalignment_deg],
            "matrix_sensor_to_body": r.tolist(),
        }
        out.meta["frame"] = "vessel body FRD (x bow, y starboard, z down)"
        return out


REF_SENSOR, REF_BODY = "sensor", "body"
"""``meta['ref_frame']``: what a recording's ``ref_q`` rotates into NED — the sensor's axes (a mounting turns it into
the body's, :meth:`Recording.mounted`) or the body's (left alone)."""


def ref_is_sensor_frame(meta: dict[str, Any]) -> bool:
    """Whether ``meta`` declares the reference quaternion sensor→NED: ``ref_frame: sensor``, or (no ``ref_frame``)
    a ``ref_q*``/``ref_q`` header line that says ``sensor->NED`` (or ``sensor→NED``), as BROAD's files do."""
    declared = meta.get("ref_frame")
    if declared is not None:
        return str(declared).strip().lower() == REF_SENSOR
    text = " ".join(str(meta.get(k, "")) for k in ("ref_q*", "ref_q")).lower().replace(" ", "")
    return "sensor->ned" in text or "sensor→ned" in text


def parse_mounting(spec: str) -> tuple[str, tuple[float, float, float]]:
    """Parse ``"x,-y,-z"`` or ``"x,-y,-z;0.5,-0.2,1.0"`` (remap; misalignment roll,pitch,yaw in deg)."""
    remap, _, mis = spec.partition(";")
    parse_axis_remap(remap)
    angles = (0.0, 0.0, 0.0)
    if mis.strip():
        try:
            vals = tuple(float(v) for v in re.split(r"[,\s]+", mis.strip()))
        except ValueError:
            raise ImutoolError(f"mounting {spec!r}: misalignment must be three numbers in degrees") from None
        if len(vals) != 3:
            raise ImutoolError(f"mounting {spec!r}: misalignment must be three numbers (roll,pitch,yaw deg)")
        angles = vals  # type: ignore[assignment]
    return remap, angles


def _collapse_streams(rec: Recording, rep: TimeReport, duplicates: str, src: str) -> Recording:
    """Rows sharing a time in a many-clock recording become one: a channel takes its first own sample there
    (``drop``) or the mean of its own samples (``mean``); only two samples of one stream at one time are
    duplicates (counted in ``rep``; ``error`` refuses them). Rows of different streams merged are counted too."""
    t = rec.time
    first = np.concatenate([[True], np.diff(t) != 0])
    group = np.cumsum(first) - 1
    ng = int(group[-1]) + 1
    dup = conflicting = 0
    for m in rec.stream_rows.values():
        g = group[m]
        dup += int(np.count_nonzero(np.diff(g) == 0))
    rep.duplicates = dup
    if dup and duplicates == "error":
        raise ImutoolError(
            f"{dup} duplicate timestamps within a stream; use --duplicates drop|mean to accept", path=src
        )
    if duplicates not in ("drop", "mean", "error"):
        raise ImutoolError(f"unknown duplicates policy {duplicates!r} (drop, mean, error)")
    chans = {}
    for k, a in rec.channels.items():
        own = np.flatnonzero(rec.own_rows(k))
        a2 = a.reshape(len(a), -1).astype(float)
        if duplicates == "mean":
            cnt = np.bincount(group[own], minlength=ng).astype(float)
            v = np.stack([np.bincount(group[own], a2[own, j], minlength=ng) for j in range(a2.shape[1])], axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                v = np.where(cnt[:, None] > 0, v / np.maximum(cnt, 1)[:, None], np.nan)
        else:
            fo = np.full(ng, len(a))
            np.minimum.at(fo, group[own], own)  # the earliest own row of each time
            v = np.where((fo < len(a))[:, None], a2[np.minimum(fo, len(a) - 1)], np.nan)
        rep_i = np.flatnonzero(np.diff(group[own]) == 0)  # two own samples at one time: counted under every policy
        if rep_i.size:
            x, y = a2[own[rep_i]], a2[own[rep_i + 1]]
            neq = ~((x == y) | (np.isnan(x) & np.isnan(y)))
            conflicting = max(conflicting, int(np.count_nonzero(neq.any(axis=1))))
        chans[k] = v.reshape((-1,) + a.shape[1:])
    rep.duplicates_conflicting = conflicting
    out = Recording(
        t[first],
        chans,
        dict(rec.units),
        copy.deepcopy(rec.meta),
        {k: list(v) for k, v in rec.columns.items()},
        {k: np.bincount(group, m.astype(float), minlength=ng) > 0 for k, m in rec.stream_rows.items()},
    )
    merged = len(rec) - ng - dup
    if merged:
        rep.actions.append(f"joined {merged} rows of different streams sharing a timestamp into one row each")
    if dup:
        how = "averaged with" if duplicates == "mean" else "dropped after"
        rep.actions.append(
            f"{dup} samples repeating a timestamp of their own stream {how} the first ({conflicting} with different "
            "data)"
        )
    return out


def join_streams(recordings: list[Recording], names: list[str], prefixes: list[str] | None = None) -> Recording:
    """Join recordings that keep their own clocks into one many-clock recording, without resampling.

    The table's rows are the union of every input's times; each input becomes a stream (``names[i]``) whose
    channels have values on its own rows and NaN elsewhere (another stream's rows, never read as missing
    samples: see :class:`Recording`). An input that is itself many-clock keeps its streams (named
    ``names[i] + ':' + stream``). Channel names that clash take ``prefixes[i]`` (default ``r{i+1}_``).
    """
    if not recordings:
        raise ImutoolError("join: no recordings given")
    for r, name in zip(recordings, names, strict=False):
        if len(r.time) > 1 and not np.all(np.diff(r.time) > 0):  # a repeated time would keep only its last row
            raise ImutoolError(
                "join: its time is not strictly increasing (validate it first: --duplicates/--backwards)",
                path=r.meta.get("source", name),
            )
    t = np.unique(np.concatenate([r.time for r in recordings]))
    out = Recording(t, meta=copy.deepcopy(recordings[0].meta))
    out.meta.pop("streams", None)
    out.meta["joined_from"] = [r.meta.get("source", "?") for r in recordings]
    for i, r in enumerate(recordings):
        idx = np.searchsorted(t, r.time)
        sub = r.streams or {names[i]: list(r.channels)}
        renamed: dict[str, str] = {}
        for name, a in r.channels.items():
            new = name
            if name in out.channels:
                new = (prefixes[i] if prefixes else f"r{i + 1}_") + name
            full = np.full((len(t),) + a.shape[1:], np.nan)
            full[idx] = a
            cols = r.columns.get(name) if new == name else None
            out.add(new, full, r.units.get(name), columns=cols)
            renamed[name] = new
        inside = {c for chans in sub.values() for c in chans}
        rest = [c for c in r.channels if c not in inside]
        for k, chans in sub.items():
            rows = np.zeros(len(t), dtype=bool)
            rows[idx[r.own_rows(k)] if r.streams else idx] = True
            label = names[i] if not r.streams else f"{names[i]}:{k}"
            out.set_stream(label, [renamed[c] for c in chans if c in renamed], rows)
        if rest and r.streams:
            rows = np.zeros(len(t), dtype=bool)
            rows[idx] = True
            out.set_stream(names[i], [renamed[c] for c in rest], rows)
    return out


def merge(
    recordings: list[Recording],
    clock: Recording | np.ndarray | float | None = None,
    prefixes: list[str] | None = None,
) -> Recording:
    """Merge recordings sampled on different clocks onto one clock by linear interpolation.

    clock: a recording (its time base), an array of times, a rate in Hz (uniform grid over the common time
    span), or None (the time base of the first recording). Only the time span all inputs cover is kept
    (no extrapolation). Quaternion channels are interpolated component-wise and renormalised; channels whose
    names clash get the given prefixes (or ``r1_``, ``r2_``...). Samples next to a NaN stay NaN. A many-clock
    input's channel is interpolated from its own samples (another stream's row is not a NaN of it).
    """
    if not recordings:
        raise ImutoolError("merge: no recordings given")
    t0 = max(float(r.time[0]) for r in recordings)
    t1 = min(float(r.time[-1]) for r in recordings)
    if t1 <= t0:
        raise ImutoolError("merge: the recordings do not overlap in time")
    if clock is None:
        clock = recordings[0]
    if isinstance(clock, Recording):
        t = clock.time
    elif np.isscalar(clock):
        rate = float(clock)  # type: ignore[arg-type]
        t = t0 + np.arange(int(np.floor((t1 - t0) * rate)) + 1) / rate
    else:
        t = np.asarray(clock, dtype=float)
    t = t[(t >= t0) & (t <= t1)]
    out = Recording(t, meta={"merged_from": [r.meta.get("source", "?") for r in recordings]})
    seen: set[str] = set()
    for i, r in enumerate(recordings):
        for name, a in r.channels.items():
            new = name
            if name in seen:
                new = (prefixes[i] if prefixes else f"r{i + 1}_") + name
            seen.add(new)
            ts, a_own = r.series(name)  # many clocks: from the channel's own samples only
            a2 = a_own.reshape(len(a_own), -1).astype(float)
            cols = np.stack([np.interp(t, ts, a2[:, j]) for j in range(a2.shape[1])], axis=1)
            if a.ndim == 1:
                cols = cols[:, 0]
            elif a.shape[1] == 4 and name.endswith("q"):
                cols = cols / np.linalg.norm(cols, axis=1, keepdims=True)
            out.add(new, cols, r.units.get(name), columns=None if new != name else r.columns.get(name))
    return out
