"""I/O speed and memory: CSV read/write rows/s and streamed-conversion peak RSS (CSV section), ROS bag read
messages/s (bag section). Prints figures; no assertions. Sections are independent functions called from main().

Usage::

    python benchmarks/io.py                    # CSV 1 M rows x 10 columns + bag 200 k messages
    python benchmarks/io.py --stream           # also: 10 M-row CSV -> CSV streamed conversion, peak RSS
    python benchmarks/io.py --only csv --rows 200000
    python benchmarks/io.py --only bag [--bag-messages 200000] [--repeat 3]

CSV rates are CPU time of this process (``time.process_time``: the 2-core machine is shared, wall time is noisy);
wall time is printed too. Compile time of the numba kernels is excluded (one warm-up call first).
"""

from __future__ import annotations

import argparse
import io
import itertools
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from formats import Recording  # noqa: E402
from formats.csv import CsvWriter, _threads, iter_csv, read_csv, write_csv  # noqa: E402


# -- CSV ----------------------------------------------------------------------------------------------------
def _timed(f: Callable[[], object]) -> tuple[float, float, object]:
    w0, c0 = time.perf_counter(), time.process_time()
    out = f()
    return time.process_time() - c0, time.perf_counter() - w0, out


def make_recording(rows: int, kind: str = "sensor", seed: int = 0) -> Recording:
    """time + gyro + accel + mag (10 columns). ``sensor``: values at a sensor's resolution (short decimals, like
    real logs); ``full``: arbitrary doubles (16–17 significant digits when written exactly)."""
    rng = np.random.default_rng(seed)
    t = np.arange(rows) / 100.0
    g = rng.standard_normal((rows, 3)) * 0.2
    a = rng.standard_normal((rows, 3)) + [0.0, 0.0, -9.81]
    m = rng.standard_normal((rows, 3)) * 20 + [20.0, 0.0, 40.0]
    if kind == "sensor":
        g = np.round(g, 6)
        a = np.round(a, 5)
        m = np.round(m, 3)
    rec = Recording(t, meta={"benchmark": kind})
    rec.add("gyro", g)
    rec.add("accel", a)
    rec.add("mag", m)
    return rec


def bench_csv_write(rec: Recording, path: str) -> dict:
    write_csv(rec.select(slice(0, 100)), path)  # warm-up (kernel compile/cache load)
    cpu, wall, _ = _timed(lambda: write_csv(rec, path))
    return {
        "rows": len(rec),
        "cpu_s": cpu,
        "wall_s": wall,
        "rows_per_s": len(rec) / cpu,
        "mb": os.path.getsize(path) / 1e6,
    }


def bench_csv_read(path: str, rows: int) -> dict:
    read_csv(path)  # warm-up, also brings the file into the page cache
    cpu, wall, rec = _timed(lambda: read_csv(path))
    assert len(rec) == rows
    return {"rows": rows, "cpu_s": cpu, "wall_s": wall, "rows_per_s": rows / cpu}


def bench_numpy_baselines(rec: Recording, path: str, rows: int) -> dict:
    """numpy.loadtxt / savetxt on the same data (first ``rows`` rows; rates per row)."""
    sub = rec.select(slice(0, rows))
    data = np.column_stack([sub.time, sub["gyro"], sub["accel"], sub["mag"]])
    cpu_s, _, _ = _timed(lambda: np.savetxt(io.BytesIO(), data, delimiter=","))
    with open(path, "rb") as f:
        lines = b"".join(line for line in itertools.islice(f, rows + 200) if not line.startswith(b"#"))
    body = lines.split(b"\n", 1)[1]
    cpu_l, _, arr = _timed(lambda: np.loadtxt(io.BytesIO(body), delimiter=","))
    return {"rows": arr.shape[0], "savetxt_rows_per_s": rows / cpu_s, "loadtxt_rows_per_s": arr.shape[0] / cpu_l}


def _write_big(path: str, rows: int, kind: str) -> None:
    """A big CSV written in pieces (bounded memory)."""
    step = 1_000_000
    with CsvWriter(path) as w:
        for r0 in range(0, rows, step):
            n = min(step, rows - r0)
            rec = make_recording(n, kind, seed=r0)
            rec.time += r0 / 100.0
            w.write(rec)


