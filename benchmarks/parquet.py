"""Parquet speed and memory: imutool vs pyarrow directly (and polars when installed), and a large file streamed.

Usage::

    python benchmarks/parquet.py                   # 1 M rows x 10 columns: write/read, imutool vs pyarrow/polars/CSV
    python benchmarks/parquet.py --stream 10000000 # also: a 10 M-row Parquet file streamed Parquet -> Parquet
                                                   # and Parquet -> CSV (imutool convert's route), peak RSS
    python benchmarks/parquet.py --rows 200000 --repeat 3
    python benchmarks/parquet.py --rows 0 --filter-hours 1   # `imutool filter` on 1 h at 200 Hz: CSV vs Parquet
    python benchmarks/parquet.py --rows 0 --24h             # `imutool filter` on 24 h at 200 Hz (17.28 M rows) as
                                                            # CSV vs as Parquet (streamed), wall, CPU, peak RSS
    python benchmarks/parquet.py --rows 0 --day-rows 10000000   # the same on a 10 M-row recording

Rates are CPU time of this process (``time.process_time``; the 2-core machine is shared, wall time is noisy)
with wall time alongside; best of ``--repeat``. Files go to a temporary folder (``--tmp`` to choose). Peak RSS of
the streamed conversions is measured in a fresh child process (ru_maxrss), next to the in-memory size of the data.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import pyarrow as pa  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402

from formats import Recording  # noqa: E402
from formats.csv import read_csv, write_csv  # noqa: E402
from formats.parquet import read_parquet, write_parquet  # noqa: E402


def make_recording(rows: int, seed: int = 0) -> Recording:
    """time + gyro + accel + mag: 10 float64 columns of arbitrary doubles."""
    rng = np.random.default_rng(seed)
    rec = Recording(np.arange(rows) / 100.0, meta={"benchmark": "parquet"})
    rec.add("gyro", rng.standard_normal((rows, 3)) * 0.2)
    rec.add("accel", rng.standard_normal((rows, 3)) + [0.0, 0.0, -9.81])
    rec.add("mag", rng.standard_normal((rows, 3)) * 20)
    return rec


def best(f: Callable[[], object], repeat: int) -> tuple[float, float]:
    """(CPU s, wall s) of the fastest of ``repeat`` runs."""
    runs = []
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        f()
        runs.append((time.process_time() - c0, time.perf_counter() - w0))
    return min(runs)


def compare(rows: int, repeat: int, tmp: Path) -> None:
    rec = make_recording(rows)
    arrays = [rec.time] + [rec[ch][:, j] for ch in ("gyro", "accel", "mag") for j in range(3)]
    cols = dict(zip(rec.column_names(), arrays, strict=True))
    mb = rows * 10 * 8 / 1e6
    p_imu, p_pa, p_pl = (tmp / f"b_{k}.parquet" for k in ("imu", "pa", "pl"))
    p_csv = tmp / "b.csv"
    res: list[tuple[str, str, float, float]] = []

    def row(what: str, op: str, f: Callable[[], object]) -> None:
        cpu, wall = best(f, repeat)
        res.append((what, op, cpu, wall))

    row("imutool write_parquet", "write", lambda: write_parquet(rec, p_imu))
    row(
        "pyarrow pq.write_table",
        "write",
        lambda: pq.write_table(pa.table({k: pa.array(v) for k, v in cols.items()}), p_pa),
    )
    row("imutool read_parquet", "read", lambda: read_parquet(p_imu))
    row("pyarrow pq.read_table → numpy", "read", lambda: [c.to_numpy() for c in pq.read_table(p_pa).columns])
    try:
        import polars as pl

        df = pl.DataFrame(cols)
        row("polars write_parquet", "write", lambda: df.write_parquet(p_pl))
        row("polars read_parquet → numpy", "read", lambda: pl.read_parquet(p_pl).to_numpy())
    except ImportError:
        print("polars not installed (pip install 'imutool[bench]'): skipped")
    row("imutool write_csv (for scale)", "write", lambda: write_csv(rec, str(p_csv)))
    row("imutool read_csv (for scale)", "read", lambda: read_csv(str(p_csv)))
    print(
        f"\n{rows:,} rows x 10 float64 columns ({mb:.0f} MB in memory); best of {repeat}; "
        f"Parquet {p_imu.stat().st_size / 1e6:.0f} MB (snappy), CSV {p_csv.stat().st_size / 1e6:.0f} MB"
    )
    print(f"{'':34s} {'op':5s} {'CPU s':>7s} {'wall s':>7s} {'M rows/s (CPU)':>15s}")
    for what, op, cpu, wall in res:
        print(f"{what:34s} {op:5s} {cpu:7.3f} {wall:7.3f} {rows / max(cpu, 1e-9) / 1e6:15.1f}")


_MAKE = textwrap.dedent("""
    import sys
    import numpy as np
    from formats import Recording
    from formats.parquet import ParquetWriter
    n_total, chunk = int(sys.argv[2]), 500_000
    with ParquetWriter(sys.argv[1]) as w:
        for i in range(0, n_total, chunk):
            n = min(chunk, n_total - i)
            rng = np.random.default_rng(i)
            t = (i + np.arange(n)) / 200.0
            w.write(Recording(t, {"gyro": rng.normal(size=(n, 3)), "accel": rng.normal(size=(n, 3)),
                                  "mag": rng.normal(size=(n, 3))}))
