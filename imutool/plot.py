"""Plots of a recording's channels: the route behind ``imutool plot`` and ``imutool batch plot``.

One subplot per channel, units on the axes (angular rates in deg/s, angles in deg), time in seconds from the first
sample. Long recordings are decimated by a min/max envelope per bucket (peaks survive, at most ``max_points`` per
line); CSV files are streamed in chunks so a many-million-row file plots in bounded memory.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

import formats
from formats import Recording
from formats.atomic import atomic_path
from formats.errors import ImutoolError
from formats.recording import require_samples
from imutool.routes import OnInput, RouteResult, load_input

_FORMATS = {".png": "png", ".pdf": "pdf", ".svg": "svg"}


def match_channels(available: list[str], wanted: tuple[str, ...], path: str) -> list[str]:
    """Channel names for each request: an exact name, else every channel starting with it (``ref`` → ref_*)."""
    out: list[str] = []
    for w in wanted:
        hits = [w] if w in available else [c for c in available if c.startswith(w)]
        if not hits:
            raise ImutoolError(f"no channel matches {w!r} (has: {', '.join(available) or 'none'})", path=path)
        out += [h for h in hits if h not in out]
    return out


def envelope(t: np.ndarray, y: np.ndarray, bucket: int) -> tuple[np.ndarray, np.ndarray]:
    """Min/max decimation: per bucket of ``bucket`` samples keep the min and the max of every column
    (2 points per bucket, in time order), so spikes stay visible. y is (N, k)."""
    if bucket <= 1 or len(t) < 4 * bucket:
        return t, y
    n = (len(t) // bucket) * bucket
    tb = t[:n].reshape(-1, bucket)
    yb = y[:n].reshape(-1, bucket, y.shape[1])
    with np.errstate(all="ignore"):
        lo = np.nanmin(np.where(np.isnan(yb), np.inf, yb), axis=1)
        hi = np.nanmax(np.where(np.isnan(yb), -np.inf, yb), axis=1)
    lo[~np.isfinite(lo)] = np.nan
    hi[~np.isfinite(hi)] = np.nan
    t2 = np.stack([tb[:, 0], tb[:, -1]], axis=1).reshape(-1)
    y2 = np.stack([lo, hi], axis=1).reshape(-1, y.shape[1])
    if n < len(t):  # the partial last bucket: its min and max too
        tail = y[n:]
        with np.errstate(all="ignore"):
            tl = np.nanmin(np.where(np.isnan(tail), np.inf, tail), axis=0)
            th = np.nanmax(np.where(np.isnan(tail), -np.inf, tail), axis=0)
        tl[~np.isfinite(tl)] = np.nan
        th[~np.isfinite(th)] = np.nan
        t2 = np.concatenate([t2, [t[n], t[-1]]])
        y2 = np.concatenate([y2, tl[None, :], th[None, :]])
    return t2, y2


def own_samples(
    t: np.ndarray, y: np.ndarray, gap_steps: float = 3.0, own: np.ndarray | None = None, gap_s: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The rows of one channel that are its samples (y is (N, k)), so that a channel whose samples sit on rows of
    their own between other streams' rows (an NMEA log's HDT among other sentences) draws as a line; a NaN row is
    put back where a step is longer than ``gap_steps`` × the channel's median step (a real gap stays a gap).
    ``own``: the channel's own rows of a many-clock recording (:meth:`formats.Recording.own_rows`; a NaN there is
    a missing sample and breaks the line); without it, the rows that hold a value. ``gap_s``: the stream's own gap
    rule (:meth:`formats.Recording.stream_timing`, aware of bursts and of the reader's time resolution) instead of
    ``gap_steps`` × the median step."""
    ok = np.isfinite(y).any(axis=1) if own is None else np.asarray(own, dtype=bool)
    if ok.all() or ok.sum() < 2:
        return t, y
    idx = np.flatnonzero(ok)
    ts, ys = t[idx], y[idx]
    d = np.diff(ts)
    limit = gap_steps * float(np.median(d)) if gap_s is None else gap_s
    brk = np.flatnonzero((d > limit) & (np.diff(idx) > 1 if own is None else True))
    if brk.size:
        ts = np.insert(ts, brk + 1, 0.5 * (ts[brk] + ts[brk + 1]))
        ys = np.insert(ys, brk + 1, np.nan, axis=0)
    return ts, ys


