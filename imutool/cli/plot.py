"""`imutool plot FILE CHANNEL... -o out.png|pdf`: one subplot per channel, units on the axes.

Long recordings are decimated by a min/max envelope per bucket (peaks survive, at most ``--max-points`` per
line); CSV files are streamed in chunks so a many-million-row file plots in bounded memory.
"""

from __future__ import annotations

import os
from pathlib import Path

import click
import numpy as np

import formats
from formats import Recording
from formats.atomic import atomic_path
from formats.errors import ImutoolError
from formats.recording import require_samples
from imutool.cli.common import emit_summary, input_options, load_input, safe_outputs

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


def _collect(
    path: str, wanted: tuple[str, ...], start: float | None, end: float | None, max_points: int, io: dict
) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], Recording, int]:
    """Decimated (t, y) per matched channel; streams CSV files, reads others whole."""
    plain_csv = formats.kind_of(path) == "csv" and not io.get("mounting") and not io.get("calibration_file")
    if plain_csv:
        from formats.csv import iter_csv

        size = os.path.getsize(path)
        parts: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        template = None
        t0 = None
        bucket = 1
        total = 0
        span = (np.inf, -np.inf)  # earliest and latest finite time seen
        for chunk in iter_csv(path, chunk_rows=250_000, columns=io.get("columns"), profile=io.get("profile")):
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
            for n in names:
                a = chunk[n].reshape(len(chunk), -1)
                parts.setdefault(n, []).append(envelope(chunk.time - t0, a, bucket))
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
    rec, _ = load_input(path, validate=False, **io)
    if not len(rec):
        raise ImutoolError("no samples", path=path)
    names = match_channels(list(rec.channels), wanted, path)
    t0 = float(rec.time[0])
    if start is not None or end is not None:
        rec = rec.slice_time(None if start is None else t0 + start, None if end is None else t0 + end)
    bucket = max(1, -(-2 * len(rec) // max_points))
    out = {n: envelope(rec.time - t0, rec[n].reshape(len(rec), -1), bucket) for n in names}
    return out, rec, len(rec)


def _bytes_per_row(path: str, rows: int) -> float:
    """Mean bytes per data row from the first chunk's share of the file (an estimate for the bucket size)."""
    with open(path, "rb") as f:
        head = f.read(1 << 20)
    n = head.count(b"\n")
    return len(head) / max(n, 1)


@click.command("plot", epilog="Example: imutool plot roll.csv gyro accel -o roll.png --start 10 --end 60")
@click.argument("path", metavar="FILE", type=click.Path(exists=True, dir_okay=True))
@click.argument("channels", nargs=-1, required=True)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Output .png, .pdf or .svg.")
@click.option("--start", type=float, default=None, help="Start, seconds from the first sample.")
@click.option("--end", type=float, default=None, help="End, seconds from the first sample.")
@click.option(
    "--max-points",
    type=int,
    default=20000,
    show_default=True,
    help="Per line; longer series are decimated to a min/max envelope.",
)
@click.option("--title", default=None, help="Figure title (default: the file name).")
@click.option("--dpi", type=int, default=120, show_default=True, help="Resolution of PNG output.")
@input_options
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--quiet", "-q", is_flag=True, help="No summary output.")
@safe_outputs("output")
def plot_cmd(
    path: str,
    channels: tuple[str, ...],
    output: str,
    start: float | None,
    end: float | None,
    max_points: int,
    title: str | None,
    dpi: int,
    columns: str | None,
    profile: str | None,
    topic: str | None,
    stamp: str,
    duplicates: str,
    backwards: str,
    mounting: str | None,
    calibration_file: str | None,
    as_json: bool,
    quiet: bool,
) -> None:
    """Plot CHANNEL... of FILE (names or prefixes: `gyro accel`, `ref`) to a PNG/PDF, one subplot each,
    units in the axis labels (angular rates in deg/s, angles in deg), time in seconds from the first sample."""
    ext = Path(output).suffix.lower()
    if ext not in _FORMATS:
        raise ImutoolError(f"plot output must end in {', '.join(_FORMATS)} (got {output!r})")
    if max_points < 10:
        raise ImutoolError("--max-points must be at least 10")
    io = {
        "columns": columns,
        "profile": profile,
        "topic": topic,
        "stamp": stamp,
        "duplicates": duplicates,
        "backwards": backwards,
        "mounting": mounting,
        "calibration_file": calibration_file,
    }
    series, rec, total = _collect(path, channels, start, end, max_points, io)
    if not series:
        raise ImutoolError("no samples in the requested time window", path=path)

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
    emit_summary({"output": output, "channels": names, "rows": total, "points_per_line": drawn}, as_json, quiet)