""")

_STREAM = textwrap.dedent("""
    import sys, time
    import imutool.convert, formats.parquet, formats.csv
    def hwm_mib():  # VmHWM: this process's peak RSS (ru_maxrss would include the parent's peak before exec)
        for line in open("/proc/self/status"):
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    base = hwm_mib()
    t0, c0 = time.perf_counter(), time.process_time()
    if sys.argv[2] == "-":
        rows = sum(len(c) for c in formats.parquet.iter_parquet(sys.argv[1], chunk_rows=int(sys.argv[3])))
    else:
        rows = imutool.convert.stream_convert(sys.argv[1], sys.argv[2], chunk_rows=int(sys.argv[3]))["rows_out"]
    print(rows, time.perf_counter() - t0, time.process_time() - c0, base, hwm_mib())
""")


def stream(rows: int, chunk_rows: int, tmp: Path) -> None:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    src = tmp / "big.parquet"
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", _MAKE, str(src), str(rows)], check=True, env=env)
    print(
        f"\nstreamed: {rows:,} rows x 10 columns ({rows * 80 / 2**20:.0f} MiB as float64), Parquet "
        f"{src.stat().st_size / 1e6:.0f} MB written by ParquetWriter in {time.perf_counter() - t0:.1f} s wall; "
        f"chunks of {chunk_rows:,} rows"
    )
    for label, dst in (
        ("iter_parquet (read only)", "-"),
        ("Parquet -> Parquet", str(tmp / "out.parquet")),
        ("Parquet -> CSV", str(tmp / "out.csv")),
    ):
        r = subprocess.run(
            [sys.executable, "-c", _STREAM, str(src), dst, str(chunk_rows)],
            check=True,
            env=env,
            capture_output=True,
            text=True,
        )
        n, wall, cpu, base, peak = r.stdout.split()
        print(
            f"  {label:26s} {int(n) / float(cpu) / 1e6:6.2f} M rows/s CPU ({float(wall):6.1f} s wall)  peak RSS "
            f"{float(peak):6.0f} MiB (after imports {float(base):4.0f} MiB)"
        )
        if dst != "-":
            os.unlink(dst)
    print(f"  (this process: peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB)")


_FILTER = textwrap.dedent("""
    import atexit, json, resource, sys, time
    t0 = time.perf_counter()
    def report():
        hwm = next(int(l.split()[1]) / 1024 for l in open("/proc/self/status") if l.startswith("VmHWM:"))
        ru = resource.getrusage(resource.RUSAGE_SELF)
        print(json.dumps({"wall": time.perf_counter() - t0, "cpu": ru.ru_utime + ru.ru_stime, "peak_mib": hwm}),
              file=sys.stderr)
    atexit.register(report)
    from imutool.cli import main
    main(sys.argv[1:])