def _collect(
    path: str,
    wanted: tuple[str, ...] | list[str],
    start: float | None,
    end: float | None,
    max_points: int,
    io: dict[str, Any],
    inputs: list[dict[str, Any]],
    strict: bool = False,
    on_input: OnInput | None = None,
) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], Recording, int]:
    """Decimated (t, y) per matched channel; streams CSV files, reads others whole (their report into
    ``inputs``)."""
    in_memory = ("mounting", "calibration_file", "with_files")
    plain_csv = formats.kind_of(path) == "csv" and not any(io.get(k) for k in in_memory)
    if plain_csv:
        from formats.csv import iter_csv

        size = os.path.getsize(path)
        parts: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        template = None
        t0 = None
        bucket = 1
        total = 0
        span = (np.inf, -np.inf)  # earliest and latest finite time seen
        csv_opts = {k: io.get(k) for k in ("columns", "profile", "time_column", "header_rows")}
        csv_opts["rate_hz"] = io.get("input_rate_hz")
        for chunk in iter_csv(path, chunk_rows=250_000, **csv_opts):
            if template is None:
                template = chunk
                names = match_channels(list(chunk.channels), wanted, path)
                t0 = float(chunk.time[0])
                est_rows = max(len(chunk), int(size / max(1, _bytes_per_row(path, len(chunk)))))
                bucket = max(1, -(-2 * est_rows // max_points))  # 2 points per bucket
            total += len(chunk)
            finite = chunk.time[np.isfinite(chunk.time)]
            if len(finite):
                span = (min(span[0], float(finite.min())), max(span[1], float(finite.max())))
            chunk = (
                chunk.slice_time(None if start is None else t0 + start, None if end is None else t0 + end)
                if (start is not None or end is not None)
                else chunk
            )
            if not len(chunk):
                continue
            chunk.restore_streams()  # a many-clock CSV: each channel on its stream's own rows
            for n in names:
                a = chunk[n].reshape(len(chunk), -1).astype(float)
                own, gap = _own(chunk, n)
                parts.setdefault(n, []).append(envelope(*own_samples(chunk.time - t0, a, own=own, gap_s=gap), bucket))
        if template is None:
            raise ImutoolError("no data rows", path=path)
        distinct = 2 if span[1] > span[0] else (1 if np.isfinite(span[0]) else 0)  # rows at different times
        require_samples(total, distinct, path, total - 1 if distinct == 1 else 0)
        out = {
            n: (np.concatenate([p[0] for p in parts[n]]), np.concatenate([p[1] for p in parts[n]]))
            for n in names
            if n in parts
        }
        return out, template, total
    rec, _ = load_input(path, inputs, strict=strict, on_input=on_input, validate=False, **io)
    if not len(rec):
        raise ImutoolError("no samples", path=path)
    names = match_channels(list(rec.channels), wanted, path)
    t0 = float(rec.time[0])
    if start is not None or end is not None:
        rec = rec.slice_time(None if start is None else t0 + start, None if end is None else t0 + end)
    bucket = max(1, -(-2 * len(rec) // max_points))
    out = {}
    for n in names:
        own, gap = _own(rec, n)
        y = rec[n].reshape(len(rec), -1).astype(float)
        out[n] = envelope(*own_samples(rec.time - t0, y, own=own, gap_s=gap), bucket)
    return out, rec, len(rec)


def _own(rec: Recording, name: str) -> tuple[np.ndarray | None, float | None]:
    """A channel's own rows and its stream's gap limit (s) in a many-clock recording; (None, None) otherwise."""
    if not rec.multi_clock:
        return None, None
    gap = rec.stream_timing(name).get("gap_longer_than_s")
    return rec.own_rows(name), (float(gap) if gap else None)


def _bytes_per_row(path: str, rows: int) -> float:
    """Mean bytes per data row from the first chunk's share of the file (an estimate for the bucket size)."""
    with open(path, "rb") as f:
        head = f.read(1 << 20)
    n = head.count(b"\n")
    return len(head) / max(n, 1)


def run_plot(
    source: str | os.PathLike,
    channels: tuple[str, ...] | list[str],
    output: str | os.PathLike,
    *,
    start: float | None = None,
    end: float | None = None,
    max_points: int = 20000,
    title: str | None = None,
    dpi: int = 120,
    strict: bool = False,
    on_input: OnInput | None = None,
    **load_options: Any,
) -> RouteResult:
    """Plot ``channels`` (names or prefixes: ``gyro``, ``ref`` → every ref_* channel) of ``source`` to ``output``
    (.png, .pdf or .svg, written atomically): ``start``/``end`` s from the first sample, at most ``max_points`` per
    line (min/max envelope), ``title`` (default the file name), ``dpi`` for PNG. A file other than a plain CSV is
    loaded unvalidated with ``load_options`` (columns, profile, ... calibration_file; ``strict``: its warnings are
    an error). The summary: output, channels drawn, rows read, points per line."""
    path = os.fspath(source)
    output = os.fspath(output)
    ext = Path(output).suffix.lower()
    if ext not in _FORMATS:
        raise ImutoolError(f"plot output must end in {', '.join(_FORMATS)} (got {output!r})")
    if max_points < 10:
        raise ImutoolError("--max-points must be at least 10")
    inputs: list[dict[str, Any]] = []
    series, rec, total = _collect(path, tuple(channels), start, end, max_points, load_options, inputs, strict, on_input)
    if not series:
        raise ImutoolError("no samples in the requested time window", path=path)
    series, empty = _with_values(series, path, start is not None or end is not None)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(series)
    fig, axes = plt.subplots(len(names), 1, sharex=True, figsize=(10, 1.2 + 2.2 * len(names)), squeeze=False)
    drawn = 0
    for ax, name in zip(axes[:, 0], names, strict=True):
        t, y = series[name]
        unit = rec.units.get(name)
        if unit in ("rad/s", "rad"):  # degrees at every user-facing surface
            y, unit = np.degrees(y), {"rad/s": "deg/s", "rad": "deg"}[unit]
        cols = rec.columns.get(name, [name])
        for j in range(y.shape[1]):
            ax.plot(t, y[:, j], lw=0.7, label=cols[j] if j < len(cols) else f"{name}[{j}]")
        drawn = max(drawn, len(t))
        ax.set_ylabel(f"{name} [{unit}]" if unit else name)
        ax.grid(True, alpha=0.3)
        if y.shape[1] > 1:
            ax.legend(loc="upper right", fontsize="small", ncol=min(4, y.shape[1]))
    axes[-1, 0].set_xlabel("time since first sample [s]")
    fig.suptitle(title or os.path.basename(path))
    fig.tight_layout()
    with atomic_path(output) as tmp:
        fig.savefig(tmp, format=_FORMATS[ext], dpi=dpi)
    plt.close(fig)
    summary: dict[str, Any] = {"output": output, "channels": names, "rows": total, "points_per_line": drawn}
    if empty:
        summary["not_drawn"] = empty
        summary["warnings"] = [f"not drawn: every value of {', '.join(empty)} is NaN or missing"]
    return RouteResult(summary, inputs)


def _with_values(
    series: dict[str, tuple[np.ndarray, np.ndarray]], path: str, windowed: bool
) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], list[str]]:
    """(the channels of ``series`` that hold a finite value, the names of those that hold none). None holding
    one is an ImutoolError naming them: empty axes would look like a plot."""
    empty = [n for n, (_, y) in series.items() if not np.isfinite(y).any()]
    if len(empty) == len(series):
        where = " in the requested time window" if windowed else ""
        raise ImutoolError(f"every value of {', '.join(empty)} is NaN or missing{where}: nothing to draw", path=path)
    return {n: v for n, v in series.items() if n not in empty}, empty