def _convert_child(src: str, dst: str) -> None:
    """Streamed CSV → CSV conversion (what `imutool convert` does for big files); runs in a child process."""
    with CsvWriter(dst) as w:
        for chunk in iter_csv(src):
            w.write(chunk)


def bench_stream_convert(rows: int, kind: str, tmpdir: str) -> dict:
    """Peak RSS of a child process converting a ``rows``-row CSV (VmHWM: ru_maxrss would include the parent's
    size at fork, which Linux carries across exec)."""
    src = os.path.join(tmpdir, "big.csv")
    dst = os.path.join(tmpdir, "big_copy.csv")
    _write_big(src, rows, kind)
    code = (
        f"import sys; sys.path.insert(0, {str(ROOT)!r}); import resource, time; "
        f"from benchmarks.io import _convert_child; c = time.process_time(); "
        f"_convert_child({src!r}, {dst!r}); "
        f"hwm = [ln.split()[1] for ln in open('/proc/self/status') if ln.startswith('VmHWM')]; "
        f"print(time.process_time() - c, hwm[0] if hwm else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)"
    )
    w0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    wall = time.perf_counter() - w0
    cpu, rss_kb = float(out[0]), int(out[1])
    return {
        "rows": rows,
        "file_gb": os.path.getsize(src) / 1e9,
        "cpu_s": cpu,
        "wall_s": wall,
        "rows_per_s": rows / cpu,
        "peak_rss_mb": rss_kb / 1024.0,
    }


# -- ROS bags ---------------------------------------------------------------------------------------------------
def bench_bag_read(n_messages: int = 200_000, repeat: int = 3) -> dict[str, dict[str, float]]:
    """Write an n-message sensor_msgs/Imu bag (ROS1 .bag and ROS2 sqlite3 folder) with formats.rosbag.write_bag,
    then time formats.rosbag.read_bag (fast path) and, on a 20 000-message slice, rosbags' own per-message
    deserialise for comparison. Returns {format: {"write_s", "read_msgs_per_s", "rosbags_deserialise_msgs_per_s"}}.
    """
    from pathlib import Path

    from formats import Recording
    from formats.rosbag import read_bag, write_bag

    rng = np.random.default_rng(0)
    rec = Recording(1_700_000_000.0 + np.arange(n_messages) * 0.005)
    rec.add("gyro", rng.normal(size=(n_messages, 3)) * 0.1)
    rec.add("accel", rng.normal(size=(n_messages, 3)) + [0, 0, -9.81])
    rec.add("q", np.tile([1.0, 0.0, 0.0, 0.0], (n_messages, 1)))
    rec.add("roll_std", np.full(n_messages, 0.5))
    rec.add("pitch_std", np.full(n_messages, 0.5))
    rec.add("heading_std", np.full(n_messages, 2.0))
    results: dict[str, dict[str, float]] = {}
    tmp = tempfile.mkdtemp(prefix="imutool-bench-bag-")
    try:
        read_bag(_small_bag(tmp))  # compile / warm numba kernels outside the timing
        for label, name in (("ROS1 .bag", "b.bag"), ("ROS2 sqlite3", "b_sqlite3"), ("ROS2 MCAP", "b.mcap")):
            path = os.path.join(tmp, name)
            t0 = time.perf_counter()
            write_bag(rec, path)
            t_write = time.perf_counter() - t0
            best = best_cpu = np.inf
            for _ in range(repeat):
                t0, c0 = time.perf_counter(), time.process_time()
                out = read_bag(path)
                best = min(best, time.perf_counter() - t0)
                best_cpu = min(best_cpu, time.process_time() - c0)
            assert len(out) == n_messages
            # rosbags' per-message deserialise for comparison (on the first 20 000 raw messages)
            from rosbags.highlevel import AnyReader

            k = min(n_messages, 20_000)
            with AnyReader([Path(path)]) as r:
                raws = []
                for c, _, raw in r.messages():
                    raws.append((c.msgtype, raw))
                    if len(raws) >= k:
                        break
                c0 = time.process_time()
                for typ, raw in raws:
                    r.deserialize(raw, typ)
                t_des = time.process_time() - c0
            results[label] = {
                "messages": n_messages,
                "write_s": t_write,
                "read_s": best,
                "read_msgs_per_s": n_messages / best,
                "read_cpu_s": best_cpu,
                "read_msgs_per_cpu_s": n_messages / best_cpu,
                "rosbags_deserialise_msgs_per_cpu_s": k / t_des,
            }
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return results