""")


def filter_compare(hours: float, tmp: Path) -> None:
    """`imutool filter` on the same recording as CSV and as Parquet (input → output of the same format)."""
    from formats import write
    from imutool.sim import simulate

    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    rec = simulate("static", duration=hours * 3600.0, rate_hz=200.0)
    n = len(rec)
    for ext in (".csv", ".parquet"):
        write(rec, tmp / f"rec{ext}")
    del rec
    mb = {e: (tmp / f"rec{e}").stat().st_size / 1e6 for e in (".csv", ".parquet")}
    print(
        f"\n`imutool filter` on {hours:g} h at 200 Hz ({n:,} rows, static scenario, 9-axis + truth columns); "
        f"CSV {mb['.csv']:.0f} MB, Parquet {mb['.parquet']:.0f} MB"
    )
    # warm-up (numba cache), then the timed runs
    subprocess.run(
        [sys.executable, "-c", _FILTER, "filter", str(tmp / "rec.parquet"), "-o", str(tmp / "warm.csv"), "-q"],
        env=env,
        capture_output=True,
    )
    for src, dst in (("rec.csv", "est.csv"), ("rec.parquet", "est.parquet"), ("rec.parquet", "est2.csv")):
        r = subprocess.run(
            [sys.executable, "-c", _FILTER, "filter", str(tmp / src), "-o", str(tmp / dst), "-q"],
            env=env,
            capture_output=True,
            text=True,
        )
        if r.returncode:
            print(f"  {src} -> {dst}: failed: {r.stderr.strip()[-300:]}")
            continue
        m = json.loads(r.stderr.strip().splitlines()[-1])
        print(
            f"  {src:12s} -> {dst:12s} {m['wall']:6.1f} s wall  {m['cpu']:6.1f} s CPU  "
            f"peak RSS {m['peak_mib']:6.0f} MiB"
        )


def build_day(rows: int, folder: Path, env: dict[str, str]) -> tuple[Path, Path]:
    """The long recording as CSV, built as benchmarks/attitude.py --24h builds its 24 h file (one simulated
    ship-roll hour per seed, gyro/accel/mag, appended), then converted to Parquet with `imutool convert`."""
    import formats
    from formats.csv import CsvWriter
    from imutool.sim import simulate

    csv, pq_path = folder / "day.csv", folder / "day.parquet"
    t0 = time.perf_counter()
    hour = 720_000
    with CsvWriter(str(csv)) as w:
        for i in range(-(-rows // hour)):
            n = min(hour, rows - i * hour)
            r = simulate("ship-roll", duration=(n - 1) / 200.0, seed=i)
            r.time = r.time + 3600.0 * i
            w.write(formats.Recording(r.time, {c: r[c] for c in ("gyro", "accel", "mag")}))
    t1 = time.perf_counter()
    r = subprocess.run(
        [sys.executable, "-c", _FILTER, "convert", str(csv), str(pq_path), "-q"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    m = json.loads(r.stderr.strip().splitlines()[-1])
    print(
        f"\n{rows:,} rows (ship-roll, {rows / 720_000:.2f} h at 200 Hz, gyro/accel/mag): CSV "
        f"{csv.stat().st_size / 1e9:.2f} GB written in {t1 - t0:.0f} s; `imutool convert` CSV -> Parquet "
        f"{m['wall']:.1f} s wall, {m['cpu']:.1f} s CPU, peak RSS {m['peak_mib']:.0f} MiB -> "
        f"{pq_path.stat().st_size / 1e9:.2f} GB Parquet"
    )
    return csv, pq_path


def filter_day(rows: int, tmp: Path, repeat: int = 2) -> None:
    """`imutool filter` (defaults: EKF, streamed above --stream-mb 300 in chunks of 1 M rows) on a long recording,
    CSV vs Parquet; best wall time of ``repeat`` runs (with its CPU time and peak RSS)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    csv, pq_path = build_day(rows, tmp, env)
    os.sync()  # the freshly written files' dirty pages would otherwise be flushed during the first timed run
    print(
        f"  in-memory size of the input arrays: {rows * 10 * 8 / 2**20:.0f} MiB (time + 9 axes, float64); of "
        f"the estimate: {rows * 17 * 8 / 2**20:.0f} MiB (17 columns); best of {repeat}"
    )
    subprocess.run(
        [
            sys.executable,
            "-c",
            _FILTER,
            "filter",
            str(pq_path),
            "-o",
            str(tmp / "warm.csv"),
            "-q",
            "--chunk-rows",
            "1000",
            "--stream-mb",
            "1e9",
        ],
        env=env,
        capture_output=True,
    )  # numba cache
    cases = (
        (csv, "est.csv", []),
        (pq_path, "est.parquet", []),
        (pq_path, "est2.csv", []),
        (pq_path, "est3.parquet", ["--chunk-rows", "100000"]),
    )
    for src, dst, extra in cases:
        cmd = ["filter", str(src), "-o", str(tmp / dst), "-q", "--force", *extra]
        runs = []
        for _ in range(repeat):
            load0 = os.getloadavg()[0]
            r = subprocess.run([sys.executable, "-c", _FILTER, *cmd], env=env, capture_output=True, text=True)
            if r.returncode:
                print(f"  {src.name} -> {dst}: failed: {r.stderr.strip()[-300:]}")
                break
            runs.append({**json.loads(r.stderr.strip().splitlines()[-1]), "load": load0})
            os.sync()
        if not runs:
            continue
        m = min(runs, key=lambda x: x["wall"])
        print(
            f"  imutool filter {src.name:11s} -o {dst:12s} {' '.join(extra):20s} {m['wall']:5.1f} s wall "
            f"{m['cpu']:5.1f} s CPU  peak RSS {m['peak_mib']:5.0f} MiB  (load {m['load']:.1f}; output "
            f"{(tmp / dst).stat().st_size / 1e9:.2f} GB)"
        )
        (tmp / dst).unlink()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--stream", type=int, default=0, metavar="ROWS", help="also stream a file of ROWS rows")
    ap.add_argument("--chunk-rows", type=int, default=500_000)
    ap.add_argument(
        "--filter-hours",
        type=float,
        default=0.0,
        metavar="H",
        help="also time `imutool filter` on H hours at 200 Hz as CSV and as Parquet",
    )
    ap.add_argument(
        "--24h",
        dest="day",
        action="store_true",
        help="also time `imutool filter` on 24 h at 200 Hz (17.28 M rows) as CSV and as Parquet",
    )
    ap.add_argument(
        "--day-rows",
        type=int,
        default=0,
        metavar="ROWS",
        help="the same on ROWS rows (e.g. 10000000); --24h is 17280000",
    )
    ap.add_argument("--tmp", default=None)
    a = ap.parse_args()
    day_rows = a.day_rows or (17_280_000 if a.day else 0)
    with tempfile.TemporaryDirectory(dir=a.tmp) as d:
        if a.rows:
            compare(a.rows, a.repeat, Path(d))
        if a.stream:
            stream(a.stream, a.chunk_rows, Path(d))
        if a.filter_hours:
            filter_compare(a.filter_hours, Path(d))
        if day_rows:
            filter_day(day_rows, Path(d), a.repeat)


if __name__ == "__main__":
    main()