def _small_bag(folder: str) -> str:
    from formats import Recording
    from formats.rosbag import write_bag

    r = Recording(np.arange(10) * 0.01)
    r.add("gyro", np.zeros((10, 3)))
    p = os.path.join(folder, "warm.bag")
    write_bag(r, p)
    return p


def print_bag(results: dict[str, dict[str, float]]) -> None:
    print("ROS bag read (sensor_msgs/Imu, formats.rosbag.read_bag; best of repeats; CPU = process time, the fair")
    print("figure on a shared machine)")
    print(
        "| format | messages | read wall s | read CPU s | msgs/s (wall) | msgs/s (CPU) | rosbags deserialise "
        "msgs/s (CPU) | write s |"
    )
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for label, r in results.items():
        print(
            f"| {label} | {r['messages']:,} | {r['read_s']:.2f} | {r['read_cpu_s']:.2f} | "
            f"{r['read_msgs_per_s']:,.0f} | {r['read_msgs_per_cpu_s']:,.0f} | "
            f"{r['rosbags_deserialise_msgs_per_cpu_s']:,.0f} | {r['write_s']:.1f} |"
        )


def run_csv(rows: int, baseline_rows: int, stream: bool, stream_rows: int) -> None:
    with tempfile.TemporaryDirectory(prefix="imutool-bench-") as tmp:
        print(
            f"CSV, {rows} rows x 10 columns; rows/s per wall-clock second and per CPU second (the kernels run in"
            f" up to {_threads()} threads, so CPU time sums the threads)"
        )
        print(
            "| data | write rows/s wall | write rows/s CPU | read rows/s wall | read rows/s CPU | file MB | "
            "numpy.savetxt rows/s CPU | numpy.loadtxt rows/s CPU |"
        )
        print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        for kind in ("sensor", "full"):
            rec = make_recording(rows, kind)
            path = os.path.join(tmp, f"{kind}.csv")
            w = bench_csv_write(rec, path)
            r = bench_csv_read(path, rows)
            b = bench_numpy_baselines(rec, path, min(baseline_rows, rows))
            print(
                f"| {kind} | {rows / w['wall_s']:,.0f} | {w['rows_per_s']:,.0f} | {rows / r['wall_s']:,.0f} | "
                f"{r['rows_per_s']:,.0f} | {w['mb']:.0f} | {b['savetxt_rows_per_s']:,.0f} | "
                f"{b['loadtxt_rows_per_s']:,.0f} |"
            )
        if stream:
            s = bench_stream_convert(stream_rows, "sensor", tmp)
            print(
                f"streamed CSV->CSV conversion, {s['rows']:,} rows ({s['file_gb']:.2f} GB): "
                f"{s['rows_per_s']:,.0f} rows/s CPU, wall {s['wall_s']:.0f} s, peak RSS {s['peak_rss_mb']:.0f} MB"
            )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", choices=["csv", "bag"], default=None, help="run one section only")
    ap.add_argument("--rows", type=int, default=1_000_000, help="CSV: rows of the read/write benchmark")
    ap.add_argument("--baseline-rows", type=int, default=200_000, help="CSV: rows for the numpy baselines")
    ap.add_argument("--stream", action="store_true", help="CSV: also run the streamed conversion (slow)")
    ap.add_argument("--stream-rows", type=int, default=10_000_000)
    ap.add_argument("--bag-messages", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    try:
        print(f"load average: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    except OSError:
        pass
    if args.only in (None, "csv"):
        run_csv(args.rows, args.baseline_rows, args.stream, args.stream_rows)
    if args.only in (None, "bag"):
        print_bag(bench_bag_read(args.bag_messages, args.repeat))
    print(f"(peak RSS of this process {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB)")


if __name__ == "__main__":
    main()
